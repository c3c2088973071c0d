"""Pinhole projection of world geometry into the tablet image, with near-plane clipping.

A point behind the camera has no meaningful projection (the pinhole formula mirrors it through the
centre), so lines and polylines are clipped against the plane ``z_cam = near`` *in camera
coordinates* before dividing by depth; single points behind it are reported as not visible.
Distortion (OpenCV's k1 k2 p1 p2 k3) is applied in numpy: ~4× cheaper than ``cv2.projectPoints``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from runtime.frames import CameraPose

#: Default near plane (metres in front of the camera centre).
NEAR = 0.05


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics and OpenCV distortion of one camera stream."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple[float, ...] = field(default=(0.0, 0.0, 0.0, 0.0, 0.0))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(d != 0.0 for d in self.distortion)

    @staticmethod
    def parse(text: str) -> Intrinsics:
        """``"fx,fy,cx,cy,w,h"`` optionally followed by ``,k1,k2,p1,p2,k3``."""
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if len(parts) not in (6, 11):
            raise ValueError(f"intrinsics {text!r}: expected fx,fy,cx,cy,w,h[,k1,k2,p1,p2,k3]")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"intrinsics {text!r}: not numbers") from None
        fx, fy, cx, cy, w, h = values[:6]
        if fx <= 0 or fy <= 0 or w < 1 or h < 1 or w != int(w) or h != int(h):
            raise ValueError(f"intrinsics {text!r}: focal lengths must be > 0 and the size whole pixels")
        dist = tuple(values[6:]) if len(values) == 11 else (0.0,) * 5
        return Intrinsics(fx, fy, cx, cy, int(w), int(h), dist)

    @staticmethod
    def from_fov(width: int, height: int, fov_y_deg: float) -> Intrinsics:
        """An ideal pinhole with vertical field of view ``fov_y_deg`` and the principal point at the centre."""
        f = height / (2.0 * np.tan(np.radians(fov_y_deg) / 2.0))
        return Intrinsics(f, f, (width - 1) / 2.0, (height - 1) / 2.0, width, height)

    def as_list(self) -> list[float]:
        return [self.fx, self.fy, self.cx, self.cy, float(self.width), float(self.height)]


class Projector:
    """Projects world points, segments and polylines for one camera pose and intrinsics."""

    def __init__(self, pose: CameraPose, intrinsics: Intrinsics, near: float = NEAR) -> None:
        self.pose = pose
        self.K = intrinsics
        self.near = near
        self._R_cw = pose.R_cw
        self._t_cw = pose.t_cw

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        return np.asarray(points_world, dtype=np.float64).reshape(-1, 3) @ self._R_cw.T + self._t_cw

    def camera_to_pixels(self, pc: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) with z > 0 to pixels (N, 2)."""
        x = pc[:, 0] / pc[:, 2]
        y = pc[:, 1] / pc[:, 2]
        if self.K.has_distortion:
            k1, k2, p1, p2, k3 = self.K.distortion
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
            )
        return np.stack([self.K.fx * x + self.K.cx, self.K.fy * y + self.K.cy], axis=1)

    def project_points(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) and a mask of points in front of the near plane (others' pixels are NaN)."""
        pc = self.to_camera(points_world)
        front = pc[:, 2] >= self.near
        uv = np.full((len(pc), 2), np.nan)
        if front.any():
            uv[front] = self.camera_to_pixels(pc[front])
        return uv, front

    def project_polyline(self, points_world: np.ndarray) -> list[np.ndarray]:
        """A world polyline as the list of its visible 2-D pieces, clipped at the near plane.

        A polyline that dips behind the camera comes back as several pieces; each piece has at least
        two points and its end points on the near plane are exact intersections, not mirrored points.
        """
        pc = self.to_camera(points_world)
        if len(pc) < 2:
            return []
        if (pc[:, 2] >= self.near).all():  # the common case, without the per-segment loop
            return [self.camera_to_pixels(pc)]
        pieces: list[np.ndarray] = []
        current: list[np.ndarray] = []
        near = self.near
        for a, b in pairwise(pc):
            za, zb = a[2], b[2]
            if za >= near and zb >= near:
                if not current:
                    current.append(a)
                current.append(b)
                continue
            if za < near and zb < near:
                if len(current) >= 2:
                    pieces.append(np.array(current))
                current = []
                continue
            # One end behind the near plane: cut the segment where it crosses z = near.
            s = (near - za) / (zb - za)
            cut = a + s * (b - a)
            cut[2] = near
            if za >= near:  # leaving the visible half-space
                if not current:
                    current.append(a)
                current.append(cut)
                pieces.append(np.array(current))
                current = []
            else:  # entering it
                current = [cut, b]
        if len(current) >= 2:
            pieces.append(np.array(current))
        return [self.camera_to_pixels(piece) for piece in pieces]

    def depth(self, points_world: np.ndarray) -> np.ndarray:
        """Distance along the optical axis (negative behind the camera)."""
        return self.to_camera(points_world)[:, 2]


def clip_segment(
    a: np.ndarray, b: np.ndarray, box: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray] | None:
    """The part of the 2-D segment a-b inside ``box`` = (x0, y0, x1, y1) (Liang-Barsky), or None."""
    d = b - a
    t0, t1 = 0.0, 1.0
    x0, y0, x1, y1 = box
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if p == 0.0:
            if q < 0.0:
                return None
            continue
        r = q / p
        if p < 0.0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
        if t0 > t1:
            return None
    return a + t0 * d, a + t1 * d


def clip_polyline(points: np.ndarray, box: tuple[float, float, float, float]) -> list[np.ndarray]:
    """A 2-D polyline cut to ``box``: the list of its pieces inside (each at least two points).

    Keeps primitives within a sane range of the image (a line grazing the near plane projects to
    points far off-screen, which a thin client need not receive).
    """
    pts = np.asarray(points, dtype=np.float64)
    x0, y0, x1, y1 = box
    inside = (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
    if inside.all():
        return [pts] if len(pts) >= 2 else []
    pieces: list[np.ndarray] = []
    current: list[np.ndarray] = []
    for a, b in pairwise(pts):
        clipped = clip_segment(a, b, box)
        if clipped is None:
            if len(current) >= 2:
                pieces.append(np.array(current))
            current = []
            continue
        ca, cb = clipped
        if current and np.allclose(current[-1], ca):
            current.append(cb)
        else:
            if len(current) >= 2:
                pieces.append(np.array(current))
            current = [ca, cb]
        if not np.allclose(cb, b):  # left the box inside this segment
            pieces.append(np.array(current))
            current = []
    if len(current) >= 2:
        pieces.append(np.array(current))
    return pieces
