"""Where frames come from: the simulator's camera over Zenoh, a video file, a camera device, a folder.

``--source`` takes ``sim`` (frames arrive as ``CameraFrame`` messages on ``camera/<cid>/frame``; the
service subscribes, so there is no pull source for it), ``video:PATH``, ``device:N`` or
``images:DIR``. Pull sources yield :class:`SourceFrame` until they run out (``None``).

Frames from a video, a device or a folder carry no intrinsics: they come from ``--intrinsics`` or,
for a folder, from an ``intrinsics.json`` beside the images (``{"intrinsics": [fx, fy, cx, cy, w,
h], "distortion": [k1, k2, p1, p2, k3]}``, the latter optional). Without them the client refuses
to start rather than guess a camera (a guessed focal length would be a made-up pose).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .project import Intrinsics

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class SourceFrame:
    image: np.ndarray | bytes  # decoded BGR, or encoded bytes (the pipeline decodes and counts failures)
    intrinsics: Intrinsics
    stamp: float
    seq: int
    name: str = ""


@dataclass(frozen=True)
class SourceSpec:
    kind: str  # "sim" | "video" | "device" | "images"
    target: str = ""  # path, device index, or folder


def parse_source(text: str) -> SourceSpec:
    """``sim``, ``video:PATH``, ``device:N`` or ``images:DIR``; ``ValueError`` otherwise."""
    if text == "sim":
        return SourceSpec("sim")
    kind, sep, target = text.partition(":")
    if not sep or not target or kind not in ("video", "device", "images"):
        raise ValueError(f"--source {text!r}: expected sim, video:PATH, device:N or images:DIR")
    if kind == "device" and not target.isdigit():
        raise ValueError(f"--source {text!r}: the device is a number (e.g. device:0)")
    if kind in ("video", "images") and not Path(target).exists():
        raise FileNotFoundError(f"--source {text!r}: {target} does not exist")
    return SourceSpec(kind, target)


def folder_intrinsics(folder: str | Path) -> Intrinsics | None:
    """Intrinsics from ``DIR/intrinsics.json`` if present (``ValueError`` if it is malformed)."""
    path = Path(folder) / "intrinsics.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        values = list(data["intrinsics"]) + list(data.get("distortion", []))
        return Intrinsics.parse(",".join(str(float(v)) for v in values))
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as exc:
        raise ValueError(
            f'{path}: expected {{"intrinsics": [fx, fy, cx, cy, w, h], "distortion": [...]}} ({exc})'
        ) from None


class ImageFolderSource:
    """The folder's images in name order, once each; the stamp is the clock's time when read."""

    def __init__(self, folder: str | Path, intrinsics: Intrinsics, clock: Callable[[], float] = time.time) -> None:
        self.files = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise ValueError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
        self.intrinsics = intrinsics
        self.clock = clock
        self._it: Iterator[Path] = iter(self.files)
        self._seq = 0
        self.fps = 0.0  # as fast as they can be processed

    def read(self) -> SourceFrame | None:
        path = next(self._it, None)
        if path is None:
            return None
        self._seq += 1
        # Bytes, not a decoded image: an unreadable file is then a bad frame, counted by the pipeline.
        return SourceFrame(path.read_bytes(), self.intrinsics, self.clock(), self._seq, path.name)

    def close(self) -> None:
        pass


class VideoSource:
    """A video file or a camera device through ``cv2.VideoCapture``."""

    def __init__(self, target: str | int, intrinsics: Intrinsics, clock: Callable[[], float] = time.time) -> None:
        self.capture = cv2.VideoCapture(target)
        if not self.capture.isOpened():
            raise ValueError(f"cannot open video source {target!r}")
        self.intrinsics = intrinsics
        self.clock = clock
        fps = self.capture.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else 30.0
        self._seq = 0
        self.name = str(target)

    def read(self) -> SourceFrame | None:
        ok, image = self.capture.read()
        if not ok or image is None:
            return None
        self._seq += 1
        return SourceFrame(image, self.intrinsics, self.clock(), self._seq, f"{self.name}#{self._seq}")

    def close(self) -> None:
        self.capture.release()


def open_source(spec: SourceSpec, intrinsics: Intrinsics | None, clock: Callable[[], float] = time.time):  # noqa: ANN201
    """The pull source for ``spec`` (not for ``sim``); ``ValueError`` when intrinsics are missing."""
    if spec.kind == "sim":
        raise ValueError("the sim source is a Zenoh subscription, not a pull source")
    if spec.kind == "images" and intrinsics is None:
        intrinsics = folder_intrinsics(spec.target)
    if intrinsics is None:
        raise ValueError(
            f"--source {spec.kind}:{spec.target} needs --intrinsics fx,fy,cx,cy,w,h (the camera's calibration)"
        )
    if spec.kind == "images":
        return ImageFolderSource(spec.target, intrinsics, clock)
    target: str | int = int(spec.target) if spec.kind == "device" else spec.target
    return VideoSource(target, intrinsics, clock)
