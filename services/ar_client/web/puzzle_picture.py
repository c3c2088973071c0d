"""The puzzle's picture, drawn from the trial's seed: no image file ships with the page.

A smooth four-colour gradient (so every piece differs from every other even where no shape lies)
under seeded discs, rings, boxes, triangles and stripes in seeded colours with dark outlines, so
a person can tell the pieces apart and see where each one fits. The same seed draws the same
picture on every machine (the random stream is :class:`random.Random` seeded with a string; the
drawing is OpenCV's, in integer pixel coordinates).
"""

from __future__ import annotations

import colorsys
import math
import random

import cv2
import numpy as np

PIECE_PX = 128  # pixels a side of one piece in the served picture
OUTLINE = (25, 25, 30)


def _colour(rng: random.Random, lightness: tuple[float, float] = (0.35, 0.7)) -> tuple[int, int, int]:
    """A saturated RGB colour."""
    h = rng.random()
    lo, hi = lightness
    r, g, b = colorsys.hls_to_rgb(h, lo + (hi - lo) * rng.random(), 0.65 + 0.35 * rng.random())
    return int(r * 255), int(g * 255), int(b * 255)


def _gradient(rng: random.Random, width: int, height: int) -> np.ndarray:
    corners = np.array([_colour(rng, (0.55, 0.85)) for _ in range(4)], dtype=np.float32)
    u = np.linspace(0.0, 1.0, width, dtype=np.float32)[None, :, None]
    v = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None]
    top = corners[0] * (1 - u) + corners[1] * u
    bottom = corners[2] * (1 - u) + corners[3] * u
    return np.ascontiguousarray((top * (1 - v) + bottom * v).astype(np.uint8))


def picture(seed: int, rows: int, cols: int, piece_px: int = PIECE_PX) -> np.ndarray:
    """The RGB picture (``rows·piece_px`` × ``cols·piece_px``) of the puzzle with this seed."""
    width, height = cols * piece_px, rows * piece_px
    rng = random.Random(f"arroch-puzzle-picture:{seed}")
    image = _gradient(rng, width, height)
    unit = piece_px
    # Stripes first, shapes over them: a few wide diagonal bands across the whole picture.
    for _ in range(2):
        colour = _colour(rng, (0.6, 0.8))
        angle = rng.random() * math.pi
        offset = (rng.random() - 0.5) * width
        dx, dy = math.cos(angle), math.sin(angle)
        cx, cy = width / 2 + offset * -dy, height / 2 + offset * dx
        span = 2 * max(width, height)
        p0 = (int(cx - dx * span), int(cy - dy * span))
        p1 = (int(cx + dx * span), int(cy + dy * span))
        cv2.line(image, p0, p1, colour, int(unit * (0.25 + 0.3 * rng.random())), cv2.LINE_AA)
    shapes = rows * cols + 4
    for _ in range(shapes):
        kind = rng.choice(("disc", "ring", "box", "triangle"))
        colour = _colour(rng)
        x = int(rng.random() * width)
        y = int(rng.random() * height)
        size = int(unit * (0.25 + 0.5 * rng.random()))
        if kind == "disc":
            cv2.circle(image, (x, y), size, colour, -1, cv2.LINE_AA)
            cv2.circle(image, (x, y), size, OUTLINE, 3, cv2.LINE_AA)
        elif kind == "ring":
            thickness = max(6, size // 3)
            cv2.circle(image, (x, y), size, OUTLINE, thickness + 6, cv2.LINE_AA)
            cv2.circle(image, (x, y), size, colour, thickness, cv2.LINE_AA)
        else:
            corners = 4 if kind == "box" else 3
            turn = rng.random() * 2 * math.pi
            angles = [turn + 2 * math.pi * k / corners for k in range(corners)]
            pts = np.array([(x + size * math.cos(a), y + size * math.sin(a)) for a in angles], dtype=np.int32)
            cv2.fillPoly(image, [pts], colour, cv2.LINE_AA)
            cv2.polylines(image, [pts], True, OUTLINE, 3, cv2.LINE_AA)
    return image


def picture_png(seed: int, rows: int, cols: int, piece_px: int = PIECE_PX) -> bytes:
    """The picture as PNG bytes (what the page loads from ``/puzzle.png``)."""
    ok, data = cv2.imencode(".png", cv2.cvtColor(picture(seed, rows, cols, piece_px), cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError("PNG encoding of the puzzle picture failed")
    return data.tobytes()
