"""Robot-robot contact: the simulator counts two discs that intersect (once per contact, by pair
and place), and its robots do not touch - they stop for a robot ahead, drive around one that keeps
them back, cross a doorway one at a time, queue behind a robot standing where they are going, and
never push through (wedged for long, the action fails and the planner plans again); a trajectory's
hold is kept. Robot-wall contacts are counted the same way."""

from __future__ import annotations

import math

from runtime.executor.avoidance import REACHED
from runtime.executor.doorways import in_lane
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
    assert event.data.robots == ["r0", "r1"] and event.data.place == "corridor"
    assert abs(event.data.depth - 0.05) < 1e-6
    r1.x = 9.0  # apart ...
    e.step()
    r1.x, r1.y = 3.0, 5.9  # ... and again, in d_office's doorway this time
    r0.x, r0.y = 3.0, 6.3
    e.step()
    (again,) = overlaps(e)
    assert again.data.place == "d_office"
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


def closest_approach(e: Engine, until: float, *robots: str) -> float:
    """Run ``e`` until ``until`` (or every robot named is done); the least centre distance seen."""
    least = math.inf
    bodies = [e.robots[r] for r in robots]
    while e.time < until - 1e-9 and any(b.phase == "drive" for b in bodies):
        e.step()
        least = min(least, min(math.dist((a.x, a.y), (b.x, b.y)) for a in bodies for b in bodies if a is not b))
    return least


def test_a_robot_kept_back_by_a_parked_robot_drives_around_it():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r1.x, r1.y = 6.0, 5.0  # parked on r0's way (no command), in the middle of the 2 m corridor
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(1.0, 5.0), (11.0, 5.0)]))
    run_until(e, 10.0)
    gap = math.dist((r0.x, r0.y), (r1.x, r1.y))
    assert 0.5 <= gap < 0.6 and r0.x < 6.0  # stopped short of it first ...
    least = closest_approach(e, 60.0, "r0", "r1")
    assert r0.phase == "done" and r0.x > 10.9  # ... then around it to the end of its trajectory
    assert least >= 0.5 and overlaps(e) == [] and e.summary()["robot_overlaps"] == 0


def test_a_robot_all_but_touching_a_parked_robot_backs_off_and_drives_around_it():
    # Where two robots stood in a generated storage room (shifted into this one's): r0, told to
    # approach the door, is 0.5055 m from r1 (its disc 5.5 mm from r1's), r1 right on its way. The
    # way around starts almost along r1's disc: every step of it would close in, and solid bodies
    # refused each one, so r0 never set off and its approach failed every 12 s. It backs off first.
    # (r1 is not asked to make way here: r0 must get round it on its own.)
    e = engine()
    e.executor.make_way.ask = lambda asker, asked, way, now: False
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r1.x, r1.y = 5.6125, 2.611
    r0.x, r0.y, r0.theta = 5.9827, 2.2668, 1.2657
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(r0.x, r0.y), (5.1, 3.4)]))
    least, events = math.inf, []
    while e.time < 60.0 and r0.phase == "drive":
        e.step()
        events += e.take_events()
        least = min(least, math.dist((r0.x, r0.y), (r1.x, r1.y)))
    assert [ev for ev in events if ev.kind == "action_failed"] == []
    assert r0.phase == "done" and math.dist((r0.x, r0.y), (5.1, 3.4)) < 0.1
    assert least >= 0.505 - 1e-9 and not [ev for ev in events if ev.kind == "robot_overlap"]


def test_a_way_planned_beside_a_robot_it_all_but_touches_starts_straight_away_from_it():
    e = engine()
    avoidance, r0 = e.executor.avoidance, e.robots["r0"]
    r0.x, r0.y = 5.9827, 2.2668
    other = (5.6125, 2.611)
    points = avoidance._search(r0, (e.site.rooms["storage"],), (5.1, 3.4), [other])
    away = math.atan2(r0.y - other[1], r0.x - other[0])
    first = points[0]
    assert math.isclose(math.atan2(first[1] - r0.y, first[0] - r0.x), away, abs_tol=1e-6)
    assert math.dist(first, other) >= 2 * avoidance.radius + avoidance.clearance
    assert math.dist(first, (r0.x, r0.y)) > REACHED  # farther than a reached point: it is driven
    r0.x, r0.y = 6.5, 1.5  # with room around it, a robot plans from where it stands
    assert avoidance._backed_off(r0, [other]) is None


def test_two_robots_head_on_in_a_corridor_pass_each_other_without_touching():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r0.x, r0.y, r0.theta = 2.0, 5.0, 0.0
    r1.x, r1.y, r1.theta = 10.0, 5.0, math.pi
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(2.0, 5.0), (10.0, 5.0)]))
    e.apply_command(command("r1", 1, "approach", ["d_office"], [(10.0, 5.0), (2.0, 5.0)]))
    least = closest_approach(e, 90.0, "r0", "r1")
    assert r0.phase == r1.phase == "done"
    assert math.dist((r0.x, r0.y), (10.0, 5.0)) < 0.05 and math.dist((r1.x, r1.y), (2.0, 5.0)) < 0.05
    assert least >= 0.5 and overlaps(e) == []


def test_two_robots_head_on_at_a_door_cross_it_one_at_a_time():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    door = e.site.opening("d_office")  # an automatic door at (3, 6), corridor below, office above
    r0.x, r0.y, r0.theta = 3.0, 4.6, math.pi / 2
    r1.x, r1.y, r1.theta = 3.0, 6.6, -math.pi / 2
    e.apply_command(command("r0", 1, "gothrough", ["d_office"], [(3.0, 4.6), (3.0, 6.6), (2.0, 7.5)]))
    e.apply_command(command("r1", 1, "gothrough", ["d_office"], [(3.0, 6.6), (3.0, 4.6), (2.0, 4.6)]))
    both_in_lane = 0
    least = math.inf
    while e.time < 90.0 and (r0.phase == "drive" or r1.phase == "drive"):
        e.step()
        least = min(least, math.dist((r0.x, r0.y), (r1.x, r1.y)))
        both_in_lane += in_lane(door, r0.x, r0.y) and in_lane(door, r1.x, r1.y) and abs(r0.y - r1.y) < 1.0
    assert r0.phase == r1.phase == "done"
    assert r0.y > 6.5 and r1.y < 5.5  # each crossed
    assert least >= 0.5 and overlaps(e) == []
    assert both_in_lane == 0  # never both in front of the gap


def test_robots_approaching_a_taken_spot_queue_behind_it():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r1.x, r1.y = 8.0, 4.6  # standing where r0's approach ends (off d_storage's lane)
    e.apply_command(command("r0", 1, "approach", ["d_storage"], [(1.0, 5.0), (8.0, 4.6)]))
    least = closest_approach(e, 40.0, "r0", "r1")
    assert r0.phase == "done" and r0.state == "done" and e.time < 20.0  # done where it is, behind r1
    assert 0.5 <= math.dist((r0.x, r0.y), (8.0, 4.6)) <= 1.5
    assert least >= 0.5 and overlaps(e) == []


def test_a_robot_wedged_for_long_never_pushes_through_its_action_fails_for_a_new_plan():
    e = engine()
    r0, r1 = e.robots["r0"], e.robots["r1"]
    r1.x, r1.y = 3.0, 6.0  # parked in d_office's doorway, the only way into the office
    r0.x, r0.y, r0.theta = 3.0, 4.6, math.pi / 2
    e.apply_command(command("r0", 1, "gothrough", ["d_office"], [(3.0, 4.6), (3.0, 7.2)]))
    events = []
    while e.time < 60.0:
        e.step()
        events += e.take_events()
        assert math.dist((r0.x, r0.y), (r1.x, r1.y)) >= 0.5  # never touches r1
    assert not [ev for ev in events if ev.kind == "robot_overlap"] and e.summary()["robot_overlaps"] == 0
    (failed,) = [ev for ev in events if ev.kind == "action_failed"]
    assert failed.robot == "r0" and failed.data.reason == "kept back by robots for 12 s (waiting: r0 -> r1)"
    assert 12.0 <= failed.time <= 30.0  # given up 12 s after it last got 0.5 m anywhere
    assert r0.phase == "failed" and r0.y < 5.5  # where it was kept back, waiting for a new plan


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


def test_a_disc_reaching_into_a_wall_is_one_wall_contact_each_time_and_the_deepest_is_kept():
    e = engine()
    r0 = e.robots["r0"]
    (wall,) = [w.box for w in e.site.walls if w.box[0] <= 8.0 <= w.box[2] and 5.5 < w.box[1] < 6.5]
    r0.x, r0.y = 8.0, wall[1] - 0.25 + 0.04  # 4 cm into the corridor's north wall
    for _ in range(5):
        e.step()  # however long it stays so, one contact
    r0.y -= 0.5  # away ...
    e.step()
    r0.y = wall[1] - 0.25 + 0.02  # ... and back, 2 cm in
    e.step()
    contacts = [ev for ev in e.take_events() if ev.kind == "wall_contact"]
    assert [(c.robot, c.data.place) for c in contacts] == [("r0", "corridor"), ("r0", "corridor")]
    assert abs(contacts[0].data.depth - 0.04) < 1e-6 and abs(contacts[1].data.depth - 0.02) < 1e-6
    summary = e.summary()
    assert summary["wall_contacts"] == 2 and summary["wall_contacts_by_place"] == {"corridor": 2}
    assert abs(summary["wall_depth_max"] - 0.04) < 1e-6
    r0.y -= 0.5
    e.step()
    r0.y = wall[1] - 0.25 + 0.0005  # half a millimetre: touching, not a contact
    e.step()
    assert not [ev for ev in e.take_events() if ev.kind == "wall_contact"]
