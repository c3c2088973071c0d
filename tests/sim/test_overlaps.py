"""Robot-robot contact: the simulator counts two discs that intersect (once per contact, by pair
and place), and its robots keep a margin - they stop for a robot ahead, a robot that must give way
backs off from one with the right of way, and a trajectory's hold is kept."""

from __future__ import annotations

import math

from services.sim.engine import Engine
from tests.sim.helpers import command, small_site


def engine() -> Engine:
    e = Engine(small_site(), method="no-feedback", seed=1)
    e.start()
    e.take_events()
    return e


def run_until(e: Engine, t: float) -> None:
    while e.time < t - 1e-9:
        e.step()


def overlaps(e: Engine) -> list:
    return [ev for ev in e.take_events() if ev.kind == "robot_overlap"]


def test_two_bodies_that_intersect_are_one_overlap_each_time_they_meet():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r0.x, r0.y = 8.0, 5.0
    r1.x, r1.y = 8.45, 5.0  # 0.45 m apart: the 0.25 m discs intersect by 5 cm
    for _ in range(5):
        e.step()  # however long they stay so, one overlap
    (event,) = overlaps(e)
    assert event.data["robots"] == ["r0", "r1"] and event.data["place"] == "corridor"
    assert abs(event.data["depth"] - 0.05) < 1e-6
    r1.x = 9.0  # apart ...
    e.step()
    r1.x, r1.y = 3.0, 5.9  # ... and again, in d_office's doorway this time
    r0.x, r0.y = 3.0, 6.3
    e.step()
    (again,) = overlaps(e)
    assert again.data["place"] == "d_office"
    summary = e.summary()
    assert summary["robot_overlaps"] == 2
    assert summary["robot_overlaps_by_pair"] == {"r0-r1": 2}
    assert summary["robot_overlaps_by_place"] == {"corridor": 1, "d_office": 1}


def test_robots_that_only_come_near_are_no_overlap():
    e = engine()
    e.robots["r0"].x, e.robots["r0"].y = 8.0, 5.0
    e.robots["r1"].x, e.robots["r1"].y = 8.5, 5.0  # touching, not intersecting
    e.step()
    assert overlaps(e) == [] and e.summary()["robot_overlaps"] == 0


def test_a_robot_stops_short_of_a_parked_robot_and_goes_on_only_after_its_patience():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r1.x, r1.y = 6.0, 5.0  # parked on r0's way (no command)
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(1.0, 5.0), (11.0, 5.0)]))
    run_until(e, 15.0)
    gap = math.dist((r0.x, r0.y), (r1.x, r1.y))
    limit = 2 * 0.25 + e.executor.config.robot_margin
    assert limit - 0.03 <= gap < limit + 0.03  # stopped at the margin
    assert r0.yield_time > 3.0 and overlaps(e) == []
    # A parked robot waits for nothing: after the patience r0 goes on (the contact is counted).
    run_until(e, 40.0)
    assert r0.x > 7.0 and len(overlaps(e)) == 1


def test_head_on_the_robot_without_the_right_of_way_backs_off():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r0.x, r0.y, r0.theta = 2.0, 5.0, 0.0
    r1.x, r1.y, r1.theta = 7.0, 5.0, math.pi
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(2.0, 5.0), (6.0, 5.0)]))
    e.apply_command(command("r1", 1, "approach", ["d_office"], [(7.0, 5.0), (3.0, 5.0)]))
    least = math.inf
    while r0.phase == "drive" and e.time < 30.0:
        e.step()
        least = min(least, math.dist((r0.x, r0.y), (r1.x, r1.y)))
    assert r0.phase == "done"  # r0 (the priority) got where it was going
    assert least >= 0.5 and overlaps(e) == []
    assert r1.x > 6.0 + 0.5  # r1 backed off east to let it


def test_a_hold_keeps_the_robot_in_place_until_its_time():
    e = engine()
    r0 = e.robots["r0"]
    cmd = command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (3.0, 5.0)])
    rows = [[0.0, 1.0, 5.0, 0.0], [6.0, 1.0, 5.0, 0.0], *[[t + 6.0, x, y, th] for t, x, y, th in cmd.trajectory[1:]]]
    cmd.trajectory = rows
    e.apply_command(cmd)
    run_until(e, 5.9)
    assert (r0.x, r0.y) == (1.0, 5.0) and r0.state == "moving"
    run_until(e, 12.0)
    assert r0.x > 2.5
