"""The virtual tablet camera: pose, intrinsics, pybullet matrices, and the messages it produces.

A :class:`CameraSpec` is a pinhole camera with no roll: ``position`` in the world, ``yaw`` the
viewing direction counter-clockwise from +x, ``pitch`` > 0 looking up (radians), an image of
``width`` × ``height`` pixels and a vertical field of view ``vfov_deg`` (square pixels).

Conventions (DESIGN §3): the camera frame is OpenCV's (x right, y down, z forward) and a pose is
``T_world_camera``. pybullet wants OpenGL matrices instead (camera x right, y up, z backward,
column-major); both are built here from the same rotation, so the rendered image and the
intrinsics describe one camera.

Pixel convention: OpenCV's, the centre of pixel (u, v) at (u, v). An ideal OpenGL rasteriser
sampling pixel centres would put the principal point at ``(w/2 − ½, h/2 − ½)``. pybullet's
ER_TINY_RENDERER is half a pixel off that in each direction (it samples at integer screen
coordinates, i.e. pixel corners, and flips its rows after rasterising): the principal point that
makes its pixels agree with a pinhole camera is ``(w/2, h/2 − 1)`` (:data:`PRINCIPAL_OFFSET`).
tests/sim/test_camera.py measures it on rendered tag edges (no detector involved) and corners.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from protocol.messages import CameraFrame, CameraTruth
from runtime.frames import camera_from_yaw_pitch, gravity_in_camera, quat_from_matrix

#: Near and far clipping planes of the rendering (m). Near is small so a tablet held close to a
#: wall still sees it; far covers any site this project generates. Depth precision is no issue:
#: the tiny renderer keeps a float depth buffer.
NEAR = 0.05
FAR = 100.0
#: (cx − w/2, cy − h/2) for ER_TINY_RENDERER, measured (see the module docstring).
PRINCIPAL_OFFSET = (0.0, -1.0)
#: Pitch beyond this leaves "no roll" undefined (the image's up would be the viewing direction).
MAX_PITCH_DEG = 89.0
#: Image sizes the camera accepts, pixels a side (the range ``arroch sim --camera-size`` allows).
MIN_SIDE, MAX_SIDE = 16, 4096
#: Supersampling factors accepted; the rendered image must stay within MAX_SIDE too.
MAX_SUPERSAMPLE = 4
#: The OpenCV camera frame and the OpenGL eye frame differ by a half-turn about x.
_CV_TO_GL = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class CameraSpec:
    """A roll-free pinhole camera in the world (angles in radians, field of view in degrees)."""

    position: tuple[float, float, float]
    yaw: float
    pitch: float
    width: int = 640
    height: int = 480
    vfov_deg: float = 60.0
    supersample: int = 1  # render s× larger and average down: anti-aliased pixels, s² the cost

    def __post_init__(self) -> None:
        values = (*self.position, self.yaw, self.pitch, self.vfov_deg)
        if len(self.position) != 3 or not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"camera position, yaw, pitch and fov must be finite numbers, got {self}")
        if abs(math.degrees(self.pitch)) > MAX_PITCH_DEG:
            raise ValueError(f"camera pitch must be within ±{MAX_PITCH_DEG:g}°, got {math.degrees(self.pitch):.1f}°")
        if not 1.0 <= self.vfov_deg <= 170.0:
            raise ValueError(f"camera vertical field of view must be within [1, 170] degrees, got {self.vfov_deg:g}")
        for name, side in (("width", self.width), ("height", self.height)):
            if not isinstance(side, numbers.Integral) or not MIN_SIDE <= side <= MAX_SIDE:
                raise ValueError(f"camera {name} must be an integer within [{MIN_SIDE}, {MAX_SIDE}], got {side!r}")
        if not isinstance(self.supersample, numbers.Integral) or not 1 <= self.supersample <= MAX_SUPERSAMPLE:
            raise ValueError(
                f"camera supersample must be an integer within [1, {MAX_SUPERSAMPLE}], got {self.supersample!r}"
            )
        if max(self.width, self.height) * self.supersample > MAX_SIDE:
            raise ValueError(
                f"camera image {self.width}x{self.height} supersampled {self.supersample}x exceeds {MAX_SIDE} pixels a "
                "side"
            )
        # Plain Python numbers from here on (numpy scalars would leak into messages and JSON).
        object.__setattr__(self, "position", tuple(float(v) for v in self.position))
        for name in ("width", "height", "supersample"):
            object.__setattr__(self, name, int(getattr(self, name)))
        for name in ("yaw", "pitch", "vfov_deg"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def from_degrees(
        cls,
        x: float,
        y: float,
        z: float,
        yaw_deg: float,
        pitch_deg: float,
        width: int = 640,
        height: int = 480,
        vfov_deg: float = 60.0,
        supersample: int = 1,
    ) -> CameraSpec:
        """The command-line form: position, then yaw and pitch in degrees."""
        return cls((x, y, z), math.radians(yaw_deg), math.radians(pitch_deg), width, height, vfov_deg, supersample)

    # ------------------------------------------------------------------ pose

    @cached_property
    def R_world_camera(self) -> np.ndarray:
        """Rotation camera → world (3×3): its columns are the OpenCV camera axes in the world."""
        R = camera_from_yaw_pitch(self.position, self.yaw, self.pitch).R_wc.copy()
        R.setflags(write=False)
        return R

    @property
    def T_world_camera(self) -> np.ndarray:
        """4×4 homogeneous ``T_world_camera`` (OpenCV camera axes)."""
        T = np.eye(4)
        T[:3, :3] = self.R_world_camera
        T[:3, 3] = self.position
        return T

    @property
    def quaternion(self) -> list[float]:
        """``[x, y, z, w]`` of ``R_world_camera`` (w ≥ 0)."""
        return [float(v) for v in quat_from_matrix(self.R_world_camera)]

    # ------------------------------------------------------------------ intrinsics

    @property
    def focal(self) -> float:
        """fx = fy in pixels, from the vertical field of view."""
        return self.height / (2.0 * math.tan(math.radians(self.vfov_deg) / 2.0))

    @property
    def intrinsics(self) -> list[float]:
        """``[fx, fy, cx, cy, width, height]`` that make the rendered pixels a pinhole camera's.

        With supersampling ``s`` the renderer's principal point ``(s·w/2 + ox, s·h/2 + oy)`` is in
        the large image, and an output pixel ``u`` averages large pixels ``s·u … s·u + s − 1``
        (centred on ``s·u + (s − 1)/2``), hence ``c = w/2 + (o − (s − 1)/2) / s``.
        """
        f, s = self.focal, self.supersample
        cx = self.width / 2.0 + (PRINCIPAL_OFFSET[0] - (s - 1) / 2.0) / s
        cy = self.height / 2.0 + (PRINCIPAL_OFFSET[1] - (s - 1) / 2.0) / s
        return [f, f, cx, cy, float(self.width), float(self.height)]

    @property
    def render_size(self) -> tuple[int, int]:
        """(width, height) the renderer draws before averaging down."""
        return self.width * self.supersample, self.height * self.supersample

    @property
    def K(self) -> np.ndarray:
        fx, fy, cx, cy = self.intrinsics[:4]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def project(self, points_world: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
        """Pixels (N, 2) of world points (N, 3) through these intrinsics (points must be in front)."""
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        cam = (pts - np.asarray(self.position)) @ self.R_world_camera  # R^T (p - c), row-wise
        if np.any(cam[:, 2] <= 0.0):
            raise ValueError("a point to project lies behind the camera")
        uvw = cam @ self.K.T
        return uvw[:, :2] / uvw[:, 2:3]

    # ------------------------------------------------------------------ pybullet (OpenGL) matrices

    def view_matrix(self) -> list[float]:
        """OpenGL world → eye matrix, column-major (what ``getCameraImage`` takes)."""
        R_gl = _CV_TO_GL @ self.R_world_camera.T  # world → GL eye rotation
        V = np.eye(4)
        V[:3, :3] = R_gl
        V[:3, 3] = -R_gl @ np.asarray(self.position)
        return V.T.reshape(-1).tolist()

    def projection_matrix(self) -> list[float]:
        """OpenGL perspective projection for the vertical fov and the image's aspect, column-major."""
        f = 1.0 / math.tan(math.radians(self.vfov_deg) / 2.0)
        aspect = self.width / self.height
        P = np.zeros((4, 4))
        P[0, 0] = f / aspect
        P[1, 1] = f
        P[2, 2] = (FAR + NEAR) / (NEAR - FAR)
        P[2, 3] = 2.0 * FAR * NEAR / (NEAR - FAR)
        P[3, 2] = -1.0
        return P.T.reshape(-1).tolist()


# ---------------------------------------------------------------------- output


def encode_jpeg(rgb: np.ndarray, quality: int = 90) -> bytes:
    """JPEG bytes of an RGB uint8 image (OpenCV encodes BGR, hence the swap)."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()


def frame_message(
    camera_id: str,
    rgb: np.ndarray,
    camera: CameraSpec,
    *,
    quality: int = 90,
    gravity_noise_deg: float | None = 1.0,
    rng: np.random.Generator | None = None,
) -> CameraFrame:
    """A CameraFrame of a rendered image (envelope left to the publisher, which stamps it).

    Its ``gravity`` is what the tablet's accelerometer would report: the true gravity in the camera
    frame turned by N(0, ``gravity_noise_deg``) about each axis; ``None`` sends no gravity.
    """
    height, width = rgb.shape[:2]
    if (width, height) != (camera.width, camera.height):
        raise ValueError(f"image is {width}x{height} but the camera is {camera.width}x{camera.height}")
    gravity = (
        []
        if gravity_noise_deg is None
        else [float(v) for v in gravity_in_camera(camera.R_world_camera, gravity_noise_deg, rng)]
    )
    return CameraFrame(
        camera=camera_id,
        jpeg=encode_jpeg(rgb, quality),
        width=width,
        height=height,
        intrinsics=camera.intrinsics[:4],
        distortion=[0.0] * 5,
        gravity=gravity,
    )


def truth_message(camera_id: str, camera: CameraSpec, frame_seq: int) -> CameraTruth:
    """The CameraTruth going with the frame published with sequence number ``frame_seq``."""
    return CameraTruth(
        camera=camera_id, frame_seq=frame_seq, position=list(camera.position), quaternion=camera.quaternion
    )


def truth_json(camera: CameraSpec) -> dict[str, list[float]]:
    """The snapshot's truth file: position, quaternion (xyzw of R_world_camera), intrinsics."""
    return {"position": list(camera.position), "quaternion": camera.quaternion, "intrinsics": camera.intrinsics}
