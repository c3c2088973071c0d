"""Rigid-pose arithmetic shared by every service that deals with cameras: rotations, quaternions, camera poses.

Conventions (DESIGN §3): world x east, y north, z up; camera frame OpenCV (x right, y down,
z forward). A camera pose is ``T_world_camera``: ``R_wc`` (columns are the camera axes in world
coordinates) and the camera centre ``position`` in the world. Quaternions are ``[x, y, z, w]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class CameraPose:
    """``T_world_camera``: rotation camera→world and the camera centre in world coordinates."""

    R_wc: np.ndarray  # (3, 3)
    position: np.ndarray  # (3,)

    @property
    def R_cw(self) -> np.ndarray:
        return self.R_wc.T

    @property
    def t_cw(self) -> np.ndarray:
        """Translation of the world→camera transform: x_cam = R_cw · x_world + t_cw."""
        return -self.R_wc.T @ self.position

    def rvec_tvec(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's world→camera ``rvec``, ``tvec`` (as ``solvePnP`` returns them)."""
        rvec, _ = cv2.Rodrigues(self.R_cw)
        return rvec.reshape(3), self.t_cw.reshape(3)

    @staticmethod
    def from_rvec_tvec(rvec: np.ndarray, tvec: np.ndarray) -> CameraPose:
        R_cw, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
        t = np.asarray(tvec, dtype=np.float64).reshape(3)
        return CameraPose(R_wc=R_cw.T, position=-R_cw.T @ t)

    def quaternion(self) -> np.ndarray:
        return quat_from_matrix(self.R_wc)

    @staticmethod
    def from_position_quaternion(position, quaternion) -> CameraPose:  # noqa: ANN001
        return CameraPose(R_wc=matrix_from_quat(quaternion), position=np.asarray(position, dtype=np.float64).reshape(3))

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """World points (N, 3) in camera coordinates (N, 3)."""
        return (np.asarray(points_world, dtype=np.float64) - self.position) @ self.R_wc


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``[x, y, z, w]`` (w ≥ 0) of a rotation matrix."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat(canonical=True)


def matrix_from_quat(q) -> np.ndarray:  # noqa: ANN001
    """Rotation matrix of a quaternion ``[x, y, z, w]`` (normalised first)."""
    return Rotation.from_quat(np.asarray(q, dtype=np.float64)).as_matrix()


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (radians) of the rotation taking ``R_a`` to ``R_b``."""
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def look_at(position, target, up=(0.0, 0.0, 1.0)) -> CameraPose:  # noqa: ANN001
    """A camera at ``position`` looking at ``target`` with image "up" towards world ``up`` (no roll)."""
    p = np.asarray(position, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - p
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # image down
    return CameraPose(R_wc=np.stack([x, y, z], axis=1), position=p)


def camera_from_yaw_pitch(position, yaw: float, pitch: float, roll: float = 0.0) -> CameraPose:  # noqa: ANN001
    """A camera at ``position`` whose optical axis has heading ``yaw`` (CCW from +x) and elevation ``pitch``
    (positive looks up), rolled by ``roll`` about its optical axis (positive turns the image clockwise)."""
    forward = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
    pose = look_at(position, np.asarray(position, dtype=np.float64) + forward)
    if roll == 0.0:
        return pose
    c, s = np.cos(roll), np.sin(roll)
    R_roll = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # about the camera's z
    return CameraPose(R_wc=pose.R_wc @ R_roll, position=pose.position)


#: Standard gravity (m/s²).
GRAVITY = 9.80665


def gravity_in_camera(R_wc: np.ndarray, sigma_deg: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
    """What a tablet's accelerometer reports as gravity, in the camera frame (OpenCV axes, pointing down).

    The truth ``R_cw · (0, 0, −g)``, turned by a random small rotation whose components are
    N(0, ``sigma_deg``) about each camera axis (an IMU's tilt error) when ``sigma_deg`` > 0.
    """
    g = np.asarray(R_wc, dtype=np.float64).T @ np.array([0.0, 0.0, -GRAVITY])
    if sigma_deg > 0.0:
        rng = rng if rng is not None else np.random.default_rng()
        noise, _ = cv2.Rodrigues(rng.normal(0.0, np.radians(sigma_deg), 3).reshape(3, 1))
        g = noise @ g
    return g
