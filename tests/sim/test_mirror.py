"""The engine mirrored into the real pybullet World: bodies never overlap walls or a shut leaf,
objects ride on their robot, and the mirror only touches pybullet for what changed."""

from __future__ import annotations

import pytest

from protocol.site import load_site
from services.sim.engine import Engine
from services.sim.mirror import WorldMirror
from services.sim.world import World
from tests.sim.standin import ScriptedPlanner


@pytest.fixture
def office():
    return load_site(None)


def test_no_robot_overlaps_a_closed_or_closing_leaf_nor_goes_deeper_into_a_wall_than_the_guard_allows(office):
    engine = Engine(office, method="no-feedback", seed=3)
    planner = ScriptedPlanner(office)
    leaf_contacts = 0
    with World(office) as world:
        mirror = WorldMirror(world, engine)
        engine.start()
        answered = plans = 0
        while not engine.done:
            for event in engine.take_events():
                if event.kind in ("action_done", "action_failed"):
                    assert event.kind == "action_done", event
                    planner.finished(event.robot, event.data.action_id, True)
            if engine.world_version > answered:
                answered, plans = engine.world_version, plans + 1
                for cmd in planner.commands(
                    plans, engine.time, {r: (b.x, b.y, b.theta) for r, b in engine.robots.items()}
                ):
                    engine.apply_command(cmd)
                continue
            engine.step()
            mirror.sync()
            for rid in engine.robots:
                # pybullet's exact distances between convex shapes; a wall only deeper than the
                # executor's wall guard allows (grazing a jamb's corner)
                hit = world.robot_blocked(rid, wall_tolerance=engine.executor.config.wall_tolerance + 1e-4)
                if hit is None:
                    continue
                assert hit in engine.doors.doors, f"{rid} overlaps {hit} at t={engine.time}"
                door = engine.doors[hit]
                # Never a closed leaf, never a closing one. An open or opening leaf may touch a robot:
                # one parked in its sweep (see doors.py), or one whose (here straight-line) path
                # grazes it, which is the motion planner's business, not the executor's.
                assert door.target_open and door.fraction > 0.0, (
                    f"{rid} overlaps {hit} (fraction {door.fraction}, opening {door.target_open}) at t={engine.time}"
                )
                leaf_contacts += 1
    assert engine.completed
    assert plans > 50


def test_mirror_pushes_only_changes_and_objects_ride_along(office):
    engine = Engine(office, method="no-feedback", seed=1)
    with World(office) as world:
        mirror = WorldMirror(world, engine)
        assert mirror.sync() > 0
        assert mirror.sync() == 0  # nothing changed: no pybullet call at all
        engine.start()
        robot = engine.robots["r0"]
        obj = engine.objects["o0"]
        engine.objects.pick("o0", "r0")
        robot.carrying.append("o0")
        robot.x, robot.y = 2.0, 5.0
        assert mirror.sync() == 2  # the robot moved, the object got attached
        assert world.carrier("o0") == "r0"
        (x, y, z), _ = world.pose_of("o0")
        assert (x, y) == pytest.approx((2.0, 5.0)) and z > 0.3  # on top of the robot
        engine.objects.place("o0", 7.0, 2.0, delivered_at=1.0)
        mirror.sync()
        assert world.carrier("o0") is None
        (x, y, _), _ = world.pose_of("o0")
        assert (x, y) == pytest.approx((7.0, 2.0))
        engine.doors.human_open("d_storage", 0.0)
        for _ in range(10):
            engine.step()
        mirror.sync()
        assert engine.doors["d_storage"].fraction > 0.0
        assert world.door_opening("d_storage") == pytest.approx(engine.doors["d_storage"].fraction)
        assert obj.delivered
