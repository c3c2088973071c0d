"""What the tablet can see directly and what only "X-ray": line of sight against the site's walls.

The building's walls are full height (2.5 m), so for a camera below wall height a world point is
hidden exactly when the floor-plane segment from the camera to the point crosses a wall's centre
line. Openings are gaps in the wall list (``site.walls`` already stops at every door and passage),
so a passage never occludes; a *closed* door occludes through its leaf, an open one does not.

Everything is vectorised over points × walls: an Intent of a few hundred samples against an
office's ~50 walls costs well under a millisecond.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

#: Paths are resampled at this spacing (metres) before classification, so a wall crossing between
#: two far-apart trajectory rows still splits the path where it should.
SAMPLE_STEP = 0.05


@dataclass
class Occluders:
    """Wall centre lines (and closed door leaves) as segment arrays ``a`` (M, 2), ``b`` (M, 2)."""

    a: np.ndarray
    b: np.ndarray
    height: float = 2.5

    @staticmethod
    def from_site(site, open_doors: Iterable[str] | None = None) -> Occluders:  # noqa: ANN001
        """Walls of ``site`` plus the leaves of its doors not in ``open_doors``.

        ``open_doors=None`` treats every door as closed (the state before any DoorState arrives).
        """
        opened = set(open_doors or ())
        segs = [(w.a, w.b) for w in site.walls]
        for door_id, leaf in site.door_leaves.items():
            if door_id not in opened:
                segs.append((leaf.hinge, leaf.tip(open=False)))
        a = np.array([s[0] for s in segs], dtype=np.float64).reshape(-1, 2)
        b = np.array([s[1] for s in segs], dtype=np.float64).reshape(-1, 2)
        return Occluders(a=a, b=b, height=site.params.wall_height)

    def blocked_many(self, eye: np.ndarray, points: np.ndarray, eye_z: float | None = None) -> np.ndarray:
        """For each floor-plane point (N, 2): does a wall cross the segment eye→point?

        Proper crossings only: a segment that merely touches a wall's end (a door jamb) is not
        blocked, so a robot standing in a doorway stays visible.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(self.a) == 0 or len(pts) == 0 or (eye_z is not None and eye_z >= self.height):
            return np.zeros(len(pts), dtype=bool)
        e = np.asarray(eye, dtype=np.float64).reshape(2)
        d = pts - e  # (N, 2) sight lines
        w = self.b - self.a  # (M, 2) walls
        # Solve e + t·d = a + u·w for every (point, wall) pair.
        denom = d[:, None, 0] * w[None, :, 1] - d[:, None, 1] * w[None, :, 0]  # (N, M)
        ea = self.a[None, :, :] - e[None, None, :]  # (1, M, 2)
        t_num = ea[..., 0] * w[None, :, 1] - ea[..., 1] * w[None, :, 0]  # (1, M)
        u_num = ea[..., 0] * d[:, None, 1] - ea[..., 1] * d[:, None, 0]  # (N, M)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = t_num / denom
            u = u_num / denom
        eps = 1e-9
        hit = (np.abs(denom) > 1e-12) & (t > eps) & (t < 1 - eps) & (u > eps) & (u < 1 - eps)
        return hit.any(axis=1)

    def blocked(self, eye, point, eye_z: float | None = None) -> bool:  # noqa: ANN001
        return bool(self.blocked_many(np.asarray(eye)[:2], np.asarray(point, dtype=np.float64)[None, :2], eye_z)[0])


def resample(points: np.ndarray, step: float = SAMPLE_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Insert points along a polyline (N, D) so no segment exceeds ``step`` (in its first two coordinates).

    Returns the new points and, for each, its fractional index into the original polyline (so other
    per-row values such as times can be interpolated onto them).
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        return pts.copy(), np.arange(len(pts), dtype=np.float64)
    seg = np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)
    counts = np.maximum(np.ceil(seg / step).astype(int), 1)
    frac = np.concatenate([i + np.arange(c) / c for i, c in enumerate(counts)] + [np.array([len(pts) - 1.0])])
    i0 = np.minimum(np.floor(frac).astype(int), len(pts) - 2)
    s = (frac - i0)[:, None]
    return pts[i0] * (1 - s) + pts[i0 + 1] * s, frac


def split_runs(points: np.ndarray, hidden: np.ndarray) -> list[tuple[bool, np.ndarray]]:
    """Cut a polyline into maximal runs of equal ``hidden`` flags: ``[(hidden, points), ...]``.

    Consecutive runs share their boundary point, so the drawn pieces join without a gap.
    """
    if len(points) == 0:
        return []
    runs: list[tuple[bool, np.ndarray]] = []
    change = np.flatnonzero(hidden[1:] != hidden[:-1]) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(points)]])
    for s, e in zip(starts, ends, strict=True):
        piece = points[s : min(e + 1, len(points))]
        if len(piece) >= 2:
            runs.append((bool(hidden[s]), piece))
    return runs
