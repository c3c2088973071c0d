"""The default recording profile: every ARROCH message (as JSON, and its wire bytes), plus the
Foxglove view of the run.

:class:`FoxgloveProfile` writes each message heard three ways, none twice: its bytes as they travelled
in the wire store (:mod:`.wire`, for ``arroch replay``; the file only), the message as JSON on
``/arroch/<key>`` (with its type's JSON Schema, :mod:`.jsonschema`), and what a Foxglove user wants
to see of it (:mod:`.topics`: frames, the scene, paths, the camera with its overlay, the log).
Everything is logged at its log time (:mod:`.timebase`: the run's start on the wall clock plus the
message's site time), so a lockstep run replays at its site pace however fast it ran. Not
thread-safe: the recorder calls it under one lock.
"""

from __future__ import annotations

from typing import Any

import msgspec
from foxglove.messages import FrameTransforms, Log, SceneUpdate

from protocol.codec import encode
from protocol.keys import Keys
from protocol.messages import (
    CameraFrame,
    CameraTruth,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Message,
    Overlay,
    RobotPose,
    RobotStatus,
)
from protocol.site import Site
from runtime.palette import unlisted_robot_color

from . import convert, topics
from .images import scale_frame, scale_overlay
from .jsonschema import record_schema
from .logtail import LogLine
from .scene import SiteScene, to_foxglove
from .sink import FoxgloveSink
from .timebase import CLOCK_METADATA, Timebase
from .wire import MEDIA_TYPE, WireRecord, WireWriter, without_jpeg

METADATA = "arroch"  # MCAP metadata record: namespace, site, profile, clock, when
PROGRESS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "Progress",
    "properties": {
        "delivered": {"type": "integer", "description": "objects delivered so far, all robots"},
        "delivered_by": {"type": "object", "additionalProperties": {"type": "integer"}},
        "door_openings": {"type": "integer", "description": "door openings so far, by anyone"},
        "human_door_openings": {"type": "integer", "description": "door openings by the human"},
        "open_doors": {"type": "integer"},
    },
}
MAX_FRAME_STAMPS = 256  # camera frames remembered for their overlays' timestamps
_to_json = msgspec.json.Encoder().encode


class FoxgloveProfile:
    def __init__(
        self,
        sink: FoxgloveSink,
        keys: Keys,
        site: Site,
        timebase: Timebase,
        *,
        image_scale: float = 1.0,
        metadata: dict[str, str] | None = None,
        site_clock: str = "sim",
    ) -> None:
        if not 0.0 < image_scale <= 1.0:
            raise ValueError(f"--image-scale must be in (0, 1], got {image_scale:g}")
        self.sink = sink
        self.image_scale = image_scale
        self.keys = keys
        self.time = timebase
        self.metadata = dict(metadata or {})
        self.site_clock = site_clock
        self.scene = SiteScene(site)
        self.wire: WireWriter | None = None
        self.poses: dict[str, RobotPose] = {}
        self.delivered: dict[str, int] = {}
        self.door_openings = 0
        self.human_door_openings = 0
        self.frame_stamps: dict[tuple[str, int], float] = {}
        self._handlers = {
            RobotPose: self._pose,
            RobotStatus: self._status,
            DoorState: self._door,
            Intent: self._intent,
            Feedback: self._described,
            FeedbackAck: self._described,
            CameraFrame: self._frame,
            CameraTruth: self._truth,
            Overlay: self._overlay,
            Event: self._event,
        }

    def start(self, at: int) -> None:
        self.sink.open_file()
        if self.sink.writing:
            self.sink.write_metadata(METADATA, self.metadata)
            self.wire = WireWriter(self._attach)
        # The fixed channels exist from the start, so a viewer can subscribe before the mission's burst.
        for topic, message_type in ((topics.TF, FrameTransforms), (topics.PATHS, SceneUpdate), (topics.LOG, Log)):
            self.sink.declare(topic, message_type)
        self.sink.declare_json(topics.PROGRESS, PROGRESS_SCHEMA)
        for key, message_type in topics.expected_keys(self.keys, self.scene.site):
            self.sink.declare_json(topics.message_topic(topics.below(self.keys, key)), record_schema(message_type))
        self._scene(at)

    def _attach(self, name: str, first: int, last: int, data: bytes) -> None:
        self.sink.attach(name, first, last, data, MEDIA_TYPE)

    def origin_fixed(self) -> None:
        """The timebase has its origin now: the file keeps it (readers turn log times back into site time)."""
        self.sink.write_metadata(CLOCK_METADATA, self.time.metadata(self.site_clock))

    def _scene(self, at: int) -> None:
        self.sink.message(topics.SCENE, to_foxglove(self.scene.entities(), at), at)

    def resend(self, topic: str, at: int) -> None:
        """A viewer subscribed to ``topic``: the scene, sent whole only at the start, goes out again as it is now."""
        if topic == topics.SCENE:
            self._scene(at)

    def tick(self) -> None:
        if self.wire is not None:
            self.wire.flush_if_old()

    def handle(self, msg: Message, key: str, payload: bytes) -> None:
        if self.image_scale < 1.0:  # frames kept smaller, everything drawn on them alike
            if isinstance(msg, CameraFrame):
                msg = scale_frame(msg, self.image_scale)
                payload = encode(msg)
            elif isinstance(msg, Overlay):
                msg = scale_overlay(msg, self.image_scale)
                payload = encode(msg)
        rest = topics.below(self.keys, key)
        at = self.time.at(msg.stamp)
        # A camera frame's JPEG is kept once, in its CompressedImage (the wire store and JSON without it).
        stored = msgspec.structs.replace(msg, jpeg=b"") if isinstance(msg, CameraFrame) else msg
        if self.wire is not None:
            kept, cut = without_jpeg(payload, msg.jpeg) if isinstance(msg, CameraFrame) else (payload, -1)
            self.wire.add(WireRecord(rest, at, kept, cut))
        self.sink.json(topics.message_topic(rest), record_schema(type(msg)), _to_json(stored), at)
        handler = self._handlers.get(type(msg))
        if handler is not None:
            handler(msg, at)

    def log_line(self, line: LogLine, at: int, file: str = "") -> None:
        self.sink.message(topics.LOG, convert.text_log(at, line.level, line.name, line.text, file, line.number), at)

    # ------------------------------------------------------------------ per message type

    def _pose(self, msg: RobotPose, at: int) -> None:
        self.poses[msg.robot] = msg
        self.sink.message(topics.TF, convert.robot_transform(msg, at), at)

    def _status(self, msg: RobotStatus, at: int) -> None:
        if self.delivered.get(msg.robot) != len(msg.delivered):
            self.delivered[msg.robot] = len(msg.delivered)
            self._progress(at)

    def _door(self, msg: DoorState, at: int) -> None:
        changed = self.scene.door_changed(msg.door, msg.open)
        if changed is None:
            return
        self.sink.message(topics.SCENE, to_foxglove([changed], at), at)
        if msg.open:
            self.door_openings += 1
            self.human_door_openings += msg.by == "human"
        self._progress(at)

    def _progress(self, at: int) -> None:
        self.sink.json(
            topics.PROGRESS,
            PROGRESS_SCHEMA,
            {
                "delivered": sum(self.delivered.values()),
                "delivered_by": dict(sorted(self.delivered.items())),
                "door_openings": self.door_openings,
                "human_door_openings": self.human_door_openings,
                "open_doors": sum(1 for state in self.scene.doors.values() if state),
            },
            at,
        )

    def _intent(self, msg: Intent, at: int) -> None:
        color = self.scene.colors.get(msg.robot) or unlisted_robot_color(msg.robot)
        self.sink.message(topics.PATHS, convert.intent_path(msg, color, at), at)

    def _described(self, msg: Feedback | FeedbackAck | Event, at: int) -> None:
        level, text = convert.describe(msg)
        self.sink.message(topics.LOG, convert.text_log(at, level, msg.src, text), at)

    def _frame(self, msg: CameraFrame, at: int) -> None:
        self.frame_stamps[(msg.camera, msg.seq)] = msg.stamp
        if len(self.frame_stamps) > MAX_FRAME_STAMPS:
            del self.frame_stamps[next(iter(self.frame_stamps))]
        self.sink.message(topics.camera_image(msg.camera), convert.camera_image(msg, at), at)
        self.sink.message(topics.camera_calibration(msg.camera), convert.camera_calibration(msg, at), at)

    def _truth(self, msg: CameraTruth, at: int) -> None:
        self.sink.message(topics.TF, convert.camera_transform(msg, at), at)

    def _overlay(self, msg: Overlay, at: int) -> None:
        # Drawn for a frame: shown with that frame (its timestamp), logged when it was made.
        frame_stamp = self.frame_stamps.get((msg.camera, msg.frame_seq), msg.stamp)
        annotations = convert.overlay_annotations(msg, self.time.at(frame_stamp))
        self.sink.message(topics.camera_overlay(msg.camera), annotations, at)

    def _event(self, msg: Event, at: int) -> None:
        self._described(msg, at)
        update = None
        if msg.kind == "loaded" and msg.object and msg.robot:
            update = self.scene.object_loaded(msg.object, msg.robot)
        elif msg.kind == "delivered" and msg.object:
            pose = self.poses.get(msg.robot)
            update = self.scene.object_delivered(msg.object, (pose.x, pose.y)) if pose else None
        if update is not None:
            self.sink.message(topics.SCENE, to_foxglove([update], at), at)

    def close(self) -> None:
        if self.wire is not None:
            self.wire.flush()
        self.sink.close()

    def abort(self) -> None:
        self.sink.abort()
