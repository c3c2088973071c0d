"""Rasterise Overlay primitives onto a BGR image (what a thin client does with an Overlay).

Primitive conventions (also in docs/services/ar_client.md, "Overlay"):

* coordinates are image pixels (OpenCV convention, pixel centres at integers); ``color`` is RGBA;
* ``line``/``polyline``: stroked through ``points``, ``width`` pixels;
* ``polygon``: filled, with the colour's alpha (the UI's button backgrounds);
* ``circle``: centre ``points[0]``, ``radius``; stroked ``width`` px, filled when ``width`` is 0;
* ``arrow``: ``points`` = [tail, head];
* ``text``: ``text`` with its baseline starting at ``points[0]``, ``radius`` = text height in pixels;
* ``style``: ``solid``; ``dashed`` (dashes); ``xray`` (dashes at half opacity: seen through a wall).

Translucent primitives are drawn on a copy of the part of the frame they cover, blended once per
opacity.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from protocol.messages import Primitive

from .project import clip_segment

DASH_ON = 10.0  # pixels
DASH_OFF = 7.0
XRAY_ALPHA = 0.5
FONT = cv2.FONT_HERSHEY_SIMPLEX
_FONT_BASE_PX = 22.0  # cv2 text height (cap height + descent) at fontScale 1, roughly


def _bgr(color: Sequence[int]) -> tuple[int, int, int]:
    r, g, b = color[:3]
    return (int(b), int(g), int(r))


def _alpha(p: Primitive) -> float:
    a = (p.color[3] if len(p.color) > 3 else 255) / 255.0
    return a * XRAY_ALPHA if p.style == "xray" else a


def _dashes(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """A polyline cut into dash segments, (K, 2, 2) pairs of points, the pattern running across joints.

    Segments are first clipped to the image (plus a margin): a line passing close to the near plane
    projects to thousands of pixels off-screen, which must not turn into millions of dashes. Only
    segments leaving that box are clipped one by one; the dashes of all segments are laid at once.
    """
    period = DASH_ON + DASH_OFF
    margin = 2.0 * period
    x0, y0, x1, y1 = box = (-margin, -margin, width + margin, height + margin)
    a0, b0 = points[:-1], points[1:]
    full = np.hypot(*(b0 - a0).T)  # (n,) segment lengths
    phase = np.concatenate([[0.0], np.cumsum(full)[:-1]])  # arc length at each segment's start
    ends_in = (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    a, b = a0.copy(), a0 + (b0 - a0)  # what clipping gives a segment wholly inside the box
    visible = full > 1e-9
    for i in np.flatnonzero(visible & ~(ends_in[:-1] & ends_in[1:])):
        clipped = clip_segment(a0[i], b0[i], box)
        if clipped is None:
            visible[i] = False
        else:
            a[i], b[i] = clipped
    s0 = phase + np.hypot(*(a - a0).T)  # arc length of each visible part's ends
    s1 = s0 + np.hypot(*(b - a).T)
    seg = np.flatnonzero(visible)
    if not len(seg):
        return np.zeros((0, 2, 2))
    # Dash k covers [k*period, k*period + DASH_ON) of arc length; intersect with [s0, s1].
    first = np.floor(s0[seg] / period)
    counts = (np.ceil(s1[seg] / period) - first + 1).astype(np.int64)
    owner = np.repeat(seg, counts)
    k = np.repeat(first, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    lo = np.maximum(k * period, s0[owner])
    hi = np.minimum(k * period + DASH_ON, s1[owner])
    keep = hi > lo
    owner, lo, hi = owner[keep], lo[keep], hi[keep]
    direction = (b0 - a0)[owner] / full[owner, None]
    starts = a0[owner] + (lo - phase[owner])[:, None] * direction
    stops = a0[owner] + (hi - phase[owner])[:, None] * direction
    return np.stack([starts, stops], axis=1)


def _int_pts(points: np.ndarray) -> np.ndarray:
    # Fixed-point with 4 fractional bits: cv2 draws at sub-pixel positions with shift=4.
    return np.round(np.asarray(points, dtype=np.float64) * 16.0).astype(np.int32)


def text_width(text: str, height_px: float) -> float:
    """Width in pixels :func:`draw` gives ``text`` at ``height_px`` (for laying out the UI)."""
    scale = height_px / _FONT_BASE_PX
    thickness = max(1, int(round(scale * 1.6)))
    (w, _h), _ = cv2.getTextSize(text, FONT, scale, thickness)
    return float(w)


def _draw_one(img: np.ndarray, p: Primitive) -> None:
    pts = np.asarray(p.points, dtype=np.float64).reshape(-1, 2) if p.points else np.zeros((0, 2))
    if not np.isfinite(pts).all():
        return
    colour = _bgr(p.color)
    width = max(1, int(round(p.width)))
    dashed = p.style in ("dashed", "xray")
    if p.kind in ("line", "polyline"):
        if len(pts) < 2:
            return
        pieces = list(_int_pts(_dashes(pts, img.shape[1], img.shape[0]))) if dashed else [_int_pts(pts)]
        cv2.polylines(img, pieces, False, colour, width, cv2.LINE_AA, shift=4)
    elif p.kind == "polygon":
        if len(pts) >= 3:
            cv2.fillPoly(img, [_int_pts(pts)], colour, cv2.LINE_AA, shift=4)
    elif p.kind == "circle":
        if len(pts) >= 1:
            centre = tuple(int(v) for v in _int_pts(pts[0]))
            cv2.circle(
                img, centre, int(round(p.radius * 16.0)), colour, -1 if p.width <= 0 else width, cv2.LINE_AA, shift=4
            )
    elif p.kind == "arrow":
        if len(pts) >= 2:
            tail, head = pts[0], pts[-1]
            length = float(np.hypot(*(head - tail)))
            if length < 1.0:
                return
            tip = min(0.4, 12.0 / length)  # head about 12 px, never more than 40 % of the arrow
            cv2.arrowedLine(
                img,
                tuple(int(v) for v in _int_pts(tail)),
                tuple(int(v) for v in _int_pts(head)),
                colour,
                width,
                cv2.LINE_AA,
                shift=4,
                tipLength=tip,
            )
    elif p.kind == "text":
        if len(pts) >= 1 and p.text:
            height = p.radius if p.radius > 0 else 16.0
            scale = height / _FONT_BASE_PX
            thickness = max(1, int(round(scale * 1.6)))
            org = (int(round(pts[0][0])), int(round(pts[0][1])))
            # A dark shadow first keeps text readable on any background (same thickness: Hershey
            # glyph advances grow with thickness, so a thicker outline would drift off the text).
            cv2.putText(img, p.text, (org[0] + 1, org[1] + 1), FONT, scale, (0, 0, 0), thickness, cv2.LINE_AA)
            cv2.putText(img, p.text, org, FONT, scale, colour, thickness, cv2.LINE_AA)


def draw(image: np.ndarray, primitives: Sequence[Primitive], *, copy: bool = True) -> np.ndarray:
    """``image`` (BGR or gray; gray is converted) with ``primitives`` drawn on it, in list order."""
    if image.ndim == 2:
        out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    else:
        out = image.copy() if copy else image
    opaque = [p for p in primitives if _alpha(p) >= 0.999]
    translucent = [p for p in primitives if _alpha(p) < 0.999]
    # Group by alpha so each group blends once (xray and the UI's backgrounds are the usual two),
    # and blend only the rectangle the group covers: a full-frame blend costs ~1 ms at 720p.
    groups: dict[float, list[Primitive]] = {}
    for p in translucent:
        groups.setdefault(round(_alpha(p), 2), []).append(p)
    h, w = out.shape[:2]
    for alpha, group in sorted(groups.items()):
        box = _bounds(group, w, h)
        if box is None:
            continue
        x0, y0, x1, y1 = box
        roi = out[y0:y1, x0:x1]
        layer = roi.copy()
        shifted = [_shift(p, -x0, -y0) for p in group]
        for p in shifted:
            _draw_one(layer, p)
        cv2.addWeighted(layer, alpha, roi, 1.0 - alpha, 0.0, dst=roi)
    for p in opaque:
        _draw_one(out, p)
    return out


def _bounds(prims: Sequence[Primitive], w: int, h: int) -> tuple[int, int, int, int] | None:
    """Integer pixel rectangle (x0, y0, x1, y1) covering ``prims`` (clipped to the image), or None."""
    lo = np.array([np.inf, np.inf])
    hi = -lo
    for p in prims:
        if not p.points:
            continue
        pts = np.asarray(p.points, dtype=np.float64).reshape(-1, 2)
        if not np.isfinite(pts).all():
            continue
        margin = p.width + 16.0 + p.radius
        if p.kind == "text":
            hi = np.maximum(hi, pts[0] + [text_width(p.text, p.radius or 16.0) + 4.0, p.radius * 0.5 + 4.0])
            lo = np.minimum(lo, pts[0] - [4.0, p.radius * 1.2 + 4.0])
        lo = np.minimum(lo, pts.min(axis=0) - margin)
        hi = np.maximum(hi, pts.max(axis=0) + margin)
    if not np.isfinite(lo).all():
        return None
    x0, y0 = int(max(np.floor(lo[0]), 0)), int(max(np.floor(lo[1]), 0))
    x1, y1 = int(min(np.ceil(hi[0]), w)), int(min(np.ceil(hi[1]), h))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


def _shift(p: Primitive, dx: float, dy: float) -> Primitive:
    """A copy of ``p`` moved by (dx, dy) pixels."""
    moved = [[x + dx, y + dy] for x, y in p.points]
    return Primitive(
        kind=p.kind,
        points=moved,
        color=p.color,
        width=p.width,
        radius=p.radius,
        text=p.text,
        style=p.style,
        layer=p.layer,
    )
