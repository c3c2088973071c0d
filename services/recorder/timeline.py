"""A run's timeline from its recording: per agent, what it did when.

Rows: each robot (moving, waiting at a door — which one —, loading/unloading, idle/done), the human
(focus intervals, declarations she sent, doors she opened) and each door (open intervals, who opened
it). Intervals come from the recorded ``RobotStatus`` and ``DoorState`` messages, declarations from
``Feedback`` (or the simulated human's ``feedback_sent`` events, as her feedback travels as queries),
focus intervals from the mission's metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.events import FeedbackSent, MissionDone, data_to_wire
from protocol.messages import DoorState, Event, Feedback, RobotStatus
from runtime.palette import robot_colors

from .reading import messages

STATE_COLOURS = {
    "waiting_at_door": "#d62728",
    "loading": "#444444",
    "unloading": "#7f7f7f",
    "idle": "#e8e8e8",
    "done": "#c8e6c9",
    "failed": "#000000",
}


@dataclass
class Timeline:
    end: float = 0.0
    robots: dict[str, list[tuple[float, float, str, str]]] = field(default_factory=dict)  # (start, end, state, door)
    doors: dict[str, list[tuple[float, float, str]]] = field(default_factory=dict)  # (start, end, opened by)
    declarations: list[tuple[float, str]] = field(default_factory=list)  # (time, "kind(params)")
    focus: list[tuple[float, float]] = field(default_factory=list)
    metrics: dict[str, Any] | None = None


def build_timeline(path: Path) -> Timeline:
    tl = Timeline()
    current: dict[str, tuple[float, str, str]] = {}  # robot -> (since, state, door)
    opened: dict[str, tuple[float, str]] = {}  # door -> (since, by)
    for rec in messages(path):
        msg, t = rec.message, rec.message.stamp
        tl.end = max(tl.end, t)
        if isinstance(msg, RobotStatus):
            state = (msg.state, msg.waiting_door if msg.state == "waiting_at_door" else "")
            since = current.get(msg.robot)
            if since is None or (since[1], since[2]) != state:
                if since is not None:
                    tl.robots.setdefault(msg.robot, []).append((since[0], t, since[1], since[2]))
                current[msg.robot] = (t, *state)
        elif isinstance(msg, DoorState):
            tl.doors.setdefault(msg.door, [])
            if msg.open and msg.door not in opened:
                opened[msg.door] = (t, msg.by)
            elif not msg.open and msg.door in opened:
                start, by = opened.pop(msg.door)
                tl.doors[msg.door].append((start, t, by))
        elif isinstance(msg, Feedback):
            params = ", ".join(f"{k}={v}" for k, v in msg.params.items())
            tl.declarations.append((t, f"{msg.kind}({params})"))
        elif isinstance(msg, Event) and isinstance(msg.data, FeedbackSent):
            # The simulated human's declarations go out as queries, which no subscriber hears: her event says them.
            params = ", ".join(f"{k}={v}" for k, v in msg.data.params.items())
            tl.declarations.append((t, f"{msg.data.kind}({params})"))
        elif isinstance(msg, Event) and isinstance(msg.data, MissionDone):
            tl.metrics = data_to_wire(msg.data)
            human = msg.data.human or {}
            tl.focus = [(float(f["start"]), float(f["end"])) for f in human.get("focus", [])]
    for rid, (since, state, door) in current.items():
        tl.robots.setdefault(rid, []).append((since, tl.end, state, door))
    for did, (since, by) in opened.items():
        tl.doors[did].append((since, tl.end, by))
    return tl


def draw_timeline(tl: Timeline, out: Path, title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    robots = sorted(tl.robots)
    doors = sorted(tl.doors)
    rows = [*robots, "human", *doors]
    colours = {rid: tuple(c / 255 for c in rgb) for rid, rgb in robot_colors(robots).items()}
    fig, ax = plt.subplots(figsize=(12, 0.55 * len(rows) + 1.8))
    y = {name: len(rows) - 1 - i for i, name in enumerate(rows)}
    for rid in robots:
        for start, end, state, door in tl.robots[rid]:
            colour = colours[rid] if state == "moving" else STATE_COLOURS.get(state, "#bbbbbb")
            ax.broken_barh([(start, max(end - start, 0.01))], (y[rid] - 0.35, 0.7), facecolors=colour)
            if state == "waiting_at_door" and end - start > 0.03 * max(tl.end, 1.0):
                ax.text((start + end) / 2, y[rid], door, ha="center", va="center", fontsize=7, color="white")
    for start, end in tl.focus:
        ax.broken_barh([(start, end - start)], (y["human"] - 0.35, 0.7), facecolors="#9467bd", alpha=0.6)
    for t, text in tl.declarations:
        ax.plot([t], [y["human"]], marker="v", color="black", markersize=8)
        ax.text(t + 0.005 * max(tl.end, 1.0), y["human"] - 0.12, text, fontsize=7, ha="left", va="top")
    for did in doors:
        for start, end, by in tl.doors[did]:
            ax.broken_barh(
                [(start, max(end - start, 0.01))],
                (y[did] - 0.3, 0.6),
                facecolors="#2ca02c" if by == "human" else "#98df8a",
            )
            if by == "human":
                ax.plot([start], [y["human"]], marker="|", color="#2ca02c", markersize=14)
    ax.set_yticks([y[name] for name in rows], [f"door {n}" if n in tl.doors else n for n in rows])
    ax.set_xlim(0, max(tl.end, 1.0))
    ax.set_xlabel("site time (s)")
    ax.grid(axis="x", alpha=0.3)
    params = (tl.metrics or {}).get("params") or {}
    what = ", ".join(f"{k} {params[k]}" for k in ("site", "method", "seed") if k in params)
    ax.set_title(f"{title or 'timeline'}{f' ({what})' if what else ''}")
    legend = [
        Patch(facecolor="#888888", label="moving (robot's colour)"),
        Patch(facecolor=STATE_COLOURS["waiting_at_door"], label="waiting at door"),
        Patch(facecolor=STATE_COLOURS["loading"], label="loading"),
        Patch(facecolor=STATE_COLOURS["unloading"], label="unloading"),
        Patch(facecolor=STATE_COLOURS["done"], label="done"),
        Patch(facecolor="#9467bd", alpha=0.6, label="human: focus interval"),
        Patch(facecolor="#2ca02c", label="door open (by the human)"),
        Patch(facecolor="#98df8a", label="door open (robot/sensor)"),
    ]
    ax.legend(
        handles=legend,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.06 - 0.5 / len(rows)),
        ncol=4,
        fontsize=8,
        frameon=False,
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
