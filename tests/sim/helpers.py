"""Shared pieces of the simulator's tests: a small site, and driving an engine like a planner would."""

from __future__ import annotations

from dataclasses import dataclass

from protocol.messages import RobotCommand
from protocol.site import loads_site
from protocol.site.model import Site
from services.sim.engine import Engine, SimEvent
from services.sim.human import HumanConfig
from tests.sim.standin import ScriptedPlanner

# A corridor with a storage room behind a human-operated door (the human works inside) and an
# office behind an ordinary door. Two robots, one object each.
SMALL_SITE = """
[site]
name = "simtest"

[params]
robot_speed = 0.5
robot_radius = 0.25
load_time = 10.0
door_hold_time = 20.0
robot_capacity = 1

[[rooms]]
id = "corridor"
rect = [0.0, 4.0, 12.0, 6.0]

[[rooms]]
id = "storage"
rect = [4.0, 0.0, 8.0, 4.0]

[[rooms]]
id = "office"
rect = [0.0, 6.0, 6.0, 10.0]

[[doors]]
id = "d_storage"
rooms = ["corridor", "storage"]
center = [6.0, 4.0]
width = 0.9
human_operated = true

[[doors]]
id = "d_office"
rooms = ["corridor", "office"]
center = [3.0, 6.0]
width = 0.9

[[robots]]
id = "r0"
start = [1.0, 5.0, 0.0]

[[robots]]
id = "r1"
start = [10.0, 5.0, 3.14159]

[[objects]]
id = "o0"
position = [2.0, 8.0]
deliver_to = "storage"
robot = "r0"

[[objects]]
id = "o1"
position = [11.0, 5.0]
deliver_to = "storage"
robot = "r1"

[human]
room = "storage"
position = [7.0, 1.0]
"""


# A human who never opens a door and never focuses: the tests open doors themselves.
PASSIVE = HumanConfig(door_probability=0.0, focus_count=0)


def small_site() -> Site:
    return loads_site(SMALL_SITE, "simtest.toml")


def command(
    robot: str,
    action_id: int,
    action: str,
    args: list[str],
    points: list[tuple[float, float]],
    *,
    now: float = 0.0,
    speed: float = 0.5,
    duration: float = 0.0,
    plan_id: int = 1,
) -> RobotCommand:
    """A RobotCommand along straight segments through ``points`` (rows timed at ``speed``)."""
    import math

    rows, t = [], now
    for i, (x, y) in enumerate(points):
        if i:
            t += math.dist(points[i - 1], (x, y)) / speed
        nxt = points[min(i + 1, len(points) - 1)]
        prev = points[max(i - 1, 0)]
        a, b = (prev, (x, y)) if i == len(points) - 1 else ((x, y), nxt)
        rows.append([t, x, y, math.atan2(b[1] - a[1], b[0] - a[0])])
    return RobotCommand(
        robot=robot, plan_id=plan_id, action_id=action_id, action=action, args=args, trajectory=rows, duration=duration
    )


def run_mission(engine: Engine, *, max_time: float = 7200.0, planner: ScriptedPlanner | None = None) -> list[SimEvent]:
    """Drive ``engine`` with the scripted planner (or ``planner``), answering every world version at
    once, like a lockstep planner with zero solve time. Returns every event."""
    planner = planner or ScriptedPlanner(engine.site)
    engine.start()
    answered, plans, log = 0, 0, []
    while not engine.done and engine.time < max_time:
        for event in engine.take_events():
            log.append(event)
            if event.kind in ("action_done", "action_failed") and event.robot in planner.todo:
                planner.finished(event.robot, int(event.data.action_id), event.kind == "action_done")
        for request in engine.take_feedback():
            engine.feedback_answered(request, accepted=True, constraints_version=request.id)
        if engine.world_version > answered:
            answered = engine.world_version
            plans += 1
            poses = {rid: (r.x, r.y, r.theta) for rid, r in engine.robots.items()}
            for cmd in planner.commands(plans, engine.time, poses):
                engine.apply_command(cmd)
            continue  # the commands may have produced events (a failure) to answer first
        engine.step()
    log.extend(engine.take_events())
    return log


@dataclass
class Bot:
    """A robot as the traffic rules see it (runtime.executor.right_of_way.Body): its id, where it is, its phase."""

    id: str
    x: float
    y: float
    phase: str = "drive"
