"""A geometric check of what a tablet camera sees: frustum, facing and wall occlusion (no rendering)."""

from __future__ import annotations

import math

import numpy as np

from protocol.site import Site

YAWS = (0.0, math.pi / 2, math.pi, -math.pi / 2)  # facing east, north, west, south walls


def camera_axes(yaw: float) -> np.ndarray:
    """Rows: the camera's x (right), y (down), z (forward) in the world, for a level camera at ``yaw``."""
    return np.array([[math.sin(yaw), -math.cos(yaw), 0.0], [0.0, 0.0, -1.0], [math.cos(yaw), math.sin(yaw), 0.0]])


def _segments_hit_boxes(p: np.ndarray, q: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """For 2-D segments p[i] -> q[i], whether each crosses any axis-aligned box (slab test), shape (N,)."""
    d = (q - p)[:, None, :]  # (N, 1, 2)
    lo, hi = boxes[None, :, :2], boxes[None, :, 2:]  # (1, W, 2)
    start = p[:, None, :]
    inside = (start >= lo) & (start <= hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - start) / d, (hi - start) / d
    parallel = d == 0
    tmin = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    tmax = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    enter = np.maximum(tmin.max(axis=2), 0.0)
    leave = np.minimum(tmax.min(axis=2), 1.0)
    return (enter < leave).any(axis=1)


def visible_matrix(
    site: Site, cameras: np.ndarray, yaws: np.ndarray, vfov_deg: float = 60.0, aspect: float = 4.0 / 3.0
) -> np.ndarray:
    """(P, T) booleans: pose p sees landmark t, i.e. its four black-square corners are inside the image,
    it faces the camera and no wall or closed door leaf stands between them."""
    tan_v = math.tan(math.radians(vfov_deg) / 2.0)
    tan_h = aspect * tan_v
    corners = np.stack([lm.corners() for lm in site.landmarks])  # (T, 4, 3)
    axes = np.stack([camera_axes(float(y)) for y in yaws])  # (P, 3, 3)
    rel = corners[None] - cameras[:, None, None, :]  # (P, T, 4, 3)
    pc = np.einsum("ptkj,pij->ptki", rel, axes)
    z = pc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        in_view = (z > 0.05) & (np.abs(pc[..., 0] / z) <= tan_h) & (np.abs(pc[..., 1] / z) <= tan_v)
    normals = np.array([lm.normal for lm in site.landmarks])
    positions = np.array([lm.position for lm in site.landmarks])
    facing = np.einsum("ptj,tj->pt", cameras[:, None, :] - positions[None], normals) > 0
    seen = in_view.all(axis=2) & facing
    pose_idx, tag_idx = np.nonzero(seen)
    if len(pose_idx):
        boxes = np.array([w.box for w in site.walls] + [leaf.box(open=False) for leaf in site.door_leaves.values()])
        starts = np.repeat(cameras[pose_idx, :2], 4, axis=0)
        ends = corners[tag_idx, :, :2].reshape(-1, 2)
        blocked = _segments_hit_boxes(starts, ends, boxes).reshape(-1, 4).any(axis=1)
        seen[pose_idx[blocked], tag_idx[blocked]] = False
    return seen


def visible_tags(site: Site, camera: tuple[float, float, float], yaw: float) -> list[int]:
    """Tag ids one tablet pose sees."""
    row = visible_matrix(site, np.array([camera], dtype=float), np.array([yaw]))[0]
    return [site.landmarks[i].tag for i in np.nonzero(row)[0]]


def tablet_poses(
    site: Site, room_id: str, min_wall_distance: float = 0.7, step: float = 0.1, height: float = 1.3
) -> tuple[np.ndarray, np.ndarray]:
    """Cameras on a grid (boundaries included) at least ``min_wall_distance`` from the room's wall faces,
    each with the four yaws facing the walls: ``(cameras (P, 3), yaws (P,))``."""
    x0, y0, x1, y1 = site.rooms[room_id].rect
    inset = site.params.wall_thickness / 2.0 + min_wall_distance
    xs = np.linspace(x0 + inset, x1 - inset, max(2, math.ceil((x1 - x0 - 2 * inset) / step) + 1))
    ys = np.linspace(y0 + inset, y1 - inset, max(2, math.ceil((y1 - y0 - 2 * inset) / step) + 1))
    gx, gy, gyaw = np.meshgrid(xs, ys, np.array(YAWS), indexing="ij")
    cameras = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, height)], axis=1)
    return cameras, gyaw.ravel()


def poses_seeing_fewer_than(site: Site, room_id: str, count: int = 2) -> list[tuple[tuple[float, ...], float, int]]:
    """Every tablet pose in ``room_id`` that sees fewer than ``count`` tags: (camera, yaw, number seen)."""
    cameras, yaws = tablet_poses(site, room_id)
    counts = visible_matrix(site, cameras, yaws).sum(axis=1)
    return [(tuple(cameras[i]), float(yaws[i]), int(counts[i])) for i in np.nonzero(counts < count)[0]]
