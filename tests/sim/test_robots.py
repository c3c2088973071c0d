"""Robots executing commands in the engine: doors, loading, failures (no network, no pybullet)."""

from __future__ import annotations

import math

import pytest
from msgspec import UNSET

from runtime.executor.walls import TOUCH
from runtime.plane import segment_distance
from services.sim.engine import Engine
from tests.sim.helpers import PASSIVE, command, small_site

RADIUS = 0.25


@pytest.fixture
def engine() -> Engine:
    e = Engine(small_site(), method="no-feedback", seed=1, human=PASSIVE)
    e.start()
    e.take_events()
    return e


def run_until(engine: Engine, predicate, limit: float = 120.0, on_step=None):
    events = []
    while not predicate(events):
        assert engine.time < limit, f"condition not met by t={engine.time}"
        engine.step()
        new = engine.take_events()
        events.extend(new)
        if on_step:
            on_step()
    return events


def kinds(events, kind):
    return [e for e in events if e.kind == kind]


def gap_distance(engine: Engine, door: str, rid: str) -> float:
    a, b = engine.site.doors[door].endpoints
    r = engine.robots[rid]
    return segment_distance((r.x, r.y), a, b)


def test_robot_stops_before_a_closed_door_and_goes_on_once_it_opens(engine):
    engine.apply_command(command("r0", 1, "gothrough", ["d_storage"], [(1.0, 5.0), (6.0, 5.0), (6.0, 3.0)]))
    closest = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "waiting_at_door"),
        on_step=lambda: closest.append(gap_distance(engine, "d_storage", "r0")),
    )
    wait = kinds(events, "waiting_at_door")[0]
    assert wait.robot == "r0" and wait.door == "d_storage"
    r0 = engine.robots["r0"]
    assert r0.state == "waiting_at_door" and r0.waiting_door == "d_storage"
    # Stopped radius + stop margin (0.15 m) short of the leaf's line, never closer.
    assert r0.y == pytest.approx(4.0 + RADIUS + 0.15, abs=0.02)
    # It stays there while the door stays shut.
    held_at = (r0.x, r0.y)
    run_until(
        engine,
        lambda ev: engine.time >= wait.time + 30.0,
        on_step=lambda: closest.append(gap_distance(engine, "d_storage", "r0")),
    )
    assert (r0.x, r0.y) == held_at and r0.state == "waiting_at_door"
    assert min(closest) >= RADIUS + 0.05  # never touched the closed leaf
    version = engine.world_version
    engine.doors.human_open("d_storage", engine.time)
    events = run_until(engine, lambda ev: kinds(ev, "action_done"))
    opened = kinds(events, "door_opened")[0]
    assert opened.door == "d_storage" and opened.data.by == "human"
    assert opened.data.world_version == version + 1  # a human door's change is a new world
    done = kinds(events, "action_done")[0]
    assert done.time > opened.time
    assert done.data.action == "gothrough" and done.data.action_id == 1
    assert math.dist((r0.x, r0.y), (6.0, 3.0)) <= 0.02
    assert engine.site.room_at(r0.x, r0.y).id == "storage"


def test_a_door_closing_in_front_of_a_robot_stops_it_before_the_leaf(engine):
    engine.doors.human_open("d_storage", 0.0)
    run_until(engine, lambda ev: engine.time >= 14.0)
    # r1 needs more than 10 s to get there: the hold time (20 s) runs out on the way.
    engine.apply_command(
        command("r1", 1, "gothrough", ["d_storage"], [(10.0, 5.0), (6.0, 5.0), (6.0, 3.0)], now=engine.time)
    )
    closest = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "action_done"),
        limit=200,
        on_step=lambda: (
            closest.append(gap_distance(engine, "d_storage", "r1")) if not engine.doors.passable("d_storage") else None,
            engine.doors.human_open("d_storage", engine.time)
            if engine.robots["r1"].state == "waiting_at_door"
            else None,
        ),
    )
    assert kinds(events, "door_closed") and kinds(events, "waiting_at_door")
    assert min(closest) >= RADIUS + 0.05


def test_automatic_door_opens_for_the_approaching_robot_and_closes_after_it(engine):
    engine.apply_command(command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (3.0, 5.4)]))
    events = run_until(engine, lambda ev: kinds(ev, "action_done"))
    opened = kinds(events, "door_opened")
    assert opened and opened[0].door == "d_office" and opened[0].data.by == "r0"
    assert opened[0].data.world_version is UNSET  # automatic doors do not make the planner replan
    # Through, and on beyond the leaf's reach (a leaf never closes onto a robot in its sweep).
    engine.apply_command(command("r0", 2, "gothrough", ["d_office"], [(3.0, 5.4), (3.0, 7.5)], now=engine.time))
    crossed, clear_at_close = [], []

    def watch() -> None:
        if engine.robots["r0"].y > 6.0 and not crossed:
            crossed.append(engine.time)
        if not engine.doors["d_office"].target_open and not clear_at_close:
            clear_at_close.append(gap_distance(engine, "d_office", "r0"))

    events = run_until(engine, lambda ev: kinds(ev, "door_closed") and kinds(ev, "action_done"), on_step=watch)
    assert not kinds(events, "waiting_at_door")  # it was open in time
    closed = kinds(events, "door_closed")[0]
    assert closed.time >= crossed[0] + 1.0  # after the robot passed, and the closing delay
    assert clear_at_close[0] > RADIUS + 0.1  # doorway clear when it closed


def test_automatic_door_opens_ahead_of_a_robot_on_its_way(engine):
    # Asked 1.75 m ahead, the door has swung open before the robot gets there: no stop.
    engine.apply_command(command("r0", 1, "gothrough", ["d_office"], [(1.0, 5.0), (3.0, 5.0), (3.0, 7.0)]))
    crossed = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "action_done"),
        on_step=lambda: crossed.append(engine.time) if engine.robots["r0"].y > 6.0 - RADIUS and not crossed else None,
    )
    opened = kinds(events, "door_opened")[0]
    assert crossed[0] > opened.time  # its disc reached the door line only once the door was open
    assert not kinds(events, "waiting_at_door")
    assert engine.robots["r0"].y == pytest.approx(7.0, abs=0.02)


def test_robot_starting_right_at_an_automatic_door_waits_for_its_swing(engine):
    engine.apply_command(command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (1.0, 5.1)]))
    run_until(engine, lambda ev: kinds(ev, "action_done"))
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = 3.0, 5.4, math.pi / 2  # placed beside the closed door
    engine.apply_command(command("r0", 2, "gothrough", ["d_office"], [(3.0, 5.4), (3.0, 6.6)], now=engine.time))
    events = run_until(engine, lambda ev: kinds(ev, "action_done"))
    waited, opened = kinds(events, "waiting_at_door")[0], kinds(events, "door_opened")[0]
    assert waited.door == "d_office" and waited.time < opened.time
    assert opened.time - waited.time <= engine.config.door_swing_time
    assert r0.y == pytest.approx(6.6, abs=0.02)


def test_a_robot_back_in_front_of_a_door_it_had_reached_waits_for_it_again(engine):
    """Progress along a path never goes back, but a robot can (it backs away from a robot with the
    right of way): one that is in front of a door again asks an automatic door to open and reports
    that it waits, instead of pushing against the shut leaf for ever unseen."""
    engine.apply_command(command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (1.0, 5.1)]))
    run_until(engine, lambda ev: kinds(ev, "action_done"))
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = 3.0, 5.4, math.pi / 2
    engine.apply_command(command("r0", 2, "gothrough", ["d_office"], [(3.0, 5.4), (3.0, 7.0)], now=engine.time))
    run_until(engine, lambda ev: r0.y > 6.05)  # its centre just through the door line
    assert r0.follower is not None and r0.follower.s > r0.crossings[0][0]
    r0.y = 5.0  # set back in front of it, and the door shut behind its back
    door = engine.doors["d_office"]
    door.target_open, door.fraction = False, 0.0
    events = run_until(engine, lambda ev: kinds(ev, "action_done"), limit=engine.time + 60.0)
    waited, opened = kinds(events, "waiting_at_door"), kinds(events, "door_opened")
    assert waited and waited[0].door == "d_office" and opened and waited[0].time <= opened[0].time
    assert r0.y == pytest.approx(7.0, abs=0.02)


def test_a_robot_in_the_doorway_may_be_given_the_rest_of_its_passage(engine):
    """Re-commanded while its disc is over the door's line (its centre already past it), a robot gets
    a gothrough whose trajectory no longer crosses the line: that finishes the passage. Out of the
    doorway, the same command is refused."""
    door = engine.doors["d_office"]
    door.target_open, door.fraction = True, 1.0
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = 3.0, 6.1, math.pi / 2  # the line is y = 6; the disc's radius 0.25
    engine.apply_command(command("r0", 1, "gothrough", ["d_office"], [(3.0, 6.1), (3.0, 7.0)], now=engine.time))
    events = run_until(engine, lambda ev: kinds(ev, "action_done") or kinds(ev, "action_failed"))
    assert kinds(events, "action_done") and r0.y == pytest.approx(7.0, abs=0.02)
    engine.apply_command(command("r0", 2, "gothrough", ["d_office"], [(3.0, 7.0), (3.0, 7.5)], now=engine.time))
    failed = kinds(run_until(engine, lambda ev: kinds(ev, "action_failed")), "action_failed")
    assert "does not cross" in failed[0].data.reason


def test_human_door_stays_open_while_the_doorway_is_occupied(engine):
    engine.doors.human_open("d_storage", 0.0)
    events = run_until(engine, lambda ev: kinds(ev, "door_opened"))
    opened_at = kinds(events, "door_opened")[0].time
    # r1 parks in the doorway for a while.
    engine.apply_command(
        command("r1", 1, "approach", ["d_storage"], [(10.0, 5.0), (6.0, 5.0), (6.0, 4.0)], now=engine.time)
    )
    run_until(engine, lambda ev: kinds(ev, "action_done"))
    events = run_until(engine, lambda ev: engine.time >= opened_at + 40.0)
    assert not kinds(events, "door_closed")  # hold time long over, but the doorway is not clear
    engine.apply_command(command("r1", 2, "approach", ["d_storage"], [(6.0, 4.0), (6.0, 5.5)], now=engine.time))
    events = run_until(engine, lambda ev: kinds(ev, "door_closed"))
    closed = kinds(events, "door_closed")[0]
    assert closed.data.world_version > 0
    assert gap_distance(engine, "d_storage", "r1") > RADIUS + 0.1


def test_human_door_closes_after_the_hold_time(engine):
    engine.doors.human_open("d_storage", 0.0)
    events = run_until(engine, lambda ev: kinds(ev, "door_closed"))
    opened, closed = kinds(events, "door_opened")[0], kinds(events, "door_closed")[0]
    assert closed.time - opened.time == pytest.approx(engine.site.params.door_hold_time, abs=0.06)
    assert opened.data.until == pytest.approx(closed.time, abs=0.06)


def test_load_and_unload_take_load_time_and_the_object_rides_along(engine):
    load_time = engine.site.params.load_time
    engine.apply_command(command("r1", 1, "load", ["o1"], [(10.0, 5.0), (10.8, 5.0)], duration=load_time))
    started = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "action_done"),
        on_step=lambda: started.append(engine.time) if engine.robots["r1"].state == "loading" and not started else None,
    )
    loaded = kinds(events, "loaded")[0]
    assert loaded.object == "o1" and loaded.robot == "r1"
    assert loaded.time - (started[0] - engine.config.tick) == pytest.approx(load_time, abs=engine.config.tick + 1e-9)
    assert engine.objects["o1"].carrier == "r1" and engine.robots["r1"].carrying == ["o1"]
    # Into the storage room (the door opened by the human beforehand), then unload.
    engine.doors.human_open("d_storage", engine.time)
    path = [(10.8, 5.0), (6.0, 5.0), (6.0, 2.5)]
    engine.apply_command(command("r1", 2, "gothrough", ["d_storage"], path, now=engine.time))
    run_until(engine, lambda ev: kinds(ev, "action_done"))
    r1 = engine.robots["r1"]
    engine.apply_command(
        command("r1", 3, "unload", ["o1"], [(r1.x, r1.y), (5.5, 2.0)], now=engine.time, duration=load_time)
    )
    events = run_until(engine, lambda ev: kinds(ev, "action_done"))
    delivered = kinds(events, "delivered")[0]
    assert delivered.object == "o1"
    obj = engine.objects["o1"]
    assert obj.delivered and obj.carrier is None and obj.delivered_at == pytest.approx(delivered.time)
    assert (obj.x, obj.y) == pytest.approx((r1.x, r1.y))
    assert r1.carrying == [] and r1.delivered == ["o1"]
    assert engine.metrics.robot_done["r1"] == pytest.approx(delivered.time)


@pytest.mark.parametrize(
    "cmd, reason",
    [
        (command("r0", 1, "load", ["o1"], [(1.0, 5.0), (2.0, 5.0)]), "belongs to robot 'r1'"),
        (command("r0", 1, "load", ["nope"], [(1.0, 5.0), (2.0, 5.0)]), "no object"),
        (command("r0", 1, "unload", ["o0"], [(1.0, 5.0), (2.0, 5.0)]), "does not carry"),
        (command("r0", 1, "approach", ["d_nowhere"], [(1.0, 5.0), (2.0, 5.0)]), "no door or passage"),
        (command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (1.0, 7.0)]), "crosses a wall"),
        (command("r0", 1, "approach", ["d_office"], [(5.0, 5.0), (3.0, 5.4)]), "starts 4.00 m from the robot"),
        (command("r0", 1, "gothrough", ["d_storage"], [(1.0, 5.0), (3.0, 5.0)]), "does not cross"),
        (command("r0", 1, "gothrough", ["d_storage"], []), "empty trajectory"),
    ],
)
def test_commands_that_cannot_be_executed_fail_with_a_reason(engine, cmd, reason):
    version = engine.world_version
    assert engine.apply_command(cmd) == "applied"
    failed = kinds(engine.take_events(), "action_failed")
    assert len(failed) == 1 and reason in failed[0].data.reason
    assert failed[0].data.action_id == 1 and failed[0].data.world_version == version + 1
    assert engine.robots["r0"].state == "failed"
    engine.step()  # and the engine goes on


def test_load_out_of_reach_and_unload_in_the_wrong_room_fail_on_arrival(engine):
    engine.apply_command(command("r0", 1, "load", ["o0"], [(1.0, 5.0), (2.0, 5.0)]))
    events = run_until(engine, lambda ev: kinds(ev, "action_failed"))
    assert "reach" in kinds(events, "action_failed")[0].data.reason
    engine.apply_command(command("r1", 1, "load", ["o1"], [(10.0, 5.0), (10.8, 5.0)]))
    run_until(engine, lambda ev: kinds(ev, "action_done"))
    engine.apply_command(command("r1", 2, "unload", ["o1"], [(10.8, 5.0), (9.0, 5.0)], now=engine.time))
    events = run_until(engine, lambda ev: kinds(ev, "action_failed"))
    assert "goes to 'storage'" in kinds(events, "action_failed")[0].data.reason
    assert engine.robots["r1"].carrying == ["o1"]  # still has it


def test_stale_commands_are_ignored_and_new_ones_preempt(engine):
    engine.apply_command(command("r0", 5, "approach", ["d_office"], [(1.0, 5.0), (3.0, 5.4)]))
    for _ in range(20):
        engine.step()
    assert engine.apply_command(command("r0", 5, "approach", ["d_office"], [(1.0, 5.0), (8.0, 5.0)])) == "stale"
    assert engine.apply_command(command("r0", 4, "approach", ["d_office"], [(1.0, 5.0), (8.0, 5.0)])) == "stale"
    r0 = engine.robots["r0"]
    assert engine.apply_command(command("r0", 6, "stop", [], [])) == "applied"
    done = kinds(engine.take_events(), "action_done")
    assert done and done[0].data.action == "stop" and done[0].data.world_version is UNSET
    x, y = r0.x, r0.y
    for _ in range(20):
        engine.step()
    assert (r0.x, r0.y) == (x, y) and r0.state == "idle"


def test_unknown_robot_is_reported_not_fatal(engine):
    assert engine.apply_command(command("r9", 1, "stop", [], [])) == "unknown_robot"
    failed = kinds(engine.take_events(), "action_failed")
    assert failed and failed[0].robot == "r9"


def test_a_leaf_never_closes_onto_a_robot_in_its_sweep(engine):
    # d_storage swings into the storage room; r1 parks there 0.6 m from the door, within the leaf's reach.
    engine.doors.human_open("d_storage", 0.0)
    run_until(engine, lambda ev: engine.doors.passable("d_storage"))
    engine.apply_command(
        command("r1", 1, "gothrough", ["d_storage"], [(10.0, 5.0), (6.0, 5.0), (6.0, 3.4)], now=engine.time)
    )
    events = run_until(engine, lambda ev: engine.time >= 60.0)
    assert kinds(events, "action_done") and not kinds(events, "door_closed")  # hold long over, robot in the sweep
    engine.apply_command(command("r1", 2, "approach", ["d_storage"], [(6.0, 3.4), (7.0, 1.5)], now=engine.time))
    events = run_until(engine, lambda ev: kinds(ev, "door_closed"))
    leaf = engine.site.door_leaves["d_storage"]
    r1 = engine.robots["r1"]
    assert math.dist((r1.x, r1.y), leaf.hinge) > leaf.length + RADIUS


def test_a_robot_facing_a_shut_doors_gap_turns_where_it_stands_and_drives_off(engine):
    # Beside the shut door's gap, facing it; its way leads off along the corridor. Every step
    # forward would first bring its disc nearer the gap, which the guard refuses: it must turn first.
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = 5.8, 4.25, -0.68
    start = gap_distance(engine, "d_storage", "r0")
    engine.apply_command(command("r0", 1, "approach", ["d_storage"], [(5.8, 4.25), (7.35, 4.6)]))
    closest = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "action_done") or kinds(ev, "action_failed"),
        limit=30.0,
        on_step=lambda: closest.append(gap_distance(engine, "d_storage", "r0")),
    )
    assert kinds(events, "action_done") and not kinds(events, "action_failed")
    assert math.dist((r0.x, r0.y), (7.35, 4.6)) < 0.3
    assert min(closest) >= start - 1e-9  # never nearer the shut gap than it started


def test_a_drive_the_shut_door_guard_holds_for_30_s_fails_so_the_planner_plans_again(engine):
    # A trajectory that ends in the doorway of a shut door without crossing it: no waiting_at_door
    # (the door is not on its way), so nobody would open it; the guard stops the robot short.
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = 6.0, 4.8, -math.pi / 2
    engine.apply_command(command("r0", 1, "approach", ["d_storage"], [(6.0, 4.8), (6.0, 4.02)]))
    held_from = []

    def note_held():
        if not held_from and r0.v == 0.0 and gap_distance(engine, "d_storage", "r0") < RADIUS + 0.05:
            held_from.append(engine.time)

    events = run_until(engine, lambda ev: kinds(ev, "action_failed"), limit=60.0, on_step=note_held)
    failed = kinds(events, "action_failed")[0]
    assert failed.robot == "r0" and "shut door" in failed.data.reason
    assert not kinds(events, "waiting_at_door") and not kinds(events, "action_done")
    assert failed.time - held_from[0] == pytest.approx(30.0, abs=0.5)
    assert gap_distance(engine, "d_storage", "r0") >= RADIUS - 1e-9  # its disc never entered the gap


def _wall_depth(engine: Engine, rid: str) -> float:
    """How deep the robot's disc reaches into the walls (0 when it touches none)."""
    r = engine.robots[rid]

    def distance(box: tuple[float, float, float, float]) -> float:  # from the centre to the wall's box
        x0, y0, x1, y1 = box
        return math.hypot(max(x0 - r.x, 0.0, r.x - x1), max(y0 - r.y, 0.0, r.y - y1))

    return max(0.0, *(RADIUS - distance(w.box) for w in engine.site.walls))


def _approach_beside_the_open_storage_door(engine: Engine, pose, points) -> float:
    """r0 placed at ``pose`` with the storage door open drives an approach through ``points`` to its
    end (asserted); how deep its disc went into a wall."""
    engine.doors.human_open("d_storage", 0.0)
    run_until(engine, lambda ev: engine.doors.passable("d_storage"))
    r0 = engine.robots["r0"]
    r0.x, r0.y, r0.theta = pose
    engine.apply_command(command("r0", 1, "approach", ["d_storage"], points, now=engine.time))
    deepest = []
    events = run_until(
        engine,
        lambda ev: kinds(ev, "action_done") or kinds(ev, "action_failed"),
        limit=engine.time + 40.0,
        on_step=lambda: deepest.append(_wall_depth(engine, "r0")),
    )
    assert kinds(events, "action_done"), [e.data for e in events]
    assert math.dist((r0.x, r0.y), points[-1]) < 0.3
    return max(deepest)


def test_a_robot_off_its_trajectory_in_the_next_room_goes_back_through_the_doorway_not_the_wall(engine):
    # Beside the open storage door's gap in the corridor (where making way may leave a robot), its
    # way on is in the storage room: the straight line to it crosses the wall stub east of the gap.
    deepest = _approach_beside_the_open_storage_door(engine, (6.75, 4.35, -math.pi / 2), [(6.0, 3.5), (7.4, 2.8)])
    assert deepest < 0.01, f"its disc went {deepest:.3f} m into a wall"


def test_a_robot_off_its_trajectory_near_its_end_goes_back_through_the_doorway(engine):
    # As above, but its drive ends 0.2 m past where it stands (projected): its way back has the
    # trajectory's end as its goal, not a point further on that does not exist.
    deepest = _approach_beside_the_open_storage_door(engine, (6.75, 4.35, -math.pi / 2), [(6.0, 3.5), (6.9, 3.45)])
    assert deepest < 0.01, f"its disc went {deepest:.3f} m into a wall"


def test_a_robot_cutting_the_corner_at_a_doorways_jamb_goes_along_it_and_never_into_it(engine):
    # Just inside the storage room, 5 mm from the open doorway's east jamb, facing the wall; its
    # trajectory runs east along the wall 0.35 m off (as the motion planner keeps it: the robot's
    # radius and the wall clearance, 0.316 m), 0.25 m from the robot (near enough that it does not
    # plan a way back). Heading straight for the trajectory cuts the jamb's corner: the guard refuses
    # that, and the robot goes along the jamb (south, away from the corner) until it is clear.
    deepest = _approach_beside_the_open_storage_door(engine, (6.2, 3.9, 0.6), [(6.0, 3.6), (7.5, 3.6)])
    assert deepest <= TOUCH, deepest  # it touches the jamb at most: no wall contact
