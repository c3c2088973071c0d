"""Plane geometry the simulator and the robot driver need: angles, segments, distances.

Plain floats rather than numpy arrays: the engine calls these a few times per robot per tick on
2-D points, where numpy's per-call overhead costs more than the arithmetic.
"""

from __future__ import annotations

import math

Point = tuple[float, float]


def wrap(angle: float) -> float:
    """``angle`` mapped to (-pi, pi]."""
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def segment_distance(p: Point, a: Point, b: Point) -> float:
    """Distance from point ``p`` to the segment ``a``-``b``."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    length2 = dx * dx + dy * dy
    if length2 == 0.0:
        return math.hypot(p[0] - ax, p[1] - ay)
    t = ((p[0] - ax) * dx + (p[1] - ay) * dy) / length2
    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
    return math.hypot(p[0] - (ax + t * dx), p[1] - (ay + t * dy))


def line_side(a: Point, b: Point, p: Point) -> float:
    """Which side of the line through ``a`` and ``b`` the point ``p`` lies on: the sign of the cross
    product (positive on the left going from a to b, 0 on the line), scaled by the line's length."""
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])


def segment_intersection(p0: Point, p1: Point, q0: Point, q1: Point) -> float | None:
    """Where segment ``p0``-``p1`` meets segment ``q0``-``q1``, as the fraction along ``p``.

    Touching counts as meeting; parallel segments never meet (an overlap along a wall line is not a
    crossing of it). ``None`` when they do not meet.
    """
    rx, ry = p1[0] - p0[0], p1[1] - p0[1]
    sx, sy = q1[0] - q0[0], q1[1] - q0[1]
    denom = rx * sy - ry * sx
    if abs(denom) < 1e-12:
        return None
    qpx, qpy = q0[0] - p0[0], q0[1] - p0[1]
    t = (qpx * sy - qpy * sx) / denom
    u = (qpx * ry - qpy * rx) / denom
    eps = 1e-9
    if -eps <= t <= 1.0 + eps and -eps <= u <= 1.0 + eps:
        return min(max(t, 0.0), 1.0)
    return None


def box_distance(p: Point, box: tuple[float, float, float, float]) -> float:
    """Distance from ``p`` to an axis-aligned rectangle ``(xmin, ymin, xmax, ymax)`` (0 inside)."""
    dx = max(box[0] - p[0], 0.0, p[0] - box[2])
    dy = max(box[1] - p[1], 0.0, p[1] - box[3])
    return math.hypot(dx, dy)
