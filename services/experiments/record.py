"""A trial's outcome as CSV rows: the results (``trials.csv``) and how long it took (``timing.csv``).

``trials.csv`` holds only what follows from the seeds (a seeded lockstep mission gives the same
metrics every time), so the same sweep gives the same file byte for byte. Anything measured on the
wall clock, or depending on how the planner's replan bursts happened to fall, goes to
``timing.csv`` under the same identity columns. Numbers are written with fixed formats (times to the
millisecond), never ``repr`` of a float, so the text does not depend on how a value was computed.

A point sweep's files (:data:`.design.POINT_SWEEPS`) have a ``point`` identity column and one column
per factor its points set (:func:`trial_fields`), and its trials.csv adds how feedback changed the
plans (:data:`PLAN_FIELDS`, from :mod:`.plan_changes`). The earlier sweeps' columns are unchanged.
"""

from __future__ import annotations

from typing import Any

from .design import SweepSpec, TrialKey, format_p
from .trial import TrialOutcome

POINT_FIELD = "point"  # the identity column of a point sweep (TrialKey.point)
PLAN_FIELDS = (
    "constraint_replans",  # plans that answered a constraint (an accepted a2(N)) at the world version it came in
    "plans_changed",  # those whose robots' actions differ from the plan they replaced
    "deliveries_reordered",  # robots whose order of the deliveries still to make changed in one of them (summed)
    "door_wait_time",  # s, all robots together, waiting at a human-operated door for it to open
)

KEY_FIELDS = ("method", "robots", "objects", "door_probability", "task_mean", "interruption_cost", "trial")

TRIAL_FIELDS = KEY_FIELDS + (
    "site_seed",  # runtime.site.generate.generate_site(robots, objects, site_seed)
    "seed",  # the sim's --seed
    "status",  # ok, unfinished, timeout, error
    "reason",
    "team_completion_time",  # s, the slowest agent, the human included
    "sum_of_times",  # s, every agent's completion time added up (the paper's real-world measure)
    "slowest_robot_time",  # s, the last delivery of the team
    "human_completion_time",  # s, her own task done
    "agent_completion_times",  # name=seconds;... each robot, then the human
    "door_openings",  # doors the human opened (her a1 actions): the paper's figure (a)
    "human_door_trips",  # walks to a door she began (some turn back when a focus interval starts)
    "human_task_time",  # s of work her own task needed (the Gaussian draw)
    "human_interruptions",  # walks to a door begun during one of her focus intervals
    "human_time_lost",  # s of her task lost to those interruptions (resuming it)
    "focus_declared",  # focus intervals she declared (a2(N), ARROCH only)
    "feedback_sent",  # a2(N) feedback the human sent (ARROCH only)
    "feedback_accepted",
    "replans",  # plans the lockstep made the planner answer: new world versions + accepted feedback
    "world_versions",
    "robot_wait_time",  # s, all robots together, waiting at doors
    "human_time_away",  # s she spent walking to doors and opening them
    "actions_failed",
    "robot_overlaps",  # times two robots' discs started to intersect (services/sim/overlaps.py; 0 is safe)
    "wall_contacts",  # times a robot's disc started to reach into a wall (services/sim/walls.py)
    "wall_depth_max",  # m, the deepest any robot's disc reached into a wall
    "sim_time",  # s of simulated time when the mission ended
)

TIMING_FIELDS = KEY_FIELDS + (
    "status",
    "wall_time",  # s, the whole trial: start-up, mission, shutdown
    "services_up",  # s until the planner and restrictor showed their liveliness tokens
    "sim_startup",  # s from starting the sim to its mission start, plus its end and our noticing it
    "mission_wall_time",  # s, the sim's own measure from mission start to mission end
    "shutdown",  # s to stop the trial's processes
    "plans",  # TeamPlans the planner published
    "planner_solve_time",  # s, the sum of their solve times
    "realtime_factor",  # sim seconds per wall second during the mission
    "code",  # fingerprint of the services' sources when the trial started (provenance.py)
)

DONE = ("ok", "unfinished")  # outcomes of the model: recorded for good, skipped by --resume


def trial_fields(spec: SweepSpec | None) -> tuple[str, ...]:
    """trials.csv's columns for ``spec`` (module docstring); the earlier sweeps' without one."""
    if spec is None or not spec.points:
        return TRIAL_FIELDS
    return KEY_FIELDS + (POINT_FIELD, *spec.factor_names()) + TRIAL_FIELDS[len(KEY_FIELDS) :] + PLAN_FIELDS


def timing_fields(spec: SweepSpec | None) -> tuple[str, ...]:
    if spec is None or not spec.points:
        return TIMING_FIELDS
    return KEY_FIELDS + (POINT_FIELD,) + TIMING_FIELDS[len(KEY_FIELDS) :]


def _t(value: Any) -> str:
    """A time (or any real number) to the millisecond; empty when unknown."""
    return "" if value is None else f"{float(value):.3f}"


def _n(value: Any) -> str:
    return "" if value is None else str(int(value))


def key_cells(key: TrialKey) -> dict[str, str]:
    cells = {
        "method": key.method,
        "robots": str(key.robots),
        "objects": str(key.objects),
        "door_probability": format_p(key.p),
        "task_mean": format_p(key.task),
        "interruption_cost": format_p(key.cost),
        "trial": str(key.trial),
    }
    if key.point >= 0:
        cells[POINT_FIELD] = str(key.point)
    return cells


def key_of(row: dict[str, str]) -> TrialKey:
    """The identity of a CSV row (raises ValueError on a malformed one)."""
    return TrialKey(
        row["method"],
        int(row["robots"]),
        int(row["objects"]),
        float(row["door_probability"]),
        float(row["task_mean"]),
        float(row["interruption_cost"]),
        int(row["trial"]),
        int(row.get(POINT_FIELD) or -1),
    )


def trial_row(spec: SweepSpec, outcome: TrialOutcome) -> dict[str, str]:
    key = outcome.key
    row = {name: "" for name in trial_fields(spec)}
    row.update(key_cells(key))
    row.update(
        site_seed=str(spec.site_seed(key)), seed=str(spec.sim_seed(key)), status=outcome.status, reason=outcome.reason
    )
    row.update({name: format_p(value) for name, value in spec.point(key).items() if name in row})
    m = outcome.metrics
    if m is None:
        return row
    agents: dict[str, Any] = m.get("agent_completion_times") or {}
    robots = {name: t for name, t in agents.items() if name != "human"}
    robot_times = [t for t in robots.values() if t is not None]
    human = m.get("human") or {}
    feedback = m.get("feedback") or {}
    times = [t for t in agents.values() if t is not None]
    row.update(
        team_completion_time=_t(m.get("team_completion_time")),
        sum_of_times=_t(sum(times)) if times and len(times) == len(agents) else "",
        slowest_robot_time=_t(max(robot_times)) if robot_times and len(robot_times) == len(robots) else "",
        human_completion_time=_t(agents.get("human")),
        agent_completion_times=";".join(
            f"{name}={_t(t)}" for name, t in [*sorted(robots.items()), ("human", agents.get("human"))]
        ),
        door_openings=_n(m.get("human_door_openings")),
        human_door_trips=_n(human.get("door_trips")),
        human_task_time=_t(human.get("task_duration")),
        human_interruptions=_n(human.get("interruptions")),
        human_time_lost=_t(human.get("time_lost")),
        focus_declared=_n(human.get("declarations")),
        feedback_sent=_n(feedback.get("sent")),
        feedback_accepted=_n(feedback.get("accepted")),
        replans=_n(max(0, int(m.get("world_versions") or 0) - 1) + int(feedback.get("accepted") or 0)),
        world_versions=_n(m.get("world_versions")),
        robot_wait_time=_t(sum(float(r.get("wait_time") or 0.0) for r in (m.get("robots") or {}).values())),
        human_time_away=_t(human.get("time_away")),
        actions_failed=_n((m.get("actions") or {}).get("failed")),
        robot_overlaps=_n(m.get("robot_overlaps")),
        wall_contacts=_n(m.get("wall_contacts")),
        wall_depth_max=_t(m.get("wall_depth_max")),
        sim_time=_t(m.get("time")),
    )
    changes = m.get("plan_changes")
    if changes is not None and PLAN_FIELDS[0] in row:
        row.update(
            constraint_replans=_n(changes.get("constraint_replans")),
            plans_changed=_n(changes.get("plans_changed")),
            deliveries_reordered=_n(changes.get("deliveries_reordered")),
            door_wait_time=_t(changes.get("door_wait_time")),
        )
    return row


def timing_row(outcome: TrialOutcome) -> dict[str, str]:
    timing = outcome.timing
    row = {name: "" for name in TIMING_FIELDS}
    row.update(key_cells(outcome.key))
    realtime = ((outcome.metrics or {}).get("run") or {}).get("realtime_factor")
    row.update(
        status=outcome.status,
        wall_time=_t(timing.get("wall")),
        services_up=_t(timing.get("services_up")),
        sim_startup=_t(timing.get("sim_startup")),
        mission_wall_time=_t(timing.get("mission")),
        shutdown=_t(timing.get("shutdown")),
        plans=_n(timing.get("plans")),
        planner_solve_time=_t(timing.get("solve_time")),
        realtime_factor=_t(realtime),
        code=outcome.code,
    )
    return row
