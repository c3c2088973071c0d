"""Poses that agree with the tablet's accelerometer: gravity as a measurement beside the pixels.

A tablet at rest measures gravity; its direction in the camera frame fixes the camera's roll and
pitch (within about a degree), leaving yaw and position — a 4-DoF problem. That matters most for
one small tag: its two planar-pose solutions (the IPPE pair) fit the pixels almost equally well,
but they tilt the camera differently, so only one of them agrees with gravity.

Convention: ``gravity`` is the acceleration of gravity in the camera frame (OpenCV axes: x right,
y down, z forward), pointing *down*, any magnitude (m/s² from the page or the simulator). A level
camera looking at a wall measures ``[0, g, 0]``.

* :func:`yaw_scan` — the global 4-DoF solve: for every yaw on a grid the rotation is known, so the
  position is linear least squares (algebraic error, one pseudo-inverse shared by every yaw); the
  local minima of the reprojection error over yaw are the candidate poses.
* :func:`refine` — Levenberg–Marquardt over all six DoF with the reprojection residuals (pixels)
  and gravity as a soft prior (``sigma_deg``): an image that pins the rotation better than the
  accelerometer keeps its own, a tiny tag takes gravity's.
* :func:`gravity_error` — angle between a pose's vertical and the measured one.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: Yaw grid of the 4-DoF scan (radians between samples).
YAW_STEP = np.radians(3.0)
#: A yaw-scan minimum whose RMSE exceeds the best one's by more than this factor is not kept.
SCAN_KEEP_RATIO = 6.0
DOWN = np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class GravityPrior:
    """Measured gravity (camera frame, pointing down) and how far to trust its direction."""

    direction: np.ndarray  # unit (3,)
    sigma_deg: float = 1.0

    @staticmethod
    def from_vector(vector, sigma_deg: float = 1.0) -> GravityPrior | None:  # noqa: ANN001
        """A prior from a measured vector; None when there is none (empty, non-finite or ~zero)."""
        if vector is None:
            return None
        g = np.asarray(vector, dtype=np.float64).reshape(-1)
        if g.size != 3 or not np.isfinite(g).all():
            return None
        n = float(np.linalg.norm(g))
        if n < 1e-6:
            return None
        return GravityPrior(direction=g / n, sigma_deg=float(sigma_deg))


def parse_gravity(text: str) -> np.ndarray:
    """``"GX,GY,GZ"`` (camera frame, pointing down) → vector; ValueError naming the problem."""
    parts = [p.strip() for p in text.split(",")]
    try:
        g = np.array([float(p) for p in parts], dtype=np.float64)
    except ValueError:
        raise ValueError(f"gravity {text!r}: expected three numbers GX,GY,GZ") from None
    if g.size != 3 or not np.isfinite(g).all() or np.linalg.norm(g) < 1e-6:
        raise ValueError(f"gravity {text!r}: expected three finite numbers GX,GY,GZ, not all zero")
    return g


def gravity_error(R_wc: np.ndarray, prior: GravityPrior) -> float:
    """Angle (radians) between the pose's world-down seen from the camera and the measured gravity."""
    world = R_wc @ prior.direction
    return float(np.arccos(np.clip(-world[2], -1.0, 1.0)))


def level_rotation(direction: np.ndarray) -> np.ndarray:
    """A rotation ``R0`` (camera → world at yaw 0) taking the measured down direction to world down.

    Every camera rotation agreeing with gravity is ``Rz(yaw) @ R0``.
    """
    g = direction / np.linalg.norm(direction)
    z_world_in_cam = -g  # world up, in camera coordinates
    # A horizontal reference axis: the camera's forward (or right, when looking straight up/down)
    # with its vertical part removed.
    ref = np.array([0.0, 0.0, 1.0]) if abs(g[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x_world_in_cam = ref - np.dot(ref, z_world_in_cam) * z_world_in_cam
    x_world_in_cam /= np.linalg.norm(x_world_in_cam)
    y_world_in_cam = np.cross(z_world_in_cam, x_world_in_cam)
    # Rows are the world axes in camera coordinates: this is R_wc.
    return np.stack([x_world_in_cam, y_world_in_cam, z_world_in_cam])


def _rz(yaw: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros(yaw.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out


def yaw_scan(
    obj: np.ndarray, img: np.ndarray, K: np.ndarray, dist: np.ndarray, prior: GravityPrior
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Candidate (rvec, tvec) pairs of the gravity-constrained pose, best first.

    Global over yaw: the reprojection error is evaluated on a :data:`YAW_STEP` grid (the position of
    each yaw solved linearly) and every local minimum within :data:`SCAN_KEEP_RATIO` of the best is
    returned (a planar target usually gives two: the mirror pair).
    """
    norm = cv2.undistortPoints(img.reshape(-1, 1, 2), K, dist).reshape(-1, 2)
    n = len(obj)
    # Rows of the linear system in t for x ~ (R X + t)_x / (R X + t)_z, same for y.
    A = np.zeros((2 * n, 3))
    A[0::2, 0], A[0::2, 2] = 1.0, -norm[:, 0]
    A[1::2, 1], A[1::2, 2] = 1.0, -norm[:, 1]
    pinv = np.linalg.pinv(A)
    yaws = np.arange(-np.pi, np.pi, YAW_STEP)
    R0 = level_rotation(prior.direction)
    R_wc = _rz(yaws) @ R0  # (Y, 3, 3)
    R_cw = np.transpose(R_wc, (0, 2, 1))
    RX = np.einsum("yij,nj->yni", R_cw, obj)  # (Y, N, 3)
    b = np.empty((len(yaws), 2 * n))
    b[:, 0::2] = norm[None, :, 0] * RX[..., 2] - RX[..., 0]
    b[:, 1::2] = norm[None, :, 1] * RX[..., 2] - RX[..., 1]
    t = b @ pinv.T  # (Y, 3)
    pc = RX + t[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = pc[..., :2] / pc[..., 2:3]
        err = np.sqrt(np.mean(np.sum((proj - norm[None]) ** 2, axis=2), axis=1))
    err[~np.isfinite(err) | (pc[..., 2] <= 0).any(axis=1)] = np.inf
    if not np.isfinite(err).any():
        return []
    left, right = np.roll(err, 1), np.roll(err, -1)
    minima = np.flatnonzero((err <= left) & (err <= right) & np.isfinite(err))
    best = err[minima].min()
    minima = sorted((i for i in minima if err[i] <= SCAN_KEEP_RATIO * best + 1e-9), key=lambda i: err[i])
    out = []
    for i in minima[:4]:
        rvec, _ = cv2.Rodrigues(R_cw[i])
        out.append((rvec.reshape(3, 1), t[i].reshape(3, 1).copy()))
    return out


def refine(
    obj: np.ndarray,
    img: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    prior: GravityPrior,
    *,
    sigma_px: float = 0.5,
    iterations: int = 10,
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg–Marquardt over (rvec, tvec): reprojection residuals plus gravity at ``sigma_deg``.

    The gravity residual is the horizontal part of the pose's world-down as seen by the measured
    gravity (≈ the tilt error in radians), weighted so that one ``sigma_deg`` of tilt costs as much
    as ``sigma_px`` of one coordinate of one corner.
    """
    weight = sigma_px / np.radians(prior.sigma_deg)
    x = np.concatenate([np.asarray(rvec, np.float64).reshape(3), np.asarray(tvec, np.float64).reshape(3)])

    def residuals(p: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        proj, J = cv2.projectPoints(obj, p[:3], p[3:], K, dist)
        r_img = (proj.reshape(-1, 2) - img).reshape(-1)
        r_g = _gravity_residual(p[:3], prior.direction) * weight
        r = np.concatenate([r_img, r_g])
        if not jac:
            return r, None
        Jg = np.zeros((2, 6))
        eps = 1e-6
        for k in range(3):
            d = p[:3].copy()
            d[k] += eps
            Jg[:, k] = (_gravity_residual(d, prior.direction) * weight - r_g) / eps
        return r, np.vstack([J[:, :6], Jg])

    lam = 1e-3
    r, J = residuals(x, True)
    cost = float(r @ r)
    for _ in range(iterations):
        H = J.T @ J
        g = J.T @ r
        try:
            step = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
        except np.linalg.LinAlgError:
            break
        trial = x + step
        r2, _ = residuals(trial, False)
        c2 = float(r2 @ r2)
        if c2 < cost:
            converged = cost - c2 < 1e-10 * cost + 1e-12
            x, cost = trial, c2
            if converged:
                break
            r, J = residuals(x, True)
            lam = max(lam / 10.0, 1e-9)
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    return x[:3].reshape(3, 1), x[3:].reshape(3, 1)


def _gravity_residual(rvec: np.ndarray, direction: np.ndarray) -> np.ndarray:
    R_cw, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))
    world = R_cw.T @ direction
    return world[:2]
