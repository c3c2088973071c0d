"""The camera model of a tablet's stream: from a calibration file, or a documented default.

Intrinsics file (written by ``arroch ar calibrate``, read by ``arroch tablet --intrinsics FILE``; the
same shape ``arroch ar --source images:DIR`` reads from ``DIR/intrinsics.json``)::

    {"intrinsics": [fx, fy, cx, cy, width, height], "distortion": [k1, k2, p1, p2, k3], ...}

A browser sends frames at whatever size the link allows (the page downscales when round trips
grow), so a calibration made at ``width × height`` is scaled to each frame's size: focal lengths
and the principal point scale with the image (pixel centres at integers: ``c' = (c + ½)·s − ½``);
distortion coefficients, on normalised coordinates, do not change. A frame whose aspect ratio
differs from the calibration's by more than 1 % comes from another sensor mode (cropped
differently), so the calibration does not apply: the default is used and the page is told.

Default, without a calibration: an ideal pinhole (no distortion) with the principal point at the
image centre and a horizontal field of view of :data:`DEFAULT_HFOV_DEG` degrees — typical of a
tablet's or phone's main rear camera (about a 28 mm-equivalent lens). Poses are then only as good
as that guess (a 10 % focal-length error scales distances by about 10 %); calibrate for real use.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from ..project import Intrinsics

DEFAULT_HFOV_DEG = 62.0
ASPECT_TOLERANCE = 0.01


def load_intrinsics(path: str | Path) -> Intrinsics:
    """Intrinsics from a calibration file; ``ValueError`` naming the file when it is malformed."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        values = [float(v) for v in data["intrinsics"]]
        distortion = [float(v) for v in data.get("distortion", [0.0] * 5)]
    except FileNotFoundError:
        raise
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as exc:
        raise ValueError(
            f'{path}: expected {{"intrinsics": [fx, fy, cx, cy, w, h], "distortion": [k1, k2, p1, p2, k3]}} ({exc})'
        ) from None
    if len(values) != 6 or len(distortion) != 5:
        raise ValueError(f"{path}: 'intrinsics' needs 6 numbers and 'distortion' 5")
    return Intrinsics.parse(",".join(repr(v) for v in values + distortion))


def write_intrinsics(path: str | Path, intrinsics: Intrinsics, **extra: object) -> None:
    """Write a calibration file (``extra`` adds fields such as the RMS error and the pattern)."""
    data = {"intrinsics": intrinsics.as_list(), "distortion": list(intrinsics.distortion), **extra}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def default_intrinsics(width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG) -> Intrinsics:
    f = width / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))
    return Intrinsics(f, f, (width - 1) / 2.0, (height - 1) / 2.0, width, height)


def scaled(calibration: Intrinsics, width: int, height: int) -> Intrinsics | None:
    """``calibration`` for a ``width × height`` version of the same stream, or None if the aspect differs."""
    sx, sy = width / calibration.width, height / calibration.height
    if abs(sx / sy - 1.0) > ASPECT_TOLERANCE:
        return None
    return Intrinsics(
        calibration.fx * sx,
        calibration.fy * sy,
        (calibration.cx + 0.5) * sx - 0.5,
        (calibration.cy + 0.5) * sy - 0.5,
        width,
        height,
        calibration.distortion,
    )


@dataclass
class CameraModel:
    """Intrinsics for each frame size of one stream; ``describe`` says where they came from."""

    calibration: Intrinsics | None = None
    hfov_deg: float = DEFAULT_HFOV_DEG

    def __post_init__(self) -> None:
        self._cache: dict[tuple[int, int], tuple[Intrinsics, str]] = {}

    def for_size(self, width: int, height: int) -> tuple[Intrinsics, str]:
        """(intrinsics, a short description of their source) for a frame of this size."""
        key = (width, height)
        hit = self._cache.get(key)
        if hit is None:
            hit = self._make(width, height)
            if len(self._cache) > 64:  # a page that keeps changing size must not grow this forever
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def _make(self, width: int, height: int) -> tuple[Intrinsics, str]:
        if self.calibration is not None:
            K = scaled(self.calibration, width, height)
            if K is not None:
                return K, f"calibrated at {self.calibration.width}x{self.calibration.height}"
            why = (
                f"default {self.hfov_deg:g} deg (calibration is {self.calibration.width}x{self.calibration.height}, "
                "another aspect)"
            )
            return default_intrinsics(width, height, self.hfov_deg), why
        return default_intrinsics(
            width, height, self.hfov_deg
        ), f"default {self.hfov_deg:g} deg field of view (not calibrated)"
