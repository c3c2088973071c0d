"""The ``mission_done`` metrics as a table a person reads: rounded, with units and what each figure means.

The metrics map (:mod:`services.sim.metrics`, also written whole to the run folder's metrics.json)
nests per-agent and per-door figures and carries every parameter of the run; printed raw it is a
wall of Python dicts. Here each figure is one row: name, value (seconds to 0.1 s), unit and meaning.
Two door counts are told apart: the paper's measure is the doors the *human* opened, while the
progress line's "door openings" counts every opening, robots' automatic doors included.
Figures this table does not know, or whose shape it does not expect (another sim, an older file),
are listed after it as they are, so nothing is hidden and nothing unexpected stops the supervisor.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

Row = tuple[str, str, str, str]  # figure, value, unit, meaning

_NUMBER = (int, float)
#: The shape each known figure must have to be shown in the table (None: may be missing/null).
SHAPES: dict[str, tuple[type, ...]] = {
    "completed": (bool, type(None)),
    "time": (*_NUMBER, type(None)),
    "team_completion_time": (*_NUMBER, type(None)),
    "agent_completion_times": (Mapping,),
    "human_door_openings": (int, type(None)),
    "door_openings": (Mapping,),
    "feedback": (Mapping,),
    "actions": (Mapping,),
    "closed_door_crossings": (int,),
    "robot_overlaps": (int,),
    "robot_overlaps_by_place": (Mapping,),
    "robot_overlaps_by_pair": (Mapping,),
    "world_versions": (int,),
    "robots": (Mapping,),
    "human": (Mapping,),
    "params": (Mapping,),
}


def _fits(key: str, value: Any) -> bool:
    """The figure has the shape the table reads (nested maps checked one level down)."""
    if not isinstance(value, SHAPES[key]):
        return False
    if key == "door_openings":
        return all(isinstance(by, Mapping) and all(isinstance(n, int) for n in by.values()) for by in value.values())
    if key == "agent_completion_times":
        return all(isinstance(t, (*_NUMBER, type(None))) for t in value.values())
    if key == "robots":
        return all(isinstance(robot, Mapping) for robot in value.values())
    if key.startswith("robot_overlaps_by_"):
        return all(isinstance(n, int) for n in value.values())
    return True


def _seconds(value: Any) -> str:
    if value is None:
        return "-"
    return f"{value:.1f}" if isinstance(value, _NUMBER) else str(value)


def _count(value: Any) -> str:
    return "-" if value is None else str(value)


def _agent_rows(metrics: Mapping[str, Any]) -> list[Row]:
    rows: list[Row] = []
    robots = metrics.get("robots") or {}
    for agent, done_at in (metrics.get("agent_completion_times") or {}).items():
        if agent == "human":
            continue
        waited = (robots.get(agent) or {}).get("wait_time")
        meaning = "its last delivery" + (f"; waited {_seconds(waited)} s at doors" if waited is not None else "")
        rows.append((f"  {agent} completion time", _seconds(done_at), "s", meaning))
    human = metrics.get("human") or {}
    if "human" in (metrics.get("agent_completion_times") or {}):
        away = human.get("time_away")
        meaning = "her own task done" + (f"; {_seconds(away)} s away from it at doors" if away is not None else "")
        rows.append(("  human completion time", _seconds(metrics["agent_completion_times"]["human"]), "s", meaning))
    return rows


def _door_rows(metrics: Mapping[str, Any]) -> list[Row]:
    per_door: Mapping[str, Mapping[str, int]] = metrics.get("door_openings") or {}
    by_human = sum(n.get("human", 0) for n in per_door.values())
    by_robot = sum(n.get("robot", 0) for n in per_door.values())
    rows: list[Row] = [
        (
            "human door openings",
            _count(metrics.get("human_door_openings")),
            "count",
            "doors the human got up and opened (her a1 actions): the paper's measure",
        ),
        (
            "door openings, all",
            str(by_human + by_robot),
            "count",
            f"every opening, {by_robot} by robots (automatic doors) + {by_human} by the human: "
            "the progress line's 'door openings'",
        ),
    ]
    for door, by in per_door.items():
        split = ", ".join(f"{who} {n}" for who, n in sorted(by.items()))
        rows.append((f"  {door}", str(sum(by.values())), "count", split))
    return rows


def _contacts_row(metrics: Mapping[str, Any]) -> Row:
    """Robot-robot contacts, with where they happened and between whom."""
    meaning = "times two robots' discs began to intersect (0: no collision)"
    for key, label in (("robot_overlaps_by_place", "where"), ("robot_overlaps_by_pair", "between")):
        counts = metrics.get(key) or {}
        if counts:
            meaning += f"; {label}: " + ", ".join(f"{k} {n}" for k, n in sorted(counts.items()))
    return ("robot-robot contacts", _count(metrics["robot_overlaps"]), "count", meaning)


def metrics_rows(metrics: Mapping[str, Any]) -> list[Row]:
    """The table's rows, known figures first, in the order a reader asks about them."""
    feedback = metrics.get("feedback") or {}
    actions = metrics.get("actions") or {}
    completed = metrics.get("completed")
    rows: list[Row] = [
        (
            "completed",
            "-" if completed is None else ("yes" if completed else "no"),
            "",
            "every object delivered and the human's task done (no: the time limit ended it)",
        ),
        ("mission time", _seconds(metrics.get("time")), "s", "site clock when the mission ended"),
        (
            "team completion time",
            _seconds(metrics.get("team_completion_time")),
            "s",
            "the slowest agent's completion, the human's included (the paper's measure)",
        ),
        *_agent_rows(metrics),
        *_door_rows(metrics),
    ]
    if feedback:
        rows.append(
            (
                "feedback sent",
                _count(feedback.get("sent")),
                "count",
                f"the human's declarations to the restrictor: {_count(feedback.get('accepted'))} accepted, "
                f"{_count(feedback.get('refused'))} refused, {_count(feedback.get('unanswered'))} unanswered",
            )
        )
    if actions:
        rows.append(
            (
                "robot actions",
                _count(actions.get("done")),
                "count",
                f"plan steps the robots carried out ({_count(actions.get('failed'))} failed)",
            )
        )
    if "closed_door_crossings" in metrics:
        rows.append(
            (
                "closed-door crossings",
                _count(metrics["closed_door_crossings"]),
                "count",
                "robots that entered a closed door's doorway (0 in every correct run)",
            )
        )
    if "robot_overlaps" in metrics:
        rows.append(_contacts_row(metrics))
    if "world_versions" in metrics:
        rows.append(
            ("world versions", _count(metrics["world_versions"]), "count", "world changes the planner was told of")
        )
    return rows


def _params_line(params: Mapping[str, Any]) -> str:
    keys = ("site", "method", "seed", "mode", "robots", "objects")
    return ", ".join(f"{k} {params[k]}" for k in keys if k in params)


def metrics_table(metrics: Mapping[str, Any]) -> str:
    """The whole table as text, one row a line, columns aligned; params summed up in one line."""
    if not metrics:
        return "(no metrics)"
    known = {k: v for k, v in metrics.items() if k in SHAPES and _fits(k, v)}
    rows = [("figure", "value", "unit", "meaning"), *metrics_rows(known)]
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    lines = [f"{a:<{widths[0]}}  {b:>{widths[1]}}  {c:<{widths[2]}}  {d}".rstrip() for a, b, c, d in rows]
    params = known.get("params")
    if params:
        lines.append(f"run: {_params_line(params)} (every parameter in metrics.json)")
    others = {k: v for k, v in metrics.items() if k not in known}
    if others:
        lines.append("other figures:")
        lines.extend(f"  {k}: {_other(v)}" for k, v in others.items())
    return "\n".join(lines)


def _other(value: Any) -> str:
    return f"{value:.3f}" if isinstance(value, float) else str(value)
