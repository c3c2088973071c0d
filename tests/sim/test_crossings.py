"""The closed-door invariant: a robot forced through a closed door is caught (and pybullet agrees
that it overlaps the leaf there); the same pass through the open door, and whole missions, are not."""

from __future__ import annotations

import math

import pytest

from protocol.site import load_site
from services.sim.engine import Engine
from services.sim.mirror import WorldMirror
from services.sim.world import World
from tests.sim.helpers import run_mission, small_site

DOOR = "d_office"  # automatic door between corridor (y < 6) and office (y > 6), centre (3, 6)


def straight_pass(step: float = 0.02) -> list[tuple[float, float]]:
    """Points from the corridor, through the middle of d_office's gap, into the office."""
    n = round(1.6 / step)
    return [(3.0, 5.2 + i * step) for i in range(n + 1)]


def force_pass(engine: Engine, world: World | None = None) -> tuple[list[bool], list[bool]]:
    """Put r0 at each point of the pass (no command: only the pose is forced) and step one tick.

    Returns, per point, whether r0 was in the closed doorway by the engine's watch, and (with a
    pybullet world) whether pybullet found r0's cylinder overlapping the leaf."""
    robot = engine.robots["r0"]
    mirror = WorldMirror(world, engine) if world is not None else None
    watched, blocked = [], []
    for x, y in straight_pass():
        robot.x, robot.y, robot.theta = x, y, math.pi / 2
        engine.step()
        watched.append(("r0", DOOR) in engine.closed_doors._inside)
        if mirror is not None:
            mirror.sync()
            blocked.append(world.robot_blocked("r0") == DOOR)
    return watched, blocked


def test_a_robot_forced_through_a_closed_door_is_one_crossing_and_pybullet_sees_the_overlap():
    site = small_site()
    engine = Engine(site, method="no-feedback", seed=1)
    engine.start()
    engine.take_events()
    assert not engine.doors.passable(DOOR)
    with World(site) as world:
        watched, blocked = force_pass(engine, world)
    assert not engine.doors.passable(DOOR), "nothing asked the automatic door to open"
    events = [e for e in engine.take_events() if e.kind == "closed_door_crossing"]
    # One entry into the doorway, however many ticks the robot spent in it.
    assert len(events) == 1
    (event,) = events
    assert (event.robot, event.door) == ("r0", DOOR)
    assert event.data.fraction == 0.0 and 0.0 < event.data.depth <= 0.05
    assert engine.metrics.closed_door_crossings == 1
    assert engine.summary()["closed_door_crossings"] == 1
    # The watch and pybullet's exact overlap of the robot's cylinder with the closed leaf agree:
    # wherever the watch has the robot in the closed doorway, pybullet has it overlapping the leaf,
    # and pybullet's overlap reaches no further than the leaf's half thickness (2 cm, plus one
    # point of the pass) beyond the gap's line on either side.
    assert any(watched)
    assert all(b for w, b in zip(watched, blocked, strict=True) if w)
    points = straight_pass()
    leaf_y = [y for (_, y), b in zip(points, blocked, strict=True) if b]
    watch_y = [y for (_, y), w in zip(points, watched, strict=True) if w]
    assert min(watch_y) - min(leaf_y) <= 0.04 + 1e-9 and max(leaf_y) - max(watch_y) <= 0.04 + 1e-9


def test_a_second_entry_counts_again_and_the_open_door_counts_nothing():
    site = small_site()
    engine = Engine(site, method="no-feedback", seed=1)
    engine.start()
    force_pass(engine)
    force_pass(engine)  # back to the corridor side (out of the doorway), then through again
    assert engine.metrics.closed_door_crossings == 2

    engine = Engine(site, method="no-feedback", seed=1)
    engine.start()
    door = engine.doors[DOOR]
    door.target_open, door.fraction = True, 1.0
    door.requests.add("r0")  # keeps the automatic door open for the whole pass
    robot = engine.robots["r0"]
    for x, y in straight_pass():
        robot.x, robot.y = x, y
        door.requests.add("r0")
        engine.step()
    assert engine.doors.passable(DOOR)
    assert engine.metrics.closed_door_crossings == 0
    assert not [e for e in engine.take_events() if e.kind == "closed_door_crossing"]


@pytest.mark.parametrize("method", ["arroch", "no-comm"])
def test_a_whole_mission_has_no_closed_door_crossing(method):
    engine = Engine(load_site(None), method=method, seed=2)
    events = run_mission(engine)
    done = events[-1]
    assert done.kind == "mission_done" and done.data.completed is True
    assert done.data.closed_door_crossings == 0
    assert not [e for e in events if e.kind == "closed_door_crossing"]
    # the doors really were used: the watch had closed doors with robots near them to look at
    assert sum(n for per in done.data.door_openings.values() for n in per.values()) > 5
