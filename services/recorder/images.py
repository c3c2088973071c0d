"""Camera frames made smaller for a recording (``arroch record --image-scale``): the JPEG resized
and re-encoded, its intrinsics scaled with it, the overlay drawn for it scaled alike.

Pixel centres stay put: ``u' = (u + ½)·s − ½`` (as the tablet scales a calibration to a frame).
"""

from __future__ import annotations

import cv2
import msgspec
import numpy as np

from protocol.messages import CameraFrame, Overlay

JPEG_QUALITY = 85


def _pixel(value: float, scale: float) -> float:
    return (value + 0.5) * scale - 0.5


def scale_frame(frame: CameraFrame, scale: float) -> CameraFrame:
    """The frame at ``scale`` (0 < scale < 1); a JPEG that does not decode is kept as it is."""
    image = cv2.imdecode(np.frombuffer(frame.jpeg, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return frame
    width, height = max(1, round(frame.width * scale)), max(1, round(frame.height * scale))
    sx, sy = width / frame.width, height / frame.height
    small = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    ok, jpeg = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        return frame
    fx, fy, cx, cy = frame.intrinsics
    return msgspec.structs.replace(
        frame,
        jpeg=jpeg.tobytes(),
        width=width,
        height=height,
        intrinsics=[fx * sx, fy * sy, _pixel(cx, sx), _pixel(cy, sy)],
    )


def scale_overlay(overlay: Overlay, scale: float) -> Overlay:
    """The overlay's primitives in the pixels of the frame scaled by ``scale``."""
    prims = [
        msgspec.structs.replace(
            p,
            points=[[_pixel(u, scale), _pixel(v, scale)] for u, v in p.points],
            width=p.width * scale,
            radius=p.radius * scale,
        )
        for p in overlay.primitives
    ]
    return msgspec.structs.replace(
        overlay, primitives=prims, width=round(overlay.width * scale), height=round(overlay.height * scale)
    )
