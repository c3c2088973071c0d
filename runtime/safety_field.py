"""The laser safety field: what a robot may do with a scan of its surroundings, no I/O.

A scan becomes points in the robot's frame (x ahead, y to the left; the scanner sits at the base's
centre). Along the direction of travel the robot's disc, grown by ``side_margin``, sweeps a
corridor; the *clearance* is the distance from the front of that disc to the nearest point in the
corridor. Two zones, both growing with the speed:

- the **stop zone**: ``stop_base + v * reaction_time + v**2 / (2 * deceleration)`` (what the robot
  needs to stop from speed ``v``, plus a fixed margin). An obstacle in the stop zone at the robot's
  present speed means zero velocity now.
- the **slow-down zone** beyond it: the speed is capped so that the stop zone at the capped speed
  ends ``slow_gap`` short of the obstacle, so a robot slows down smoothly as it nears something,
  can always stop short of it, and is not stopped by the obstacle it is slowing for (only by one
  that comes closer: a person stepping in).

A robot the field stopped *waits*: it goes on only once the way is clear of the stop zone at its
cruising speed (``resume_speed``), not creeping up to whoever stepped in front of it.

Turning on the spot sweeps nothing outside the disc: only a point inside the grown disc (something
touching) stops a turn.

Other robots are not the field's business: the executor keeps robots apart by where they report
they are (its traffic rules: margin, driving around, making way), so the points of a scan that lie
on a robot the driver hears of are left out first (:func:`without_robots`). What no robot reports -
a person, a robot whose driver has gone silent, a box - stops the robot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# m beyond a robot's radius within which a scan's point belongs to that robot: how far apart two
# robots' own ideas of where they are may be (localisation, the pose's age), and the scan's noise
ROBOT_REACH = 0.1


@dataclass(frozen=True)
class FieldConfig:
    stop_base: float = 0.05  # m kept clear in front of the disc even at standstill
    reaction_time: float = 0.1  # s from the obstacle appearing to the brakes acting (scan + control period)
    deceleration: float = 1.0  # m/s² the base brakes with
    side_margin: float = 0.03  # m the disc is grown by (each side of the corridor, and ahead)
    slow_gap: float = 0.03  # m between the stop zone at the capped speed and the obstacle
    horizon: float = 3.0  # m ahead beyond which points are ignored


@dataclass(frozen=True)
class Verdict:
    v: float
    omega: float
    stop: bool  # an obstacle is inside the stop zone: zero velocity
    clearance: float  # m from the disc's front to the nearest point ahead (inf: none)


def stop_distance(v: float, cfg: FieldConfig) -> float:
    """The stop zone's depth (m ahead of the disc) at speed ``v``."""
    v = abs(v)
    return cfg.stop_base + v * cfg.reaction_time + v * v / (2.0 * cfg.deceleration)


def speed_cap(clearance: float, cfg: FieldConfig) -> float:
    """The largest speed whose stop zone fits in ``clearance`` (0 when not even the base margin does)."""
    room = clearance - cfg.stop_base
    if room <= 0.0:
        return 0.0
    if not math.isfinite(room):
        return math.inf
    a, t = cfg.deceleration, cfg.reaction_time
    return a * (-t + math.sqrt(t * t + 2.0 * room / a))


def scan_points(
    angle_min: float, angle_increment: float, range_min: float, range_max: float, ranges: np.ndarray
) -> np.ndarray:
    """The scan's returns as an (N, 2) array in the scanner's frame. Readings outside
    [range_min, range_max] or not finite are no return (LaserScan's convention). Raises ValueError
    naming the field of a scan that cannot be read."""
    for name, value in (("angle_min", angle_min), ("angle_increment", angle_increment), ("range_max", range_max)):
        if not math.isfinite(value):
            raise ValueError(f"{name} is not finite ({value})")
    if angle_increment == 0.0 and len(ranges) > 1:
        raise ValueError("angle_increment is 0 with several ranges")
    if not (math.isfinite(range_min) and 0.0 <= range_min < range_max):
        raise ValueError(f"range_min {range_min} is not in [0, range_max {range_max})")
    r = np.asarray(ranges, dtype=np.float64)
    angles = angle_min + angle_increment * np.arange(r.size)
    ok = np.isfinite(r) & (r >= range_min) & (r <= range_max)
    return np.column_stack((r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])))


def without_robots(
    points: np.ndarray, pose: tuple[float, float, float], robots: Sequence[tuple[float, float]], reach: float
) -> np.ndarray:
    """The points of a scan (robot frame, the robot at ``pose`` in the map) that are not within
    ``reach`` of another robot's centre (``robots``, map frame)."""
    if points.size == 0 or not robots:
        return points
    x, y, theta = pose
    c, s = math.cos(theta), math.sin(theta)
    centres = np.array([(c * (rx - x) + s * (ry - y), -s * (rx - x) + c * (ry - y)) for rx, ry in robots])
    gaps = np.hypot(points[:, None, 0] - centres[None, :, 0], points[:, None, 1] - centres[None, :, 1])
    return points[(gaps > reach).all(axis=1)]


def clearance_ahead(points: np.ndarray, radius: float, backwards: bool, cfg: FieldConfig) -> float:
    """Distance from the grown disc's front (its back, ``backwards``) to the nearest point in the
    corridor it sweeps (negative: a point inside the grown disc)."""
    if points.size == 0:
        return math.inf
    x = -points[:, 0] if backwards else points[:, 0]
    grown = radius + cfg.side_margin
    inside = (np.abs(points[:, 1]) <= grown) & (x > 0.0) & (x <= grown + cfg.horizon)
    if not inside.any():
        return math.inf
    # The grown disc's front edge at lateral offset y is sqrt(R² - y²) ahead of its centre.
    y = points[inside, 1]
    return float(np.min(x[inside] - np.sqrt(np.maximum(grown * grown - y * y, 0.0))))


def limit(
    points: np.ndarray,
    v: float,
    omega: float,
    speed_now: float,
    radius: float,
    cfg: FieldConfig = FieldConfig(),
    resume_speed: float | None = None,
) -> Verdict:
    """The velocity the field allows instead of (v, omega), the robot going at ``speed_now``;
    ``resume_speed``: the field stopped it, and it waits until the way is clear at that speed."""
    if points.size and v == 0.0:
        touching = bool((np.hypot(points[:, 0], points[:, 1]) < radius + cfg.side_margin).any())
        return Verdict(0.0, 0.0, True, 0.0) if touching and omega != 0.0 else Verdict(v, omega, False, math.inf)
    clearance = clearance_ahead(points, radius, v < 0.0, cfg)
    if resume_speed is not None and clearance < stop_distance(resume_speed, cfg) + cfg.slow_gap:
        return Verdict(0.0, 0.0, True, clearance)
    if clearance < stop_distance(speed_now, cfg) or clearance <= cfg.stop_base:
        return Verdict(0.0, 0.0, True, clearance)
    cap = speed_cap(clearance - cfg.slow_gap, cfg)
    if abs(v) <= cap:
        return Verdict(v, omega, False, clearance)
    scale = cap / abs(v)  # keep the curvature: slow down along the same arc
    return Verdict(v * scale, omega * scale, False, clearance)
