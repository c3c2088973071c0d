"""The default recording profile: every ARROCH message as it travelled, plus the Foxglove view of it.

:class:`FoxgloveProfile` turns each message heard into what a Foxglove user wants to see (see
:mod:`.topics`), on the site clock: a message is logged at its own ``stamp``, so a lockstep run
replays faithfully however fast it ran. Not thread-safe: the recorder calls it under one lock.
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
    ConstraintSet,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Message,
    Overlay,
    RobotPose,
    RobotStatus,
    TeamPlan,
)
from protocol.palette import unlisted_robot_color
from protocol.schema import record_to_wire
from protocol.site import Site

from . import convert, topics
from .images import scale_frame, scale_overlay
from .jsonschema import record_schema
from .scene import SiteScene, to_foxglove
from .sink import FoxgloveSink

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
METRICS_SCHEMA: dict[str, Any] = {"type": "object", "title": "Metrics", "description": "the mission_done Event's data"}
MAX_FRAME_STAMPS = 256  # camera frames remembered for their overlays' timestamps


class FoxgloveProfile:
    def __init__(self, sink: FoxgloveSink, keys: Keys, site: Site, *, image_scale: float = 1.0) -> None:
        if not 0.0 < image_scale <= 1.0:
            raise ValueError(f"--image-scale must be in (0, 1], got {image_scale:g}")
        self.sink = sink
        self.image_scale = image_scale
        self.keys = keys
        self.scene = SiteScene(site)
        self.poses: dict[str, RobotPose] = {}
        self.delivered: dict[str, int] = {}
        self.door_openings = 0
        self.human_door_openings = 0
        self.frame_stamps: dict[tuple[str, int], float] = {}
        self._handlers = {
            RobotPose: self._pose,
            RobotStatus: self._status,
            DoorState: self._door,
            TeamPlan: self._json(topics.PLAN),
            Intent: self._intent,
            Feedback: self._described,
            FeedbackAck: self._described,
            ConstraintSet: self._json(topics.CONSTRAINTS),
            CameraFrame: self._frame,
            CameraTruth: self._truth,
            Overlay: self._overlay,
            Event: self._event,
        }

    def start(self, t: float) -> None:
        # The fixed channels exist from the start, so a viewer can subscribe before the mission's burst.
        for topic, message_type in ((topics.TF, FrameTransforms), (topics.PATHS, SceneUpdate), (topics.LOG, Log)):
            self.sink.declare(topic, message_type)
        for topic, schema in (
            (topics.PLAN, record_schema(TeamPlan)),
            (topics.CONSTRAINTS, record_schema(ConstraintSet)),
            (topics.EVENTS, record_schema(Event)),
            (topics.PROGRESS, PROGRESS_SCHEMA),
            (topics.METRICS, METRICS_SCHEMA),
        ):
            self.sink.declare_json(topic, schema)
        self._scene(t)

    def _scene(self, t: float) -> None:
        self.sink.message(topics.SCENE, to_foxglove(self.scene.entities(), t), t)

    def resend(self, topic: str, t: float) -> None:
        """A viewer subscribed to ``topic``: the scene, sent whole only at the start, goes out again as it is now."""
        if topic == topics.SCENE:
            self._scene(t)

    def handle(self, msg: Message, key: str) -> None:
        if self.image_scale < 1.0:  # frames kept smaller, everything drawn on them alike
            if isinstance(msg, CameraFrame):
                msg = scale_frame(msg, self.image_scale)
            elif isinstance(msg, Overlay):
                msg = scale_overlay(msg, self.image_scale)
        self._raw(msg, key)
        handler = self._handlers.get(type(msg))
        if handler is not None:
            handler(msg)

    def log_line(self, t: float, level: str, name: str, text: str) -> None:
        self.sink.message(topics.LOG, convert.text_log(t, level, name, text), t)

    # ------------------------------------------------------------------ per message type

    def _raw(self, msg: Message, key: str) -> None:
        # A camera frame's JPEG is kept once, in its CompressedImage; replay puts it back.
        stored = msgspec.structs.replace(msg, jpeg=b"") if isinstance(msg, CameraFrame) else msg
        self.sink.raw(topics.raw_topic(self.keys, key), msg.TYPE, record_schema(type(msg)), encode(stored), msg.stamp)

    def _json(self, topic: str):
        def log(msg: Message) -> None:
            self.sink.json(topic, record_schema(type(msg)), record_to_wire(msg), msg.stamp)

        return log

    def _pose(self, msg: RobotPose) -> None:
        self.poses[msg.robot] = msg
        self.sink.message(topics.TF, convert.robot_transform(msg), msg.stamp)

    def _status(self, msg: RobotStatus) -> None:
        if self.delivered.get(msg.robot) != len(msg.delivered):
            self.delivered[msg.robot] = len(msg.delivered)
            self._progress(msg.stamp)

    def _door(self, msg: DoorState) -> None:
        changed = self.scene.door_changed(msg.door, msg.open)
        if changed is None:
            return
        self.sink.message(topics.SCENE, to_foxglove([changed], msg.stamp), msg.stamp)
        if msg.open:
            self.door_openings += 1
            self.human_door_openings += msg.by == "human"
        self._progress(msg.stamp)

    def _progress(self, t: float) -> None:
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
            t,
        )

    def _intent(self, msg: Intent) -> None:
        color = self.scene.colors.get(msg.robot) or unlisted_robot_color(msg.robot)
        self.sink.message(topics.PATHS, convert.intent_path(msg, color), msg.stamp)

    def _described(self, msg: Feedback | FeedbackAck | Event) -> None:
        level, text = convert.describe(msg)
        self.log_line(msg.stamp, level, msg.src, text)

    def _frame(self, msg: CameraFrame) -> None:
        self.frame_stamps[(msg.camera, msg.seq)] = msg.stamp
        if len(self.frame_stamps) > MAX_FRAME_STAMPS:
            del self.frame_stamps[next(iter(self.frame_stamps))]
        self.sink.message(topics.camera_image(msg.camera), convert.camera_image(msg), msg.stamp)
        self.sink.message(topics.camera_calibration(msg.camera), convert.camera_calibration(msg), msg.stamp)

    def _truth(self, msg: CameraTruth) -> None:
        self.sink.message(topics.TF, convert.camera_transform(msg), msg.stamp)

    def _overlay(self, msg: Overlay) -> None:
        # Drawn for a frame: shown with that frame (its timestamp), logged when it was made.
        frame_stamp = self.frame_stamps.get((msg.camera, msg.frame_seq), msg.stamp)
        self.sink.message(topics.camera_overlay(msg.camera), convert.overlay_annotations(msg, frame_stamp), msg.stamp)

    def _event(self, msg: Event) -> None:
        self.sink.json(topics.EVENTS, record_schema(Event), record_to_wire(msg), msg.stamp)
        self._described(msg)
        update = None
        if msg.kind == "loaded" and msg.object and msg.robot:
            update = self.scene.object_loaded(msg.object, msg.robot)
        elif msg.kind == "delivered" and msg.object:
            pose = self.poses.get(msg.robot)
            update = self.scene.object_delivered(msg.object, (pose.x, pose.y)) if pose else None
        elif msg.kind == "mission_done" and isinstance(msg.data, dict):
            self.sink.json(topics.METRICS, METRICS_SCHEMA, msg.data, msg.stamp)
        if update is not None:
            self.sink.message(topics.SCENE, to_foxglove([update], msg.stamp), msg.stamp)

    def close(self) -> None:
        self.sink.close()
