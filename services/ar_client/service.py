"""The AR client process: frames in, Overlays out on ``ar/<cid>/overlay``.

I/O (keys under ``arroch/<namespace>/``):

- subscribes to ``robot/*/pose`` (latest), ``robot/*/status``, ``intent/*``, ``door/*/state`` into a
  :class:`WorldView`, and to ``constraints`` for the feedback panel's "cancel" choices; queries
  the restrictor's ``constraints/library`` (every second until one answers) for the panel's buttons;
- with ``--source sim``, subscribes to ``camera/<cid>/frame`` (latest only: a slow frame never queues
  up stale ones); other sources are read on the worker at their frame rate;
- publishes one ``Overlay`` per processed frame on ``ar/<cid>/overlay`` (when lost, with an extra
  ``reason`` field; always with ``pose_stamps``, the stamp of each robot's RobotPose it was drawn
  from, so a viewer or a benchmark can tell how old the positions shown are); optionally records
  the annotated frames to an MP4 file, and keeps a few of them as pictures (:mod:`.snapshots`);
- feedback presses (from :attr:`ArService.panel`) go to the restrictor over Zenoh on their own thread.

A frame that cannot be decoded, or whose intrinsics are unusable, is counted (``bad_frames``),
logged at most once a minute, and dropped; the service keeps running.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import cv2
import numpy as np

from protocol.messages import CameraFrame, ConstraintSet, Overlay
from runtime.clock import SimClock, WallClock
from runtime.feedback_client import newest_constraints, wait_for_library
from runtime.service import Service
from runtime.transport import ZenohOptions

from .detect import TagDetector
from .feedback import FeedbackPanel, restrictor_sender
from .pipeline import BadFrame, Pipeline
from .project import Intrinsics
from .snapshots import OverlaySnapshots
from .sources import SourceSpec, open_source
from .world import WorldView

BAD_FRAME_LOG_INTERVAL = 60.0
DEFAULT_RECORD_FPS = 10.0
LIBRARY_RETRY = 1.0  # wall seconds between queries for the restrictor's library until one answers
MAX_STAMP_SKEW = 10.0  # seconds between a frame's stamp and our clock beyond which the stamp is ignored


class ArService(Service):
    def __init__(
        self,
        *,
        site,  # protocol.site.Site
        namespace: str,
        zenoh_options: ZenohOptions,
        source: SourceSpec,
        camera: str = "tablet",
        intrinsics: Intrinsics | None = None,
        record: str | None = None,
        detector: str = "opencv",
        feedback: bool = True,
        snapshots: OverlaySnapshots | None = None,
        clock: WallClock | SimClock | None = None,
        instance: str | None = None,
    ) -> None:
        super().__init__("ar", namespace, zenoh_options, clock=clock, instance=instance)
        self.keys.overlay(camera)  # a camera id unusable in a key fails here, before any session
        self.site = site
        self.camera = camera
        self.source_spec = source
        # Opening a pull source first reports a missing file or calibration before any Zenoh session.
        self.source = None if source.kind == "sim" else open_source(source, intrinsics, self.clock.now)
        self.world = WorldView()
        self.panel = FeedbackPanel() if feedback else None  # its entries: what the restrictor serves
        self.pipeline = Pipeline(
            site,
            self.world,
            camera_id=camera,
            detector=TagDetector(detector, known_ids=[lm.tag for lm in site.landmarks]),
            panel=self.panel,
            clock=self.clock.now,
            # A folder of stills is not a stream: each image's own pose is drawn, unfiltered.
            pose_filter=source.kind != "images",
        )
        self.record_path = record
        self.snapshots = snapshots
        self._writer: cv2.VideoWriter | None = None
        self._writer_size: tuple[int, int] | None = None
        self._last_bad_frame_log = (
            -BAD_FRAME_LOG_INTERVAL
        )  # not _last_bad_log: the Service base keeps its per-sender table there

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        k = self.keys
        self.world.follow(self)
        if self.panel is not None:
            self.panel.sender = restrictor_sender(self)
            self.subscribe(k.constraints(), ConstraintSet, self.panel.on_constraints)
            # The library, then the live set (a late joiner's), off the worker, since queries block.
            threading.Thread(target=self._fetch_panel, name="ar-library", daemon=True).start()
        if self.source is None:
            self.subscribe(k.camera_frame(self.camera), CameraFrame, self._on_frame, latest=True)
            self.log.info("waiting for frames on %s", k.camera_frame(self.camera))
        else:
            period = 1.0 / self.source.fps if self.source.fps > 0 else 0.001
            self.every(period, self._pull, first=0.0)
            self.log.info("reading frames from %s:%s", self.source_spec.kind, self.source_spec.target)

    def teardown(self) -> None:
        if self.source is not None:
            self.source.close()
        if self._writer is not None:
            self._writer.release()
            self.log.info("recorded %d frames to %s", self.counters.get("recorded", 0), self.record_path)
        if self.snapshots is not None:
            self.log.info("kept %d overlay frame(s) in %s", len(self.snapshots.kept), self.snapshots.directory)

    def _fetch_panel(self) -> None:
        library = wait_for_library(self, retry=LIBRARY_RETRY, what="feedback buttons on the overlay")
        if library is None or self.panel is None:
            return  # stopping
        self.panel.set_entries(library.entries)
        newest = newest_constraints(self)
        if newest is not None:
            self.panel.on_constraints(newest)

    # ------------------------------------------------------------------ frames

    def _on_frame(self, msg: CameraFrame, _key: str) -> None:
        if (
            len(msg.intrinsics) != 4
            or not all(np.isfinite(msg.intrinsics))
            or msg.intrinsics[0] <= 0
            or msg.intrinsics[1] <= 0
        ):
            self._bad_frame(f"frame {msg.src}/{msg.seq} has unusable intrinsics {msg.intrinsics}")
            return
        fx, fy, cx, cy = msg.intrinsics
        distortion = tuple(msg.distortion) if len(msg.distortion) == 5 else (0.0,) * 5
        K = Intrinsics(fx, fy, cx, cy, msg.width, msg.height, distortion)
        self._process(msg.jpeg, K, msg.stamp, msg.seq, msg.gravity or None)

    def _pull(self) -> None:
        assert self.source is not None
        frame = self.source.read()
        if frame is None:
            self.log.info(
                "source finished after %d frames", self.counters.get("frames", 0) + self.counters.get("bad_frames", 0)
            )
            self.stop()
            return
        self._process(frame.image, frame.intrinsics, frame.stamp, frame.seq)

    def _process(
        self, frame: bytes | np.ndarray, K: Intrinsics, stamp: float, seq: int, gravity: list[float] | None = None
    ) -> None:
        if not self.clock.synced:
            # No site clock yet (no sim clock messages): time frames on the wall clock, so tracking
            # and the "lost for N s" age still measure real intervals.
            stamp = now = time.time()
        else:
            now = self.clock.now()
            if not (0.0 < stamp and abs(now - stamp) <= MAX_STAMP_SKEW):
                # A frame stamped on another clock (or not at all): time it on ours instead.
                self.count("restamped_frames")
                stamp = now
        # Drawing costs time: only when recording, or when a kept frame may be due.
        annotate = self.record_path is not None or (self.snapshots is not None and self.snapshots.wanted(now))
        try:
            overlay, annotated = self.pipeline.process(
                frame, K, stamp, frame_seq=seq, annotate=annotate, now=now, gravity=gravity
            )
        except BadFrame as exc:
            self._bad_frame(str(exc))
            return
        self.count("frames")
        if not overlay.ok:
            self.count("lost")
        filtered = self.pipeline.last_filtered
        if filtered is not None and not filtered.accepted:
            self.count("poses_rejected")  # a jump against the motion or gravity: the prediction was drawn
        loc = self.pipeline.last_localization
        extra: dict[str, object] = {"reason": loc.reason} if loc is not None and not loc.ok else {}
        world = self.pipeline.last_world
        extra["pose_stamps"] = {rid: state.stamp for rid, state in world.robots.items()} if world is not None else {}
        self.publish(self.keys.overlay(self.camera), overlay, extra=extra)
        if annotated is not None and self.record_path is not None:
            self._record(annotated)
        if annotated is not None and self.snapshots is not None:
            self._keep(overlay, annotated, now)

    def _keep(self, overlay: Overlay, annotated: np.ndarray, now: float) -> None:
        try:
            path = self.snapshots.offer(overlay, annotated, now)
        except OSError as exc:
            self.log.error("%s; no more overlay frames are kept", exc)
            self.snapshots = None
            return
        if path is not None:
            self.count("snapshots")
            self.log.info("kept overlay frame %s", path)

    def _bad_frame(self, why: str) -> None:
        self.count("bad_frames")
        now = time.monotonic()
        if now - self._last_bad_frame_log >= BAD_FRAME_LOG_INTERVAL:
            self._last_bad_frame_log = now
            self.log.warning("dropped a bad frame: %s (further ones counted, logged once a minute)", why)

    def _record(self, image: np.ndarray) -> None:
        h, w = image.shape[:2]
        if self._writer is None:
            fps = self.source.fps if self.source is not None and self.source.fps > 0 else DEFAULT_RECORD_FPS
            Path(self.record_path).parent.mkdir(parents=True, exist_ok=True)
            self._writer = cv2.VideoWriter(str(self.record_path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
            if not self._writer.isOpened():
                self.log.error("cannot write %s; recording is off", self.record_path)
                self.record_path = None
                self._writer = None
                return
            self._writer_size = (w, h)
        if (w, h) != self._writer_size:
            self.count("record_size_mismatch")  # a video has one frame size
            return
        self._writer.write(image)
        self.count("recorded")
