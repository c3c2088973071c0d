"""The motion planner: collision-free shortest paths on the inflated grid, timed trajectories."""

from __future__ import annotations

import math
from itertools import pairwise

from services.planner.motion import MotionPlanner, polyline_distance
from tests.planner.conftest import site_named


def planner() -> MotionPlanner:
    return MotionPlanner(site_named("office"))


def test_a_free_straight_line_is_the_path():
    m = planner()
    a, b = (13.0, 7.5), (14.2, 9.2)  # inside the lab, away from its doors
    p = m.path(a, b, ("lab",))
    assert p.points == (a, b) and math.isclose(p.length, math.dist(a, b))


def test_paths_around_walls_are_collision_free_and_go_through_the_doorway():
    m = planner()
    site = m.site
    a, b = (1.5, 5.0), (1.5, 8.5)  # corridor -> office_a, the wall between them has a door at x=2.5
    p = m.path(a, b)
    assert m.stats["astar"] >= 1
    assert p.length > math.dist(a, b) + 0.5, "the straight line crosses a wall"
    for q, r in pairwise(p.points):
        assert m.segment_free(q, r), (q, r)
    door = site.opening("d_office_a")
    crossing = [(q, r) for q, r in pairwise(p.points) if (q[1] - 6.0) * (r[1] - 6.0) <= 0]
    assert crossing, "the path crosses the wall line"
    (x0, y0), (x1, y1) = crossing[0]
    x_at_wall = x0 + (x1 - x0) * (6.0 - y0) / (y1 - y0)
    assert abs(x_at_wall - door.center[0]) < door.width / 2
    # shortest: not much longer than the polyline through the door centre
    via_door = math.dist(a, door.center) + math.dist(door.center, b)
    assert p.length <= via_door + 0.3


def test_points_in_the_inflated_margin_are_snapped_into_the_room():
    m = planner()
    raw = (0.05, 8.0)  # against office_a's west wall
    assert not m.is_free(raw)
    p = m.snap(raw, "office_a")
    assert m.is_free(p) and m.site.rooms["office_a"].contains(*p)
    assert math.dist(p, raw) < 0.5


def test_trajectories_are_timed_at_robot_speed():
    m = planner()
    pts = [(12.0, 7.0), (14.0, 7.0), (14.0, 9.0)]
    rows = m.trajectory(pts, 100.0)
    assert rows[0][:3] == [100.0, 12.0, 7.0]
    assert math.isclose(rows[-1][0], 100.0 + 4.0 / m.speed) and rows[-1][1:3] == [14.0, 9.0]
    for r0, r1 in pairwise(rows):
        ds = math.dist(r0[1:3], r1[1:3])
        assert ds <= 0.5 + 1e-9
        assert math.isclose(r1[0] - r0[0], ds / m.speed, abs_tol=1e-9)
    assert math.isclose(rows[0][3], 0.0) and math.isclose(rows[-1][3], math.pi / 2)
    assert polyline_distance((13.0, 8.0), rows) == 1.0
