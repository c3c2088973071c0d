"""Pure pursuit on a unicycle: the robot follows a trajectory within a stated tolerance.

Tolerances (robot_speed 0.5 m/s, 1.5 rad/s turn rate, 0.3 m lookahead, 20 Hz):
- straight paths: no lateral error; any corner, and a bearing up to ``turn_in_place`` met along an
  arc: at most ``TRACKING_ERROR`` (0.02 m) from the polyline (sharp corners are turned on the spot);
- the end: within 0.02 m of the last row, heading within 0.03 rad of its theta;
- duration: path length / speed, plus the turns on the spot and a few ticks;
- never faster than robot_speed, never turning faster than the turn-rate bound.
"""

from __future__ import annotations

import math
from itertools import pairwise

import pytest

from runtime.plane import segment_distance, wrap
from runtime.pursuit import TRACKING_ERROR, ControllerConfig, Path, PurePursuit, integrate

CFG = ControllerConfig(speed=0.5, max_turn_rate=1.5, lookahead=0.3)
DT = 0.05


def follow(rows, start, *, cfg=CFG, s_limit=math.inf, steps=10_000):
    path = Path(rows)
    ctl = PurePursuit(path, cfg)
    x, y, th = start
    trace = []
    for i in range(steps):
        st = ctl.step(x, y, th, DT, s_limit)
        x, y, th = st.x, st.y, st.theta
        trace.append(st)
        if st.arrived or st.held:
            return path, trace, (i + 1) * DT
    raise AssertionError("did not arrive")


def deviation(path: Path, trace) -> float:
    return max(min(segment_distance((s.x, s.y), a, b) for a, b in pairwise(path.points)) for s in trace)


def test_straight_line_is_followed_exactly_at_robot_speed():
    path, trace, t = follow([[0, 0, 0, 0], [10, 5, 0, 0]], (0, 0, 0))
    assert deviation(path, trace) < 1e-9
    assert math.dist((trace[-1].x, trace[-1].y), (5, 0)) <= 0.02
    assert t == pytest.approx(5 / 0.5, abs=0.11)  # one tick to notice the arrival


@pytest.mark.parametrize("turn", [1, -1])
def test_square_corners_stay_within_tolerance(turn):
    rows = [[0, 0, 0, 0], [8, 4, 0, 0], [14, 4, 3 * turn, turn * math.pi / 2], [20, 1, 3 * turn, math.pi]]
    path, trace, t = follow(rows, (0, 0, 0))
    assert deviation(path, trace) <= TRACKING_ERROR
    end = trace[-1]
    assert math.dist((end.x, end.y), (1, 3 * turn)) <= 0.02
    assert abs(wrap(end.theta - math.pi)) <= 0.03
    turns = 2 * (math.pi / 2) / 1.5  # two square corners, each turned on the spot
    assert path.length / 0.5 + turns <= t <= path.length / 0.5 + turns + 0.5
    assert max(s.v for s in trace) <= 0.5 + 1e-9
    assert max(abs(s.omega) for s in trace) <= 1.5 + 1e-9


def corner(turn_degrees: float, leg: float = 1.5) -> list[list[float]]:
    """Rows of two legs of ``leg`` m from the origin along x, the second turned by ``turn_degrees``."""
    a = math.radians(turn_degrees)
    return [[0, 0, 0, 0], [3, leg, 0, 0], [6, leg * (1 + math.cos(a)), leg * math.sin(a), a]]


def test_tracking_error_stays_within_its_bound():
    """The controller's tracking error, which the motion planners' wall clearance counts on
    (runtime/clearance.py): corners of every angle, both ways, and paths met with a bearing just
    short of a turn on the spot (a robot taking up its path again from beside it)."""
    worst = 0.0
    for tenth in range(50, 1760, 25):
        for sign in (1, -1):
            path, trace, _ = follow(corner(sign * tenth / 10), (0, 0, 0))
            worst = max(worst, deviation(path, trace))
    limit = CFG.turn_in_place
    for bearing in (0.5 * limit, 0.9 * limit, 0.999 * limit, -0.999 * limit):
        path, trace, _ = follow([[0, 0, 0, 0], [6, 3, 0, 0]], (0, 0, bearing))
        worst = max(worst, deviation(path, trace))
    assert 0.01 < worst <= TRACKING_ERROR  # the bound is measured, not loose


def test_a_sharp_corner_is_turned_on_the_spot_at_its_vertex():
    path, trace, _ = follow(corner(90), (0, 0, 0))
    on_the_spot = [s for s in trace if s.v == 0.0 and s.omega != 0.0]
    assert on_the_spot and all(math.dist((s.x, s.y), (1.5, 0)) <= 0.005 for s in on_the_spot)
    assert deviation(path, trace) <= 0.005


def test_a_path_behind_the_robot_starts_with_a_turn_in_place():
    path, trace, t = follow([[0, 0, 0, 0], [8, 4, 0, 0]], (0, 0, math.pi))
    first = trace[: int(1.0 / DT)]
    assert all(s.v == 0.0 and abs(s.omega) > 0 for s in first[:5])  # turning on the spot first
    assert deviation(path, trace) <= 0.12
    assert math.dist((trace[-1].x, trace[-1].y), (4, 0)) <= 0.02


def test_final_heading_is_reached_by_turning_in_place():
    path, trace, _ = follow([[0, 0, 0, 0], [4, 2, 0, math.pi / 2]], (0, 0, 0))
    assert abs(wrap(trace[-1].theta - math.pi / 2)) <= 0.03
    turning = [s for s in trace if s.v == 0.0 and s.omega != 0.0]
    assert len(turning) >= int((math.pi / 2) / 1.5 / DT) - 1


def test_the_limit_is_never_passed():
    path, trace, _ = follow([[0, 0, 0, 0], [10, 5, 0, 0]], (0, 0, 0), s_limit=3.2)
    assert trace[-1].held
    assert max(s.x for s in trace) <= 3.2 + 1e-9
    assert trace[-1].x == pytest.approx(3.2, abs=0.01)


def test_unicycle_integration_is_exact_on_an_arc():
    # A full circle of radius 1 in 2*pi seconds returns to the start, whatever the step.
    x, y, th = 0.0, 0.0, 0.0
    for _ in range(100):
        x, y, th = integrate(x, y, th, 1.0, 1.0, 2 * math.pi / 100)
    assert (x, y) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert wrap(th) == pytest.approx(0.0, abs=1e-9)


def test_repeated_points_and_single_point_paths_are_handled():
    path, trace, _ = follow([[0, 1, 1, 0], [1, 1, 1, 0], [2, 2, 1, 0]], (0, 1, 0))
    assert trace[-1].x == pytest.approx(2, abs=0.02)
    path, trace, _ = follow([[0, 1, 0, 0]], (0, 0, 0))
    assert trace[-1].x == pytest.approx(1, abs=0.02)
