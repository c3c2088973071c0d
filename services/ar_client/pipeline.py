"""One frame in, one Overlay (and optionally the annotated image) out.

:meth:`Pipeline.process` is the whole AR client for a frame, independent of where frames come from
(Zenoh, a video, a tablet's WebSocket) and where overlays go::

    decode → detect (+ guided second pass) → localise → project world → draw

It reads the world from a :class:`WorldView` (fed by the service from Zenoh, or from a file) and
keeps the tracking state between frames. ``timings`` holds the last frame's per-stage seconds.
A frame that cannot be decoded raises :class:`BadFrame`; the caller counts and drops it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from protocol.messages import Overlay
from runtime.frames import CameraPose

from .detect import TagDetection, TagDetector, to_gray
from .draw import draw
from .feedback import FeedbackPanel
from .gravity import GravityPrior
from .localize import Localization, Localizer
from .overlay import OverlayBuilder, status_primitives
from .posefilter import FilteredPose, PoseFilter
from .project import Intrinsics, Projector
from .refine import Lens
from .world import WorldSnapshot, WorldView

#: Guided second pass: at most this many crops per frame, for predicted tags at least this big.
MAX_GUIDED_CROPS = 4
MIN_GUIDED_PX = 12.0
#: ... and only for tags seen less obliquely than this (beyond, they are not decodable anyway).
MAX_GUIDED_OBLIQUITY = np.radians(75.0)


#: A capture-to-overlay delay above this (seconds) means the frame's stamp is on another clock.
MAX_PLAUSIBLE_LATENCY = 10.0


class BadFrame(ValueError):
    """A frame that is not an image (bad JPEG, wrong size, ...)."""


@dataclass
class Timings:
    decode: float = 0.0
    detect: float = 0.0
    pose: float = 0.0
    project: float = 0.0
    draw: float = 0.0
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def total(self) -> float:
        return self.decode + self.detect + self.pose + self.project + self.draw


class Pipeline:
    """Localise the tablet in each frame and overlay the world on it."""

    def __init__(
        self,
        site,  # protocol.site.Site
        world: WorldView | None = None,
        *,
        camera_id: str = "tablet",
        detector: TagDetector | None = None,
        localizer: Localizer | None = None,
        panel: FeedbackPanel | None = None,
        clock: Callable[[], float] | None = None,
        guided: bool = True,
        pose_filter: PoseFilter | None | bool = True,
    ) -> None:
        self.site = site
        self.world = world if world is not None else WorldView()
        self.camera_id = camera_id
        self.detector = detector or TagDetector("opencv", known_ids=[lm.tag for lm in site.landmarks])
        self.localizer = localizer or Localizer(site)
        self.builder = OverlayBuilder(site)
        self.panel = panel
        self.clock = clock
        self.guided = guided
        self.timings = Timings()
        self.last_localization: Localization | None = None
        self.last_world: WorldSnapshot | None = None  # what the last frame's overlay was drawn from
        self.last_detections: list[TagDetection] = []
        # The pose drawn goes through a gated constant-velocity filter (posefilter.py); False: raw poses.
        self.pose_filter = PoseFilter() if pose_filter is True else (pose_filter or None)
        self.last_filtered: FilteredPose | None = None
        # Landmark geometry as arrays, for predicting which tags a pose should see.
        lms = site.landmarks
        normals = np.array([lm.normal for lm in lms], dtype=np.float64).reshape(-1, 3)
        centres = np.array([lm.position for lm in lms], dtype=np.float64).reshape(-1, 3)
        self._lm = {
            "tags": np.array([lm.tag for lm in lms], dtype=np.int64),
            "centres": centres,
            "normals": normals,
            "sight": (centres + 0.05 * normals)[:, :2],  # just in front of the tag: its own wall must not hide it
            "printed": np.array([lm.corners(printed=True) for lm in lms], dtype=np.float64).reshape(-1, 4, 3),
            "black": np.array([lm.corners() for lm in lms], dtype=np.float64).reshape(-1, 4, 3),
        }

    # ------------------------------------------------------------------ stages

    @staticmethod
    def decode(frame: bytes | np.ndarray, colour: bool = True) -> np.ndarray:
        """A BGR (or, with ``colour=False``, gray) image from JPEG/PNG bytes, or an array as it is;
        :class:`BadFrame` otherwise. Decoding straight to gray halves the cost when nothing is drawn."""
        if isinstance(frame, np.ndarray):
            if frame.dtype != np.uint8 or frame.ndim not in (2, 3) or frame.size == 0:
                raise BadFrame(f"image array must be non-empty uint8 gray or BGR, got {frame.dtype} {frame.shape}")
            return frame
        if not isinstance(frame, (bytes, bytearray, memoryview)) or len(frame) == 0:
            raise BadFrame("empty frame")
        image = cv2.imdecode(np.frombuffer(frame, dtype=np.uint8), cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise BadFrame(f"frame of {len(frame)} bytes is not a decodable image")
        return image

    def localize(self, gray: np.ndarray, intrinsics: Intrinsics, stamp: float, gravity=None) -> Localization:  # noqa: ANN001
        """Detect and localise, with the guided second pass for tags predicted but not found.

        ``gravity``: the frame's measured gravity in the camera frame (pointing down), or None.

        Adds the time spent to ``timings.detect`` (both detection passes) and ``timings.pose``.
        """
        t0 = time.perf_counter()
        lens = Lens(intrinsics.K, intrinsics.dist) if intrinsics.has_distortion else None
        dets = self.detector.detect(gray, lens)
        t1 = time.perf_counter()
        loc = self.localizer.localize(dets, intrinsics, stamp, gravity)
        detect, pose = t1 - t0, time.perf_counter() - t1
        guide = loc.pose if loc.ok else self.localizer.prior(stamp)
        if self.guided and guide is not None:
            t2 = time.perf_counter()
            regions = self._missing(guide, intrinsics, {d.tag_id for d in dets})
            t3 = time.perf_counter()
            extra = self.detector.detect_regions(gray, regions, lens) if regions else []
            t4 = time.perf_counter()
            if extra:
                dets = sorted(dets + extra, key=lambda d: d.tag_id)
                loc = self.localizer.localize(dets, intrinsics, stamp, gravity)
            detect += t4 - t3
            pose += (t3 - t2) + (time.perf_counter() - t4)
        self.timings.detect += detect
        self.timings.pose += pose
        self.last_detections = dets
        self.last_localization = loc
        return loc

    def _missing(self, pose: CameraPose, intrinsics: Intrinsics, found: set[int]) -> list[tuple[int, np.ndarray]]:
        """Landmarks that should be visible from ``pose`` but were not detected: (tag, predicted corners)."""
        lm = self._lm
        cam = pose.position
        view = cam - lm["centres"]
        dist = np.linalg.norm(view, axis=1)
        facing = np.einsum("ij,ij->i", view, lm["normals"]) > np.cos(MAX_GUIDED_OBLIQUITY) * dist
        wanted = facing & ~np.isin(lm["tags"], list(found))
        if not wanted.any():
            return []
        idx = np.flatnonzero(wanted)
        projector = Projector(pose, intrinsics)
        uv, front = projector.project_points(lm["printed"][idx].reshape(-1, 3))
        uv, front = uv.reshape(-1, 4, 2), front.reshape(-1, 4).all(axis=1)
        w, h = intrinsics.width, intrinsics.height
        with np.errstate(invalid="ignore"):
            inside = (
                front
                & (uv[..., 0].min(axis=1) >= 2)
                & (uv[..., 1].min(axis=1) >= 2)
                & (uv[..., 0].max(axis=1) <= w - 3)
                & (uv[..., 1].max(axis=1) <= h - 3)
            )
            size = np.linalg.norm(np.roll(uv, -1, axis=1) - uv, axis=2).max(axis=1)
        keep = inside & (size >= MIN_GUIDED_PX)
        if not keep.any():
            return []
        idx, size = idx[keep], size[keep]
        occ = self.builder.occluders(self.world.open_doors())
        clear = ~occ.blocked_many(cam[:2], lm["sight"][idx], float(cam[2]))
        idx, size = idx[clear], size[clear]
        order = np.argsort(-size)[:MAX_GUIDED_CROPS]
        out = []
        for i in idx[order]:
            black, _ = projector.project_points(lm["black"][i])
            out.append((int(lm["tags"][i]), black))
        return out

    def _drawn_pose(self, loc: Localization, stamp: float, gravity) -> CameraPose | None:  # noqa: ANN001
        """The pose the overlay is drawn from: the filter's (None when lost: nothing is drawn)."""
        self.last_filtered = None
        if not loc.ok or loc.pose is None:
            return None
        if self.pose_filter is None:
            return loc.pose
        self.last_filtered = self.pose_filter.update(loc.pose, stamp, GravityPrior.from_vector(gravity))
        return self.last_filtered.pose

    def reset(self) -> None:
        """Forget tracking and filtering state (the next frame is unrelated to the last). The detector's
        ``close_view`` stays: it only decides which of its passes runs first, each reading true tags."""
        self.localizer.reset()
        if self.pose_filter is not None:
            self.pose_filter.reset()

    # ------------------------------------------------------------------ the whole frame

    def process(
        self,
        frame: bytes | np.ndarray,
        intrinsics: Intrinsics,
        timestamp: float,
        *,
        frame_seq: int = 0,
        annotate: bool = True,
        now: float | None = None,
        gravity=None,  # noqa: ANN001
    ) -> tuple[Overlay, np.ndarray | None]:
        """The Overlay for a frame captured at ``timestamp`` (site clock), and the annotated image.

        ``now`` is the site-clock time the world is drawn at (intent time marks); default
        ``timestamp``. Latency in the Overlay is the clock's now minus ``timestamp`` when the
        pipeline has a clock and that difference is plausible (between this call's processing time
        and :data:`MAX_PLAUSIBLE_LATENCY`), else this call's processing time. ``gravity``: the
        frame's measured gravity (camera frame, pointing down; ``CameraFrame.gravity``), or None.
        """
        started = time.perf_counter()
        image = self.decode(frame, colour=annotate)
        if intrinsics.width != image.shape[1] or intrinsics.height != image.shape[0]:
            raise BadFrame(
                f"frame is {image.shape[1]}x{image.shape[0]} but its intrinsics say "
                f"{intrinsics.width}x{intrinsics.height}"
            )
        gray = to_gray(image)
        t_decoded = time.perf_counter()
        self.timings = Timings(decode=t_decoded - started)
        loc = self.localize(gray, intrinsics, timestamp, gravity)

        t_proj = time.perf_counter()
        world = self.world.snapshot(timestamp if now is None else now, at=timestamp)
        self.last_world = world
        prims = []
        drawn = self._drawn_pose(loc, timestamp, gravity)
        if drawn is not None:
            prims = self.builder.world_primitives(Projector(drawn, intrinsics), world)
        processing = time.perf_counter() - started
        latency = processing
        if self.clock is not None:
            since_capture = self.clock() - timestamp
            # Only trust the difference when both ends plausibly share a clock (a frame stamped by
            # a sender on another clock, or not stamped at all, gives nonsense).
            if processing <= since_capture <= MAX_PLAUSIBLE_LATENCY:
                latency = since_capture
        prims += status_primitives(loc, latency, intrinsics.width, intrinsics.height)
        if self.panel is not None:
            prims += self.panel.primitives(intrinsics.width, intrinsics.height)
        t_drawn = t_proj2 = time.perf_counter()
        self.timings.project = t_proj2 - t_proj

        annotated = None
        if annotate:
            annotated = draw(image, prims)
            t_drawn = time.perf_counter()
        self.timings.draw = t_drawn - t_proj2

        overlay = Overlay(
            camera=self.camera_id,
            frame_seq=frame_seq,
            width=intrinsics.width,
            height=intrinsics.height,
            ok=loc.ok,
            position=[float(v) for v in drawn.position] if drawn is not None else [],
            quaternion=[float(v) for v in drawn.quaternion()] if drawn is not None else [],
            tags=list(loc.tags),
            reprojection_rmse=float(loc.rmse_px) if loc.ok else 0.0,
            lost_age=float(loc.lost_age or 0.0) if not loc.ok else 0.0,
            latency=float(latency),
            primitives=prims,
        )
        return overlay, annotated
