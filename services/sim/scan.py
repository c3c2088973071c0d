"""A simulated planar laser scanner: what a robot's LaserScan shows of the kinematic world.

Rays from the robot's centre hit the site's walls (axis-aligned boxes), the doors' leaves where
they stand (a segment from the hinge, turned by how far the door is open), other robots (discs)
and the human (a disc). The ray casting is exact geometry on the same shapes the simulator steps
and counts contacts with, in numpy: deterministic, and cheaper than pybullet's ray batch, whose
scene is only a mirror of this one for the camera.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from protocol.site.model import Site
from runtime.plane import wrap

from .doors import Doors


@dataclass(frozen=True)
class ScannerConfig:
    beams: int = 180  # over a full turn (2° apart: 7 cm at 2 m), from straight behind
    range_max: float = 8.0  # m; beyond it: no return (inf)


class Scanner:
    def __init__(self, site: Site, config: ScannerConfig = ScannerConfig()) -> None:
        self.config = config
        boxes = np.array([w.box for w in site.walls], dtype=np.float64).reshape(-1, 4)
        self._lo, self._hi = boxes[:, :2], boxes[:, 2:]
        self.angle_min = -math.pi
        self.angle_increment = 2.0 * math.pi / config.beams
        self._offsets = self.angle_min + self.angle_increment * np.arange(config.beams)

    def ranges(
        self,
        pose: tuple[float, float, float],
        discs: Iterable[tuple[float, float, float]],
        doors: Doors | None = None,
    ) -> np.ndarray:
        """Ranges (m, ``inf`` for no return) of the beams from ``pose``, beam i at angle
        ``angle_min + i * angle_increment`` from the robot's heading; ``discs`` are (x, y, radius)."""
        x, y, theta = pose
        angles = theta + self._offsets
        d = np.column_stack((np.cos(angles), np.sin(angles)))  # (B, 2)
        best = np.full(d.shape[0], np.inf)
        best = np.minimum(best, self._boxes(x, y, d))
        circles = np.asarray(list(discs), dtype=np.float64).reshape(-1, 3)
        if circles.size:
            best = np.minimum(best, _discs(x - circles[:, 0], y - circles[:, 1], circles[:, 2], d))
        if doors is not None:
            for door in doors.doors.values():
                leaf = door.leaf
                if leaf is None:
                    continue
                yaw = leaf.closed_yaw + door.fraction * wrap(leaf.open_yaw - leaf.closed_yaw)
                a = np.array(leaf.hinge, dtype=np.float64)
                b = a + leaf.length * np.array((math.cos(yaw), math.sin(yaw)))
                best = np.minimum(best, _segment(np.array((x, y)), d, a, b))
        best[best > self.config.range_max] = np.inf
        return best

    def _boxes(self, x: float, y: float, d: np.ndarray) -> np.ndarray:
        """The slab method for every beam against every wall box at once."""
        if self._lo.size == 0:
            return np.full(d.shape[0], np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d[:, None, :]  # (B, 1, 2)
            t0 = (self._lo[None, :, :] - (x, y)) * inv
            t1 = (self._hi[None, :, :] - (x, y)) * inv
        near = np.nanmax(np.minimum(t0, t1), axis=2)  # (B, W)
        far = np.nanmin(np.maximum(t0, t1), axis=2)
        hit = (far >= np.maximum(near, 0.0)) & (far > 0.0)
        t = np.where(near > 0.0, near, 0.0)  # a sensor inside a wall sees it at 0
        return np.where(hit, t, np.inf).min(axis=1)


def _discs(ox: np.ndarray, oy: np.ndarray, r: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance along each beam to the nearest disc, the beams' origin being offset (ox, oy) from
    each disc's centre."""
    b = d[:, :1] * ox + d[:, 1:] * oy  # (B, D)
    c = ox * ox + oy * oy - r * r
    disc = b * b - c
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    out = np.where((disc >= 0.0) & (t >= 0.0), t, np.inf)
    return np.where(c <= 0.0, 0.0, out).min(axis=1)  # inside a disc: touching


def _segment(p: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance along each beam from ``p`` to the segment a-b."""
    e = b - a
    denom = d[:, 0] * e[1] - d[:, 1] * e[0]
    w = a - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[0] * e[1] - w[1] * e[0]) / denom
        u = (w[0] * d[:, 1] - w[1] * d[:, 0]) / denom
    ok = (np.abs(denom) > 1e-12) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    return np.where(ok, t, np.inf)
