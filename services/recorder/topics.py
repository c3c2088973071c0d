"""Which Zenoh keys a recorder hears, and the MCAP topics it writes.

Every ARROCH message is kept as it travels (msgpack) on ``/arroch/<key below the namespace>``: that is
what ``arroch replay`` publishes again. Beside these, the viewer channels (Foxglove schemas, JSON with
JSON Schemas) show the run in Foxglove; their topics are the constants below.
"""

from __future__ import annotations

from protocol.keys import Keys
from protocol.messages import (
    CameraFrame,
    CameraTruth,
    Clock,
    ConstraintSet,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Message,
    Overlay,
    RobotCommand,
    RobotPose,
    RobotStatus,
    TeamPlan,
)

RAW_PREFIX = "/arroch/"
RAW_ENCODING = "msgpack"
RAW_SCHEMA_PREFIX = "arroch."

# Viewer channels.
SCENE = "/site"  # foxglove.SceneUpdate: walls, doors (live state), rooms, tags, objects, robot bodies
TF = "/tf"  # foxglove.FrameTransforms: world -> robot/<rid>, world -> camera/<cid>
PATHS = "/paths"  # foxglove.SceneUpdate: each robot's intent (motion plan polyline), in its colour
PLAN = "/plan"  # JSON: TeamPlan
CONSTRAINTS = "/constraints"  # JSON: ConstraintSet
EVENTS = "/events"  # JSON: Event
PROGRESS = "/progress"  # JSON: deliveries and door openings so far (plot panel)
METRICS = "/metrics"  # JSON: the mission_done Event's metrics
LOG = "/log"  # foxglove.Log: feedback, acks, events, the services' log lines
WORLD_FRAME = "world"


def camera_image(camera: str) -> str:
    return f"/camera/{camera}/image"  # foxglove.CompressedImage


def camera_calibration(camera: str) -> str:
    return f"/camera/{camera}/calibration"  # foxglove.CameraCalibration


def camera_overlay(camera: str) -> str:
    return f"/camera/{camera}/overlay"  # foxglove.ImageAnnotations


def robot_frame(robot: str) -> str:
    return f"robot/{robot}"


def camera_frame(camera: str) -> str:
    return f"camera/{camera}"


def recorded_keys(keys: Keys) -> list[tuple[str, type[Message]]]:
    """Every key expression a recorder subscribes to, with its message type."""
    return [
        (keys.clock(), Clock),
        (keys.robot_pose(), RobotPose),
        (keys.robot_status(), RobotStatus),
        (keys.robot_command(), RobotCommand),
        (keys.door_state(), DoorState),
        (keys.plan(), TeamPlan),
        (keys.intent(), Intent),
        (keys.feedback(), Feedback),
        (keys.feedback_ack(), FeedbackAck),
        (keys.constraints(), ConstraintSet),
        (keys.camera_frame(), CameraFrame),
        (keys.camera_truth(), CameraTruth),
        (keys.overlay(), Overlay),
        (keys.event(), Event),
    ]


def raw_topic(keys: Keys, key: str) -> str:
    """``arroch/office/robot/r0/pose`` → ``/arroch/robot/r0/pose`` (the namespace is the file's metadata)."""
    prefix = keys.prefix + "/"
    if not key.startswith(prefix):
        raise ValueError(f"key {key!r} is not under {prefix!r}")
    return RAW_PREFIX + key[len(prefix) :]


def key_of(keys: Keys, topic: str) -> str:
    """The inverse of :func:`raw_topic` for a namespace (possibly another than the recorded one)."""
    if not topic.startswith(RAW_PREFIX):
        raise ValueError(f"topic {topic!r} is not a recorded ARROCH message")
    return f"{keys.prefix}/{topic[len(RAW_PREFIX) :]}"
