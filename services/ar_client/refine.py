"""Sub-pixel tag corners from the tag's four edges (edge-fit refinement).

OpenCV's ArUco detector finds tags reliably but reports unrefined corners on the outermost black
pixels (≈0.4 px mean error on our frames); its SUBPIX refinement looks at a small window around each
corner only. A tag's black square is bounded by four straight edges (straight under a pinhole
projection), each seen over tens of pixels, so the corners are best found by locating every edge
precisely and intersecting the lines — the idea behind the AprilTag library's ``refine_edges``:

1. along each edge, sample points between its corners (away from the corners themselves);
2. at each sample read the intensity profile across the edge (bilinear, ``cv2.remap``), within the
   black frame module inside and the white quiet-zone module outside;
3. the edge crossing is the gradient-weighted mean position of the dark→light rise (robust to blur,
   which is symmetric about the true edge);
4. fit a line to each edge's crossings (weighted total least squares) and intersect neighbours.

All tags of a frame are processed together (one ``remap`` call, batched numpy), so this costs a
fraction of a millisecond.
With lens distortion (:class:`Lens`) the same runs in undistorted coordinates, where the edges are
straight. A corner that moves implausibly far (more than :data:`MAX_SHIFT_MODULES` of a module) keeps its
original position: a refinement must never make a detection worse.
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

#: Profile half-length across an edge, as a fraction of one module (stays inside the black frame
#: and the white quiet zone, away from data modules and the background).
REACH_MODULES = 0.7
MAX_REACH_PX = 4.0
#: Points per profile (spread over ±reach) and profiles per edge.
STEPS = 25
SAMPLES = 24
#: Edge samples cover this central part of each edge (corners are rounded by blur).
SPAN = (0.12, 0.88)
MAX_SHIFT_MODULES = 0.5
#: Profiles with less dark-to-light contrast than this (grey levels) are ignored.
MIN_CONTRAST = 20.0
_ROW = 1024


def refine_corners(
    gray: np.ndarray, quads: list[np.ndarray], passes: int = 1, lens: Lens | None = None
) -> list[np.ndarray]:
    """:func:`refine_once` ``passes`` times: a corner far off (a blurred small tag's, 1-2 px) moves
    up to a module per pass, each pass starting from the previous one's corners.

    Passes after the first go to small tags only: a tag whose profiles already reach
    :data:`MAX_REACH_PX` either side of its edges (a module of ``MAX_REACH_PX / REACH_MODULES`` px
    or more) is found within that reach by the first pass, and a second would move it by noise."""
    if passes <= 0:
        return list(quads)
    quads = refine_once(gray, quads, lens)
    for _ in range(passes - 1):
        small = [i for i, q in enumerate(quads) if _module_px(q) * REACH_MODULES < MAX_REACH_PX]
        if not small:
            break
        for i, q in zip(small, refine_once(gray, [quads[i] for i in small], lens), strict=True):
            quads[i] = q
    return list(quads)


def _module_px(quad: np.ndarray) -> float:
    """A tag's module size in pixels: its mean side over the black square's 8 modules."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = quad.tolist()  # plain floats: numpy's per-call cost dominates
    sides = math.hypot(x1 - x0, y1 - y0) + math.hypot(x2 - x1, y2 - y1) + math.hypot(x3 - x2, y3 - y2)
    return (sides + math.hypot(x0 - x3, y0 - y3)) / 32.0


class Lens:
    """A camera's lens distortion (OpenCV's model): a tag's edges are straight only once undistorted.

    The edge fit then runs in undistorted pixel coordinates (same K, no distortion): its sample points
    are mapped through the distortion to read the image, the crossings found are undistorted, the
    lines fitted and intersected there, and the corners distorted back to image pixels.
    """

    def __init__(self, K: np.ndarray, dist: np.ndarray) -> None:
        self.K = np.asarray(K, np.float64)
        self.dist = np.asarray(dist, np.float64).reshape(-1)

    def undistort(self, points: np.ndarray) -> np.ndarray:
        pts = np.asarray(points, np.float64)
        flat = cv2.undistortPoints(
            pts.reshape(-1, 1, 2),
            self.K,
            self.dist,
            R=None,
            P=self.K,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-8),
        )
        return flat.reshape(pts.shape)

    def distort(self, points: np.ndarray) -> np.ndarray:
        pts = np.asarray(points, np.float64)
        flat = pts.reshape(-1, 2)
        norm = np.column_stack(
            [(flat[:, 0] - self.K[0, 2]) / self.K[0, 0], (flat[:, 1] - self.K[1, 2]) / self.K[1, 1], np.ones(len(flat))]
        )
        image, _ = cv2.projectPoints(norm, np.zeros(3), np.zeros(3), self.K, self.dist)
        return image.reshape(pts.shape)


def refine_once(gray: np.ndarray, quads: list[np.ndarray], lens: Lens | None = None) -> list[np.ndarray]:
    """Refined TL, TR, BR, BL corners (OpenCV pixel convention) for each quad in ``quads``.

    ``quads`` hold approximate corners (4, 2) of dark squares on a light border, in that order
    (any consistent winding works). Returns new arrays; unrefinable corners are returned unchanged.
    With a ``lens``, the fit runs in undistorted coordinates (see :class:`Lens`).
    Every array below has a leading tag axis T, then edge (4), sample (K) and step (S) axes.
    """
    if not quads:
        return []
    original = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    q = original if lens is None else lens.undistort(original)
    edges = np.roll(q, -1, axis=1) - q  # (T, 4, 2): edge i runs from corner i to corner i+1
    lengths = np.linalg.norm(edges, axis=2)
    module = lengths.mean(axis=1) / 8.0  # (T,)
    reach = np.minimum(MAX_REACH_PX, REACH_MODULES * module)
    usable = np.isfinite(q).all(axis=(1, 2)) & (lengths.min(axis=1) >= 6.0) & (reach >= 0.75)
    if not usable.any():
        return [quad.copy() for quad in q]
    steps = np.linspace(-1.0, 1.0, STEPS)[None, :] * reach[:, None]  # (T, S)
    t = np.linspace(SPAN[0], SPAN[1], SAMPLES)
    bases = q[:, :, None, :] + t[None, None, :, None] * edges[:, :, None, :]  # (T, 4, K, 2)
    d = edges / np.maximum(lengths, 1e-9)[..., None]
    normals = np.stack([d[..., 1], -d[..., 0]], axis=-1)  # (T, 4, 2)
    # Point each normal outward (away from the dark square's centre).
    outward = np.einsum("tij,tij->ti", normals, q + edges / 2.0 - q.mean(axis=1, keepdims=True))
    normals = np.where((outward < 0)[..., None], -normals, normals)
    # Sample points laid out step-major, (S, T, 4, K) per coordinate: every reduction along a profile is
    # then a handful of whole-array operations instead of numpy's slow short-axis loops (same values).
    across = (steps[:, None, :, None] * normals[:, :, None, :]).transpose(2, 0, 1, 3)  # (S, T, 4, 2)
    if lens is None:
        profile = _sample_profiles(gray, bases, across)
    else:
        grid = lens.distort(bases[None] + across[:, :, :, None, :])  # (S, T, 4, K, 2)
        profile = _remap_points(gray, grid)
    # Crossing of each profile: gradient-weighted mean of its rising (dark inside → light outside) part.
    # On a uint8 frame the rises, their sums and the contrast are exact integers.
    wide = np.int16 if profile.dtype == np.uint8 else np.float64
    grad = np.maximum(profile[1:].astype(wide) - profile[:-1], 0)  # (S-1, T, 4, K)
    weight = grad.sum(axis=0, dtype=np.float64)  # (T, 4, K)
    # Step midpoints are the unit profile's midpoints scaled by each tag's reach: one matrix-vector product.
    along = _unit_mids() @ grad.reshape(STEPS - 1, -1).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        crossing = along.reshape(weight.shape) * reach[:, None, None] / weight
    contrast = profile.max(axis=0).astype(np.float64) - profile.min(axis=0)
    good = np.isfinite(crossing) & (contrast > MIN_CONTRAST)
    w = np.where(good, weight, 0.0)
    pts = bases + np.where(good, crossing, 0.0)[..., None] * normals[:, :, None, :]
    # Weighted total least squares line per edge: centroid + principal direction.
    wsum = w.sum(axis=-1)  # (T, 4)
    enough = good.sum(axis=-1) >= 4
    mean = (pts * w[..., None]).sum(axis=2) / np.maximum(wsum, 1e-12)[..., None]
    centred = (pts - mean[:, :, None, :]) * np.sqrt(w)[..., None]
    direction = _principal_directions(centred)  # (T, 4, 2)
    # Corner i is where edge i-1 (ending at it) meets edge i (starting at it).
    p, u = np.roll(mean, 1, axis=1), np.roll(direction, 1, axis=1)
    r, v = mean, direction
    det = u[..., 0] * (-v[..., 1]) - u[..., 1] * (-v[..., 0])
    rp = r - p
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (rp[..., 0] * (-v[..., 1]) - rp[..., 1] * (-v[..., 0])) / det
        corners = p + s[..., None] * u  # parallel edges (a degenerate quad) give inf/nan: not accepted below
    ok_lines = enough & np.roll(enough, 1, axis=1) & (np.abs(det) > 1e-6)
    shift = np.linalg.norm(corners - q, axis=2)
    accept = usable[:, None] & ok_lines & np.isfinite(shift) & (shift <= MAX_SHIFT_MODULES * module[:, None] + 0.5)
    if lens is not None:
        corners = lens.distort(np.where(accept[..., None], corners, q))
    refined = np.where(accept[..., None], corners, original)
    return [c for c in refined]


def sample_bilinear(gray: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Bilinear intensities (float64) at ``grid``'s (..., 2) pixel positions, in one ``cv2.remap`` call."""
    return _remap_points(gray, grid).astype(np.float64)


def _remap_points(gray: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Bilinear intensities at ``grid``'s (..., 2) pixel positions, in ``gray``'s own dtype (``cv2.remap``).

    The points go to remap as one interleaved x/y float32 map (no split into two maps). Its rows are the
    longest run of the grid's trailing axes that fits in ``_ROW`` points (remap wants under 32767 on a side,
    and works row by row: narrow rows cost more), else ``_ROW`` points with the last row padded."""
    shape = grid.shape[:-1]
    coords = np.ascontiguousarray(grid, dtype=np.float32).reshape(-1, 2)
    total = len(coords)
    width = 1
    for n in reversed(shape):
        if width * n > _ROW:
            break
        width *= n
    if width < 16 or total // width >= 32767:
        width = _ROW
    rows = -(-total // width)
    if rows * width != total:
        padded = np.zeros((rows * width, 2), np.float32)
        padded[:total] = coords
        coords = padded
    values = cv2.remap(
        gray, coords.reshape(rows, width, 2), None, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    return values.reshape(-1)[:total].reshape(shape)


def _sample_profiles(gray: np.ndarray, bases: np.ndarray, across: np.ndarray) -> np.ndarray:
    """Intensities (``gray``'s dtype) at ``bases`` (T, 4, K, 2) plus each of ``across`` (S, T, 4, 2): (S, T, 4, K).

    One remap with a map of S rows, x and y built apart (a broadcast over an innermost axis of two
    coordinates is several times slower than over the K samples)."""
    n_steps, n_tags = across.shape[0], bases.shape[0]
    if n_tags * 4 * bases.shape[2] >= 32767:  # remap's limit on a map side: half the tags at a time
        half = n_tags // 2
        return np.concatenate(
            [
                _sample_profiles(gray, bases[:half], across[:, :half]),
                _sample_profiles(gray, bases[half:], across[:, half:]),
            ],
            axis=1,
        )
    maps = []
    for c in (0, 1):
        plane = np.empty((n_steps, *bases.shape[:3]), np.float32)  # added in float64, stored as remap reads it
        np.add(bases[None, ..., c], across[..., c, None], out=plane, casting="unsafe")
        maps.append(plane.reshape(n_steps, -1))
    values = cv2.remap(gray, maps[0], maps[1], interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return values.reshape(n_steps, *bases.shape[:3])


@lru_cache(maxsize=1)
def _unit_mids() -> np.ndarray:
    """Midpoints between consecutive steps of a profile of reach 1 (each tag's are these times its reach)."""
    unit = np.linspace(-1.0, 1.0, STEPS)
    return (unit[:-1] + unit[1:]) / 2.0


def _principal_directions(centred: np.ndarray) -> np.ndarray:
    """Unit direction of largest spread of each point set in ``centred`` (..., K, 2), already centred.

    The closed form of a 2 x 2 symmetric matrix's leading eigenvector: the angle ½·atan2(2b, a − c) of
    the scatter [[a, b], [b, c]] (numpy's batched ``eigh`` costs more than the rest of the fit)."""
    x, y = centred[..., 0], centred[..., 1]
    a, b, c = (x * x).sum(axis=-1), (x * y).sum(axis=-1), (y * y).sum(axis=-1)
    angle = 0.5 * np.arctan2(2.0 * b, a - c)
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)
