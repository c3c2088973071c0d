"""ARROCH messages as Foxglove messages (``foxglove.messages``): frame transforms, paths, the tablet
camera's image and calibration, the AR overlay as image annotations, and log lines.

Pure functions: the recorder decides what to log when; these only translate.
"""

from __future__ import annotations

from typing import Any

from foxglove.messages import (
    CameraCalibration,
    CircleAnnotation,
    Color,
    CompressedImage,
    FrameTransform,
    FrameTransforms,
    ImageAnnotations,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Point2,
    Point3,
    PointsAnnotation,
    PointsAnnotationType,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    TextAnnotation,
    Vector3,
)

from protocol.events import data_to_wire
from protocol.messages import (
    CameraFrame,
    CameraTruth,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Overlay,
    Primitive,
    RobotPose,
)

from .scene import rgba, stamp_of, yaw_quaternion
from .topics import MAP_FRAME, camera_frame, robot_frame

PATH_Z = 0.05  # metres above the floor, so paths are not hidden in it
PATH_THICKNESS = 0.06
XRAY_ALPHA = 0.5  # as the AR client's rasteriser draws x-ray primitives (services/ar_client/draw.py)


def robot_transform(pose: RobotPose, at: int) -> FrameTransforms:
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=stamp_of(at),
                parent_frame_id=MAP_FRAME,
                child_frame_id=robot_frame(pose.robot),
                translation=Vector3(x=pose.x, y=pose.y, z=0.0),
                rotation=yaw_quaternion(pose.theta),
            )
        ]
    )


def camera_transform(truth: CameraTruth, at: int) -> FrameTransforms:
    """Map → camera, the camera in OpenCV axes (x right, y down, z forward), as Foxglove expects."""
    qx, qy, qz, qw = truth.quaternion
    px, py, pz = truth.position
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=stamp_of(at),
                parent_frame_id=MAP_FRAME,
                child_frame_id=camera_frame(truth.camera),
                translation=Vector3(x=px, y=py, z=pz),
                rotation=Quaternion(x=qx, y=qy, z=qz, w=qw),
            )
        ]
    )


def intent_path(intent: Intent, color: tuple[int, int, int], at: int) -> SceneUpdate:
    """The robot's motion plan as a polyline in its colour (an empty trajectory deletes the path)."""
    entity_id = f"intent/{intent.robot}"
    ts = stamp_of(at)
    if len(intent.trajectory) < 2:
        return SceneUpdate(
            deletions=[SceneEntityDeletion(timestamp=ts, type=SceneEntityDeletionType.MatchingId, id=entity_id)]
        )
    points = [Point3(x=row[1], y=row[2], z=PATH_Z) for row in intent.trajectory]
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineStrip,
        pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=yaw_quaternion(0.0)),
        thickness=PATH_THICKNESS,
        points=points,
        color=rgba(color, 0.9),
    )
    return SceneUpdate(entities=[SceneEntity(timestamp=ts, frame_id=MAP_FRAME, id=entity_id, lines=[line])])


def camera_image(frame: CameraFrame, at: int) -> CompressedImage:
    return CompressedImage(timestamp=stamp_of(at), frame_id=camera_frame(frame.camera), data=frame.jpeg, format="jpeg")


def camera_calibration(frame: CameraFrame, at: int) -> CameraCalibration:
    fx, fy, cx, cy = frame.intrinsics
    return CameraCalibration(
        timestamp=stamp_of(at),
        frame_id=camera_frame(frame.camera),
        width=frame.width,
        height=frame.height,
        distortion_model="plumb_bob",
        D=list(frame.distortion),
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def _color(p: Primitive) -> Color:
    r, g, b = p.color[:3]
    a = (p.color[3] if len(p.color) > 3 else 255) / 255.0
    return Color(r=r / 255.0, g=g / 255.0, b=b / 255.0, a=a * XRAY_ALPHA if p.style == "xray" else a)


def overlay_annotations(overlay: Overlay, frame_at: int) -> ImageAnnotations:
    """The overlay's primitives as annotations of the frame they were drawn for (its log time)."""
    ts = stamp_of(frame_at)
    points: list[PointsAnnotation] = []
    circles: list[CircleAnnotation] = []
    texts: list[TextAnnotation] = []
    for p in overlay.primitives:
        color = _color(p)
        pts = [Point2(x=u, y=v) for u, v in p.points]
        if p.kind == "circle" and pts:
            fill = color if p.width == 0 else Color(r=0.0, g=0.0, b=0.0, a=0.0)
            circles.append(
                CircleAnnotation(
                    timestamp=ts,
                    position=pts[0],
                    diameter=2 * p.radius,
                    thickness=p.width,
                    fill_color=fill,
                    outline_color=color,
                )
            )
        elif p.kind == "text" and pts:
            texts.append(
                TextAnnotation(
                    timestamp=ts,
                    position=pts[0],
                    text=p.text,
                    font_size=p.radius or 12.0,
                    text_color=color,
                    background_color=Color(r=0.0, g=0.0, b=0.0, a=0.0),
                )
            )
        elif len(pts) >= 2:
            kind = PointsAnnotationType.LineLoop if p.kind == "polygon" else PointsAnnotationType.LineStrip
            fill = color if p.kind == "polygon" else Color(r=0.0, g=0.0, b=0.0, a=0.0)
            points.append(
                PointsAnnotation(
                    timestamp=ts, type=kind, points=pts, outline_color=color, fill_color=fill, thickness=p.width
                )
            )
    return ImageAnnotations(circles=circles, points=points, texts=texts)


def _short(value: Any, limit: int = 300) -> str:
    text = str(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


WARNING_EVENTS = ("action_failed", "plan_conflict", "closed_door_crossing", "robot_overlap")


def describe(msg: Feedback | FeedbackAck | Event) -> tuple[str, str]:
    """(log level name, one line) for a feedback, an ack or an event."""
    if isinstance(msg, Feedback):
        params = ", ".join(f"{k}={v}" for k, v in msg.params.items())
        return "INFO", f"feedback {msg.kind}({params})"
    if isinstance(msg, FeedbackAck):
        what = f"accepted as {msg.constraint_id}" if msg.accepted else f"refused: {msg.reason}"
        return (
            "INFO" if msg.accepted else "WARNING"
        ), f"feedback {msg.feedback_seq} of {msg.to} {what} (constraints v{msg.constraints_version})"
    who = " ".join(f"{k}={v}" for k, v in (("robot", msg.robot), ("door", msg.door), ("object", msg.object)) if v)
    wire = data_to_wire(msg.data)
    data = "" if msg.kind == "mission_done" or not wire else f" {_short(wire)}"
    return ("WARNING" if msg.kind in WARNING_EVENTS else "INFO"), f"{msg.kind} {who}{data}".strip()


LEVELS = {
    "DEBUG": LogLevel.Debug,
    "INFO": LogLevel.Info,
    "WARNING": LogLevel.Warning,
    "ERROR": LogLevel.Error,
    "CRITICAL": LogLevel.Fatal,
}


def text_log(at: int, level: str, name: str, message: str, file: str = "", line: int = 0) -> Log:
    """A log line; ``file`` and ``line`` say where it was read (a followed log file), if it was."""
    return Log(
        timestamp=stamp_of(at),
        level=LEVELS.get(level, LogLevel.Unknown),
        name=name,
        message=message,
        file=file,
        line=line,
    )
