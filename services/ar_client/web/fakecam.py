"""A camera video file for Chromium's fake capture device (``--use-file-for-fake-video-capture``).

Chromium plays a Y4M file (uncompressed YUV 4:2:0) as the camera, in a loop, at the file's size
and frame rate: a page then runs ``getUserMedia`` exactly as on a tablet, on pictures whose true
camera pose is known (frames rendered from the site: sim snapshots or
:func:`services.ar_client.synth.render`).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np


def write_y4m(path: str | Path, frames: Iterable[np.ndarray], fps: int = 15) -> tuple[int, int, int]:
    """Write BGR or gray frames (all one even size) to ``path``; returns (width, height, count)."""
    path = Path(path)
    count = 0
    size: tuple[int, int] | None = None
    with path.open("wb") as out:
        for image in frames:
            if image.ndim == 2:
                image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
            h, w = image.shape[:2]
            if size is None:
                if w % 2 or h % 2:
                    raise ValueError(f"Y4M 4:2:0 needs an even frame size, got {w}x{h}")
                size = (w, h)
                # C420jpeg: 4:2:0 with centred chroma, what OpenCV's I420 conversion produces.
                out.write(f"YUV4MPEG2 W{w} H{h} F{int(fps)}:1 Ip A1:1 C420jpeg\n".encode())
            elif (w, h) != size:
                raise ValueError(f"frame {count} is {w}x{h}, not {size[0]}x{size[1]}")
            out.write(b"FRAME\n")
            out.write(cv2.cvtColor(image, cv2.COLOR_BGR2YUV_I420).tobytes())
            count += 1
    if size is None:
        raise ValueError("no frames to write")
    return size[0], size[1], count
