"""Decoding the small tags OpenCV's ArUco detector finds as quads but fails to read.

At 10-18 px a side a tag36h11 module is 1.2-2.2 px, and with blur a lone white data module never
reaches the threshold ArUco applies to its re-sampled marker image (Otsu over a 4-px-per-cell
warp). The quad itself is usually found — it lands among the detector's *rejected* candidates. Here
each small rejected quad is read again the way the AprilTag library reads its quads:

1. its corners are refined by the edge fit (:mod:`refine`), three times: ArUco's corners of a
   blurred small quad are 1-2 px off, more than one fit can reach;
2. every module centre of the 8 x 8 black square, and points of the white quiet zone around it,
   are sampled from the original grey image (bilinear, four samples per module, averaged);
3. the black frame ring must be clearly and uniformly darker than the white quiet ring;
4. the 36 data samples are compared with every code (the site's ids only, when known) in the four
   corner orders — not bit by bit, since blur pulls a lone module towards its neighbours, but by
   normalised correlation with each code's pattern as blur shows it (a Gaussian of
   :data:`BLUR_MODULES`). The best code must correlate at :data:`MIN_SCORE` or more and beat every
   other code and order by :data:`MIN_MARGIN` (on our hard frames: true codes 0.85-0.98, the best
   wrong one 0.4-0.7, the gap never under 0.12, where bit-by-bit reading had 3-9 wrong bits).

Only quads between :data:`MIN_SIDE_PX` and :data:`MAX_SIDE_PX` are tried: bigger tags are read by
ArUco itself, and a rejected big quad is a window or a door, not a tag. All candidates of a frame
go through one ``cv2.remap`` and one vectorised code match, about 0.1 ms for a few dozen quads.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache

import cv2
import numpy as np

from .refine import Lens, refine_corners, sample_bilinear

MIN_SIDE_PX = 7.0
MAX_SIDE_PX = 48.0
REFINE_PASSES = 3
BLUR_MODULES = 0.5
MIN_SCORE = 0.7
MIN_MARGIN = 0.1
#: The black frame must be at least this much darker than the quiet zone (grey levels).
MIN_CONTRAST = 12.0
#: Frame modules allowed on the wrong side of the threshold (of 28), same for quiet-zone samples (of 36).
MAX_BAD_FRAME = 3
MAX_BAD_QUIET = 4
_SUB = np.array([[-0.22, -0.22], [0.22, -0.22], [-0.22, 0.22], [0.22, 0.22]])


@lru_cache(maxsize=1)
def _dictionary_bits() -> np.ndarray:
    """(587, 36) bool: each code's 6 x 6 data bits (True = white), generator orientation, row-major."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    return np.array(
        [
            cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[i : i + 1], d.markerSize).reshape(-1)
            for i in range(len(d.bytesList))
        ],
        bool,
    )


@lru_cache(maxsize=1)
def _blurred_patterns() -> np.ndarray:
    """(587, 36): each code's data modules as a blurred camera sees them, zero mean, unit norm."""
    codes = _dictionary_bits()
    n = len(codes)
    pattern = np.ones((n, 10, 10))  # quiet zone white
    pattern[:, 1:9, 1:9] = 0.0  # black frame
    pattern[:, 2:8, 2:8] = codes.reshape(n, 6, 6)
    offsets = np.arange(-2, 3)
    kernel = np.exp(-(offsets**2) / (2.0 * BLUR_MODULES**2))
    kernel /= kernel.sum()
    padded = np.pad(pattern, ((0, 0), (2, 2), (2, 2)), mode="edge")
    rows = sum(kernel[i] * padded[:, i : i + 10, :] for i in range(5))
    blurred = sum(kernel[i] * rows[:, :, i : i + 10] for i in range(5))
    data = blurred[:, 2:8, 2:8].reshape(n, 36)
    data = data - data.mean(axis=1, keepdims=True)
    return data / np.linalg.norm(data, axis=1, keepdims=True)


def _grid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical sample points (module units, black square = [0, 8]²): data, frame ring, quiet ring."""
    centres = np.array([[c + 0.5, r + 0.5] for r in range(8) for c in range(8)])
    ring = np.array([(r in (0, 7)) or (c in (0, 7)) for r in range(8) for c in range(8)])
    data = centres[~ring]  # 36, row-major over the inner 6 x 6
    frame = centres[ring]  # 28
    # The quiet zone: module centres of the white ring around the black square (one module wide).
    quiet = np.array(
        [[c + 0.5, -0.5] for c in range(-1, 9)]
        + [[c + 0.5, 8.5] for c in range(-1, 9)]
        + [[-0.5, r + 0.5] for r in range(8)]
        + [[8.5, r + 0.5] for r in range(8)]
    )
    return data, frame, quiet


_DATA, _FRAME, _QUIET = _grid()
_POINTS = np.concatenate([_DATA, _FRAME, _QUIET])  # 36 + 28 + 36
_SQUARE = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]])


def decode_quads(
    gray: np.ndarray, quads: Iterable[np.ndarray], known_ids: frozenset[int] | None = None, lens: Lens | None = None
) -> list[tuple[int, np.ndarray, float]]:
    """Tags read from candidate quads: ``(tag id, corners in ArUco's order, correlation)``.

    ``quads`` are (4, 2) pixel corners in any order. The corners returned are refined and in the
    order ArUco reports a detected marker's (the generator's top-left first), so
    :func:`runtime.apriltag.opencv_corners` names them as for any other OpenCV detection.
    """
    kept = []
    for q in quads:
        q = np.asarray(q, np.float64).reshape(4, 2)
        sides = np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1)
        if not (MIN_SIDE_PX <= sides.min() and sides.max() <= MAX_SIDE_PX):
            continue
        if quad_signed_area(q) < 0:  # clockwise on screen (y down), as ArUco orders its corners
            q = q[::-1].copy()
        kept.append(q)
    if not kept:
        return []
    # (The module grid is then laid by a homography: over a small tag the distortion is negligible.)
    quads_arr = np.array(refine_corners(gray, kept, REFINE_PASSES, lens))  # (Q, 4, 2)
    # Sample every quad once (corner order as given), in one remap; the other three corner orders are
    # the same samples with the 6 x 6 data grid turned (frame and quiet rings do not change).
    Hs = _homographies(quads_arr)  # (Q, 3, 3): module square -> image
    pts = (_POINTS[:, None, :] + _SUB[None, :, :]).reshape(-1, 2)  # (P*4, 2)
    homog = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
    mapped = np.einsum("qij,pj->qpi", Hs, homog)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = mapped[..., :2] / mapped[..., 2:3]
    uv = np.where(np.isfinite(uv), uv, -10.0)
    values = sample_bilinear(gray, uv).reshape(len(kept), len(_POINTS), 4).mean(axis=-1)  # (Q, P)
    grid, frame, quiet = values[:, :36].reshape(-1, 6, 6), values[:, 36:64], values[:, 64:]
    # Corner order rolled by k (corner k first) <=> the grid turned by np.rot90(..., k)
    # (pinned by tests/ar/test_smalltags.py).
    data = np.stack([np.rot90(grid, k, axes=(1, 2)).reshape(-1, 36) for k in range(4)], axis=1)  # (Q, 4, 36)
    rolls = np.stack([np.roll(quads_arr, -k, axis=1) for k in range(4)], axis=1)  # (Q, 4, 4, 2)
    black, white = np.median(frame, axis=-1), np.median(quiet, axis=-1)
    threshold = (black + white) / 2.0
    contrast_ok = np.repeat(((white - black) >= MIN_CONTRAST)[:, None], 4, axis=1)
    shape = ((frame > threshold[:, None]).sum(axis=-1) <= MAX_BAD_FRAME) & (
        (quiet < threshold[:, None]).sum(axis=-1) <= MAX_BAD_QUIET
    )
    shape_ok = np.repeat(shape[:, None], 4, axis=1)
    codes = _blurred_patterns()
    ids = (
        np.arange(len(codes))
        if known_ids is None
        else np.array(sorted(i for i in known_ids if 0 <= i < len(codes)), int)
    )
    if len(ids) == 0:
        return []
    centred = data - data.mean(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        centred = centred / np.linalg.norm(centred, axis=-1, keepdims=True)
    score = np.einsum("qkp,ip->qki", np.nan_to_num(centred), codes[ids])  # (Q, 4, I)
    out: list[tuple[int, np.ndarray, float]] = []
    for qi in range(len(kept)):
        valid = contrast_ok[qi] & shape_ok[qi]
        if not valid.any():
            continue
        sc = np.where(valid[:, None], score[qi], -1.0)
        k, j = np.unravel_index(np.argmax(sc), sc.shape)
        best = float(sc[k, j])
        second = float(np.partition(sc.reshape(-1), -2)[-2])
        if best < MIN_SCORE or best - second < MIN_MARGIN:
            continue
        out.append((int(ids[j]), rolls[qi, k].copy(), best))
    return out


def _homographies(quads: np.ndarray) -> np.ndarray:
    """(Q, 3, 3) homographies taking the module square ``_SQUARE`` to each quad (batched 8 x 8 solves)."""
    n = len(quads)
    A = np.zeros((n, 8, 8))
    b = np.zeros((n, 8))
    for i, (x, y) in enumerate(_SQUARE):
        u, v = quads[:, i, 0], quads[:, i, 1]
        A[:, 2 * i, 0:3] = [x, y, 1.0]
        A[:, 2 * i, 6], A[:, 2 * i, 7] = -u * x, -u * y
        A[:, 2 * i + 1, 3:6] = [x, y, 1.0]
        A[:, 2 * i + 1, 6], A[:, 2 * i + 1, 7] = -v * x, -v * y
        b[:, 2 * i], b[:, 2 * i + 1] = u, v
    h = np.full((n, 9), np.nan)
    ok = np.isfinite(A).all(axis=(1, 2)) & (np.abs(np.linalg.det(A)) > 1e-9)
    if ok.any():
        h[ok, :8] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
        h[ok, 8] = 1.0
    return h.reshape(n, 3, 3)


def quad_signed_area(q: np.ndarray) -> float:
    """The signed area of a (4, 2) quad (shoelace; positive when counter-clockwise with y up). In plain
    floats: called for every tag of every frame, where numpy's per-call cost is most of the work."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = q.tolist()
    return 0.5 * ((x0 * y1 - x1 * y0) + (x1 * y2 - x2 * y1) + (x2 * y3 - x3 * y2) + (x3 * y0 - x0 * y3))
