"""Trajectory following: pure pursuit on a unicycle (the simulator's robots and `arroch robot`).

A robot is a unicycle (x, y, theta) driven by a linear speed ``v`` and a turn rate ``omega``.
Pure pursuit steers toward a point ``lookahead`` metres further along the path; the curvature that
reaches it is ``2 sin(alpha) / d`` (``alpha`` the bearing of that point, ``d`` its distance). The
robot drives at ``speed`` unless the curvature would need more than ``max_turn_rate``: then it slows
down so as to keep the curvature (it never widens a corner by turning less). A bearing beyond
``turn_in_place`` (e.g. the first row points behind the robot) is met by turning on the spot, until
the bearing is within ``aligned``.

Corners: pure pursuit cuts a corner, by about 1 mm per degree the path turns there with a 0.3 m
lookahead (0.06 m at 90°), and beside a doorway's jamb the cut side is the
wall. So the lookahead point never passes a *sharp* vertex (one where the path turns more than
``turn_in_place``) before the robot has reached it: the robot drives to the vertex, turns on the
spot to the next leg and goes on. Only corners up to ``turn_in_place`` are taken along an arc.

The path is followed in space, not in time: a trajectory's timestamps are the planner's forecast,
and a robot held at a door is late on them by the time it waited. The one exception is a *hold*:
two rows at the same point (the second later) mean "wait here until then" - the planner's way of
making a robot give way to another (services/planner/reservations.py) - and :meth:`Path.hold_limit`
says how far the robot may go at a given time. ``s_limit`` caps how far along the path the robot
may go (a closed door ahead, a hold); the step never carries it past that point.

Integration is exact for constant (v, omega) over a step, so results do not drift with the tick.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from .plane import line_side, segment_intersection, wrap

# m: the farthest the controller takes the robot's centre from its path while it follows it, at
# 0.5 m/s, 1.5 rad/s, 0.3 m lookahead, 20 Hz. Measured (tests/sim/test_controller.py,
# test_tracking_error_stays_within_its_bound, which fails when the controller strays farther): a
# corner of up to ``turn_in_place`` (10°) taken along an arc cuts at most 0.0099 m; a sharper one is
# driven to its vertex and turned on the spot, then left with a bulge under 0.004 m; a bearing of up
# to ``turn_in_place`` met along an arc (a robot taking up its path again from beside it, its
# heading a little off) swings it out by at most 0.0162 m. The motion planners keep this between
# paths and walls (runtime/clearance.py).
TRACKING_ERROR = 0.02
CORNER_REACHED = 0.005  # m from a sharp vertex at which the robot turns on the spot to the next leg


@dataclass(frozen=True)
class ControllerConfig:
    speed: float = 0.5  # m/s, the site's robot_speed
    max_turn_rate: float = 1.5  # rad/s
    lookahead: float = 0.3  # m; shorter cuts corners less but reacts more sharply
    goal_tolerance: float = 0.02  # m from the last row counts as arrived
    heading_tolerance: float = 0.03  # rad from the last row's theta counts as aligned
    # rad of bearing (or of a path's turn at a vertex) beyond which the robot turns on the spot: a
    # corner taken along an arc is cut by ~1 mm per degree (TRACKING_ERROR)
    turn_in_place: float = math.radians(10.0)
    aligned: float = 0.05  # rad of bearing within which a turn on the spot ends
    align_final_heading: bool = True  # turn to the last row's theta after arriving


class Path:
    """A polyline with cumulative arc length, built from trajectory rows ``[t, x, y, theta]``."""

    def __init__(self, rows: list[list[float]]) -> None:
        points: list[tuple[float, float]] = []
        self.holds: list[tuple[float, float]] = []  # (arc length, time): stay there until then
        self.s = [0.0]
        for row in rows:
            p = (float(row[1]), float(row[2]))
            if not points or math.hypot(p[0] - points[-1][0], p[1] - points[-1][1]) > 1e-6:
                if points:
                    self.s.append(self.s[-1] + math.hypot(p[0] - points[-1][0], p[1] - points[-1][1]))
                points.append(p)
            else:
                self.holds.append((self.s[-1], float(row[0])))
        self.points = points
        self.final_theta = float(rows[-1][3]) if rows else 0.0

    def hold_limit(self, now: float) -> float:
        """How far along the path a robot may be at ``now``: the first hold not over yet, else no limit."""
        for s, until in self.holds:
            if until > now + 1e-9:
                return s
        return math.inf

    @property
    def length(self) -> float:
        return self.s[-1]

    @property
    def end(self) -> tuple[float, float]:
        return self.points[-1]

    def point_at(self, s: float) -> tuple[float, float]:
        """The point at arc length ``s`` (clamped to the path)."""
        if s <= 0.0 or len(self.points) == 1:
            return self.points[0]
        if s >= self.length:
            return self.points[-1]
        i = bisect.bisect_right(self.s, s) - 1
        a, b = self.points[i], self.points[i + 1]
        f = (s - self.s[i]) / (self.s[i + 1] - self.s[i])
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))

    def project(self, x: float, y: float, s_from: float, window: float) -> tuple[float, float]:
        """Closest path point to (x, y) within arc lengths [s_from, s_from + window]: (s, distance).

        Searching only forward of the last progress keeps progress monotone on paths that come back
        near themselves (e.g. into a room and out through the same door).
        """
        if len(self.points) == 1:
            return 0.0, math.hypot(x - self.points[0][0], y - self.points[0][1])
        first = min(max(bisect.bisect_right(self.s, s_from) - 1, 0), len(self.points) - 2)
        last = min(bisect.bisect_right(self.s, s_from + window), len(self.points) - 1)
        best_s, best_d = s_from, math.inf
        for i in range(first, max(last, first + 1)):
            (ax, ay), (bx, by) = self.points[i], self.points[i + 1]
            dx, dy = bx - ax, by - ay
            seg = self.s[i + 1] - self.s[i]
            t = ((x - ax) * dx + (y - ay) * dy) / (seg * seg)
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            s = self.s[i] + t * seg
            if s < s_from:
                s, t = s_from, (s_from - self.s[i]) / seg
            d = math.hypot(x - (ax + t * dx), y - (ay + t * dy))
            if d < best_d:
                best_s, best_d = s, d
        return best_s, best_d


def path_crossings(
    path: Path, gaps: dict[str, tuple[tuple[float, float], tuple[float, float]]]
) -> list[tuple[float, str]]:
    """Where ``path`` first crosses each gap (``{id: (end a, end b)}``, e.g. door openings), as
    ``(arc length, id)`` in path order. A robot following the path meets the doors in this order."""
    found: list[tuple[float, str]] = []
    for gap_id, (a, b) in gaps.items():
        for i in range(len(path.points) - 1):
            t = segment_intersection(path.points[i], path.points[i + 1], a, b)
            if t is not None:
                found.append((path.s[i] + t * (path.s[i + 1] - path.s[i]), gap_id))
                break
    return sorted(found)


def crossing_behind(
    path: Path,
    s_cross: float,
    gap: tuple[tuple[float, float], tuple[float, float]],
    progress: float,
    x: float,
    y: float,
) -> bool:
    """Whether a robot at (x, y), ``progress`` m along ``path``, is through the gap (``(end a, end
    b)``) that the path crosses at ``s_cross``. Progress alone cannot tell: it never goes back, but
    the robot can (backing away from another robot), and one back in front of a door its progress
    had passed must wait for that door again."""
    if s_cross >= progress:
        return False
    a, b = gap
    side_beyond = line_side(a, b, path.point_at(min(s_cross + 0.05, path.length)))
    return side_beyond == 0.0 or line_side(a, b, (x, y)) * side_beyond > 0.0


@dataclass
class Step:
    """One control step's outcome."""

    x: float
    y: float
    theta: float
    v: float
    omega: float
    arrived: bool = False  # at the end of the path (and aligned, if asked)
    held: bool = False  # stopped by ``s_limit`` short of the end


def sharp_vertices(path: Path, angle: float) -> list[float]:
    """Arc lengths of the inner vertices where ``path`` turns by more than ``angle`` rad."""
    found = []
    for i in range(1, len(path.points) - 1):
        (ax, ay), (bx, by), (cx, cy) = path.points[i - 1], path.points[i], path.points[i + 1]
        turn = wrap(math.atan2(cy - by, cx - bx) - math.atan2(by - ay, bx - ax))
        if abs(turn) > angle:
            found.append(path.s[i])
    return found


class PurePursuit:
    """Follows one path; keeps the progress along it between steps."""

    def __init__(self, path: Path, config: ControllerConfig) -> None:
        self.path = path
        self.config = config
        self.s = 0.0  # progress: arc length of the closest path point
        self.cross_track = 0.0  # distance from that point at the last step
        self.aligning = False
        self.turning = False  # turning on the spot until the bearing is within ``aligned``
        self._corners = sharp_vertices(path, config.turn_in_place)  # not reached yet, in path order

    def step(self, x: float, y: float, theta: float, dt: float, s_limit: float = math.inf) -> Step:
        cfg, path = self.config, self.path
        if not self.aligning:
            # How far the robot may get in one step, with a margin for the corner cases.
            window = max(2.0 * cfg.lookahead, 4.0 * cfg.speed * dt) + 0.5
            self.s, self.cross_track = path.project(x, y, self.s, window)
            ex, ey = path.end
            d_end = math.hypot(ex - x, ey - y)
            if d_end <= cfg.goal_tolerance and self.s >= path.length - cfg.goal_tolerance - 1e-9:
                if not cfg.align_final_heading:
                    return Step(x, y, theta, 0.0, 0.0, arrived=True)
                self.aligning = True
            else:
                return self._pursue(x, y, theta, dt, d_end, s_limit)
        delta = wrap(path.final_theta - theta)
        if abs(delta) <= cfg.heading_tolerance:
            return Step(x, y, theta, 0.0, 0.0, arrived=True)
        omega = max(-cfg.max_turn_rate, min(cfg.max_turn_rate, delta / dt))
        return Step(x, y, wrap(theta + omega * dt), 0.0, omega)

    def _pursue(self, x: float, y: float, theta: float, dt: float, d_end: float, s_limit: float) -> Step:
        cfg, path = self.config, self.path
        allowed = s_limit - self.s
        if allowed <= 0.005:
            return Step(x, y, theta, 0.0, 0.0, held=True)
        corner = self._next_corner(x, y)
        ahead = self.s + cfg.lookahead
        if corner is not None and corner < ahead:
            tx, ty = path.point_at(corner)  # not past a sharp vertex: that would cut it
        else:
            tx, ty = path.point_at(ahead) if path.length - self.s > cfg.lookahead else path.end
        ld = math.hypot(tx - x, ty - y)
        alpha = wrap(math.atan2(ty - y, tx - x) - theta) if ld > 1e-9 else 0.0
        self.turning = abs(alpha) > (cfg.aligned if self.turning else cfg.turn_in_place)
        if self.turning:
            omega = max(-cfg.max_turn_rate, min(cfg.max_turn_rate, alpha / dt))
            return Step(x, y, wrap(theta + omega * dt), 0.0, omega)
        curvature = 2.0 * math.sin(alpha) / ld if ld > 1e-9 else 0.0
        v = cfg.speed
        if abs(curvature) * v > cfg.max_turn_rate:
            v = cfg.max_turn_rate / abs(curvature)
        # Never overshoot the end of the path, a sharp vertex or the limit (a closed door ahead).
        v = min(v, d_end / dt, allowed / dt)
        if corner is not None and corner < ahead:
            v = min(v, ld / dt)
        omega = curvature * v
        nx, ny, nth = integrate(x, y, theta, v, omega, dt)
        return Step(nx, ny, nth, v, omega)

    def _next_corner(self, x: float, y: float) -> float | None:
        """Arc length of the next sharp vertex the robot has not reached (reached: progress at it, or
        the robot within ``CORNER_REACHED`` of it), or None."""
        while self._corners:
            s = self._corners[0]
            cx, cy = self.path.point_at(s)
            if self.s < s - 1e-9 and math.hypot(cx - x, cy - y) > CORNER_REACHED:
                return s
            self._corners.pop(0)
            self.turning = True  # at the vertex: on the spot to the next leg (an arc from here bulges out)
        return None


def integrate(x: float, y: float, theta: float, v: float, omega: float, dt: float) -> tuple[float, float, float]:
    """Unicycle pose after ``dt`` at constant (v, omega), exactly (an arc, or a line)."""
    if abs(omega) < 1e-9:
        return x + v * math.cos(theta) * dt, y + v * math.sin(theta) * dt, theta
    th1 = theta + omega * dt
    r = v / omega
    return x + r * (math.sin(th1) - math.sin(theta)), y - r * (math.cos(th1) - math.cos(theta)), wrap(th1)
