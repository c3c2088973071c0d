"""Synthetic tablet frames: the site's wall tags rendered at a known camera pose.

Used by the tests and the benchmark as a second source of real pixels beside the simulator's
snapshots: each visible landmark's official tag image (:func:`runtime.apriltag.tag_image`, with
its white quiet zone) is warped onto a grey background with ``cv2.warpPerspective`` through the
homography of its printed corners, on a 3× supersampled canvas averaged down (anti-aliased module
edges), then blurred slightly and given sensor noise. The true pixel positions of every tag's
black-square corners come back with the image, so detectors and poses can be scored exactly.

A landmark is drawn when it faces the camera, lies wholly in front of the near plane, and no wall
stands between the camera and it (see :mod:`services.ar_client.visibility`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from runtime.apriltag import tag_image
from runtime.frames import CameraPose

from .project import Intrinsics, Projector
from .visibility import Occluders

SUPERSAMPLE = 3


@dataclass
class SyntheticFrame:
    image: np.ndarray  # uint8 grayscale (h, w)
    pose: CameraPose  # the truth
    intrinsics: Intrinsics
    corners: dict[int, np.ndarray]  # tag id -> (4, 2) true TL, TR, BR, BL pixels of every drawn tag
    in_view: list[int]  # drawn tags wholly inside the image (the ones a detector should find)


@lru_cache(maxsize=256)
def _texture(tag_id: int, module_px: int) -> np.ndarray:
    return tag_image(tag_id, module_px=module_px, border_modules=1)


def render(
    site,  # protocol.site.Site
    pose: CameraPose,
    intrinsics: Intrinsics,
    *,
    seed: int = 0,
    noise_sigma: float = 2.0,
    blur_sigma: float = 0.6,
    background: int = 120,
    occluders: Occluders | None = None,
) -> SyntheticFrame:
    """Render the site's landmarks as seen from ``pose`` (no distortion; intrinsics' own is ignored)."""
    w, h, s = intrinsics.width, intrinsics.height, SUPERSAMPLE
    rng = np.random.default_rng(seed)
    projector = Projector(pose, intrinsics)
    occluders = occluders or Occluders.from_site(site)
    # A gentle horizontal gradient so the background is not a perfect constant.
    canvas = np.empty((h * s, w * s), np.uint8)
    canvas[:] = np.clip(background + np.linspace(-20, 20, w * s), 0, 255).astype(np.uint8)[None, :]
    corners: dict[int, np.ndarray] = {}
    in_view: list[int] = []
    cam = pose.position
    # Far tags first so nearer ones paint over them.
    order = sorted(site.landmarks, key=lambda lm: -np.linalg.norm(np.asarray(lm.position) - cam))
    for lm in order:
        centre = np.asarray(lm.position, dtype=np.float64)
        normal = np.asarray(lm.normal, dtype=np.float64)
        if np.dot(cam - centre, normal) <= 0.0:
            continue  # seen from behind (or edge-on)
        # Test the line of sight to a point just in front of the tag, so its own wall does not hide it.
        if occluders.blocked(cam[:2], (centre + 0.05 * normal)[:2]):
            continue
        printed = lm.corners(printed=True)
        uv_printed, front = projector.project_points(printed)
        if not front.all():
            continue
        uv_black, _ = projector.project_points(lm.corners())
        # Canvas coordinates of a final-image point u: U = s·(u + 0.5) − 0.5 (pixel centres at integers).
        dst = (s * (uv_printed + 0.5) - 0.5).astype(np.float32)
        footprint = float(np.max(np.linalg.norm(np.roll(dst, -1, axis=0) - dst, axis=1)))
        module_px = int(np.clip(np.ceil(footprint / 10.0), 2, 64))  # texture about as fine as the canvas
        tex = _texture(lm.tag, module_px)
        n = tex.shape[0]
        src = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
        x0, y0 = np.floor(dst.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(dst.max(axis=0)).astype(int) + 2
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w * s), min(y1, h * s)
        if x1 <= x0 or y1 <= y0:
            continue
        shift = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1]], np.float64)
        H = shift @ cv2.getPerspectiveTransform(src, dst)
        size = (x1 - x0, y1 - y0)
        warped = cv2.warpPerspective(
            tex, H, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
        )
        mask = cv2.warpPerspective(np.full_like(tex, 255), H, size, flags=cv2.INTER_LINEAR, borderValue=0)
        roi = canvas[y0:y1, x0:x1]
        alpha = mask.astype(np.float32) / 255.0
        roi[:] = (warped * alpha + roi * (1.0 - alpha)).astype(np.uint8)
        corners[lm.tag] = uv_black
        if (
            (uv_printed[:, 0] >= 0).all()
            and (uv_printed[:, 0] <= w - 1).all()
            and (uv_printed[:, 1] >= 0).all()
            and (uv_printed[:, 1] <= h - 1).all()
        ):
            in_view.append(lm.tag)
    image = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA)
    if blur_sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
    if noise_sigma > 0:
        image = np.clip(image + rng.normal(0.0, noise_sigma, image.shape), 0, 255).astype(np.uint8)
    return SyntheticFrame(image=image, pose=pose, intrinsics=intrinsics, corners=corners, in_view=sorted(in_view))


@dataclass(frozen=True)
class View:
    """A sampled camera pose looking at ``anchor`` from ``distance`` m at ``obliquity`` rad off its normal."""

    pose: CameraPose
    anchor: int
    distance: float
    obliquity: float


def sample_views(
    site,  # protocol.site.Site
    n: int,
    *,
    seed: int = 0,
    distance: tuple[float, float] = (1.0, 4.0),
    max_obliquity_deg: float = 60.0,
    heights: tuple[float, float] = (1.0, 1.8),
    aim_jitter: float = 0.3,
    max_roll_deg: float = 8.0,
    wall_clearance: float = 0.3,
) -> list[View]:
    """``n`` hand-held-tablet poses, each looking at a random landmark from inside the building.

    The camera stands ``distance`` metres from the tag at up to ``max_obliquity_deg`` off the tag's
    normal (either side), at a height in ``heights``, aimed at a point within ``aim_jitter`` m of
    the tag (so tags are not always centred), rolled a little. Poses outside every room (with
    ``wall_clearance``) or with a wall between camera and tag are drawn again. Deterministic per seed.
    """
    from runtime.frames import look_at

    rng = np.random.default_rng(seed)
    occ = Occluders.from_site(site)
    out: list[View] = []
    landmarks = list(site.landmarks)
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 1000 * max(n, 1):
            raise RuntimeError("sample_views: could not place cameras; is the site's landmark layout reachable?")
        lm = landmarks[int(rng.integers(len(landmarks)))]
        d = float(rng.uniform(*distance))
        ob = float(np.radians(rng.uniform(0.0, max_obliquity_deg)) * rng.choice([-1.0, 1.0]))
        h = float(rng.uniform(*heights))
        centre = np.asarray(lm.position, dtype=np.float64)
        direction = np.array([np.cos(lm.yaw + ob), np.sin(lm.yaw + ob)])
        # Horizontal distance chosen so the 3-D distance to the tag is d.
        dz = h - centre[2]
        if d <= abs(dz):
            continue
        xy = centre[:2] + direction * np.sqrt(d * d - dz * dz)
        if not any(r.contains(xy[0], xy[1], margin=wall_clearance) for r in site.rooms.values()):
            continue
        if occ.blocked(xy, centre[:2] + 0.05 * np.asarray(lm.normal)[:2]):
            continue
        right = np.array([-np.sin(lm.yaw), np.cos(lm.yaw), 0.0])
        target = (
            centre
            + right * rng.uniform(-aim_jitter, aim_jitter)
            + np.array([0, 0, rng.uniform(-aim_jitter, aim_jitter) * 0.6])
        )
        pose = look_at([xy[0], xy[1], h], target)
        roll = np.radians(rng.uniform(-max_roll_deg, max_roll_deg))
        c, s = np.cos(roll), np.sin(roll)
        pose = CameraPose(
            R_wc=pose.R_wc @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), position=pose.position
        )
        out.append(View(pose=pose, anchor=lm.tag, distance=d, obliquity=abs(ob)))
    return out
