"""The ``ros2`` recording profile: the run as ROS 2 messages (CDR) in a rosbag2 folder with MCAP storage,
which ``ros2 bag play`` and RViz 2 take as they are.

| topic | type |
|---|---|
| ``/tf`` | ``tf2_msgs/msg/TFMessage``: world → ``robot/<rid>``, world → ``camera/<cid>`` |
| ``/robot/<rid>/pose`` | ``geometry_msgs/msg/PoseStamped`` |
| ``/robot/<rid>/path`` | ``nav_msgs/msg/Path``: the robot's intent (motion plan), stamped per point |
| ``/camera/<cid>/image/compressed`` | ``sensor_msgs/msg/CompressedImage`` |
| ``/camera/<cid>/camera_info`` | ``sensor_msgs/msg/CameraInfo`` |
| ``/site`` | ``visualization_msgs/msg/MarkerArray``: the scene of :mod:`.scene`, doors updated as they change |
| ``/rosout`` | ``rcl_interfaces/msg/Log``: events, feedback, acks |

Message definitions are rosbags' ROS 2 Humble type store; the bag's timestamps are the site clock.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from protocol.messages import (
    CameraFrame,
    CameraTruth,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Message,
    RobotPose,
)
from protocol.site import Site

from . import convert, topics
from .scene import Entity, SiteScene
from .sink import ns

STORE = get_typestore(Stores.ROS2_HUMBLE)
T = STORE.types
LOG_LEVELS = {"DEBUG": 10, "INFO": 20, "WARNING": 30, "ERROR": 40, "CRITICAL": 50}


def ros_time(t: float) -> Any:
    n = ns(t)
    return T["builtin_interfaces/msg/Time"](sec=n // 1_000_000_000, nanosec=n % 1_000_000_000)


def header(t: float, frame: str) -> Any:
    return T["std_msgs/msg/Header"](stamp=ros_time(t), frame_id=frame)


def quaternion(x: float, y: float, z: float, w: float) -> Any:
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def yaw_q(yaw: float) -> Any:
    return quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def pose(x: float, y: float, z: float, q: Any) -> Any:
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z), orientation=q)


def transform(t: float, child: str, xyz: tuple[float, float, float], q: Any) -> Any:
    vec = T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2])
    return T["geometry_msgs/msg/TransformStamped"](
        header=header(t, topics.WORLD_FRAME),
        child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](translation=vec, rotation=q),
    )


def markers(entities: list[Entity], t: float, ids: dict[str, int]) -> Any:
    """Scene entities as markers: namespace = entity id, one marker per shape (ADD replaces)."""
    Marker = T["visualization_msgs/msg/Marker"]
    kinds = {"cube": Marker.CUBE, "cylinder": Marker.CYLINDER, "text": Marker.TEXT_VIEW_FACING}
    out = []
    for entity in entities:
        for k, shape in enumerate(entity.shapes):
            key = f"{entity.id}#{k}"
            ids.setdefault(key, len(ids))
            r, g, b, a = shape.color
            out.append(
                Marker(
                    header=header(t, entity.frame),
                    ns=entity.id,
                    id=ids[key],
                    type=kinds[shape.kind],
                    action=Marker.ADD,
                    pose=pose(*shape.center, yaw_q(shape.yaw)),
                    scale=T["geometry_msgs/msg/Vector3"](x=shape.size[0], y=shape.size[1], z=shape.size[2]),
                    color=T["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a),
                    lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
                    frame_locked=entity.locked,
                    points=[],
                    colors=[],
                    texture_resource="",
                    texture=T["sensor_msgs/msg/CompressedImage"](
                        header=header(t, ""), format="", data=np.zeros(0, dtype=np.uint8)
                    ),
                    uv_coordinates=[],
                    text=shape.text,
                    mesh_resource="",
                    mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
                    mesh_use_embedded_materials=False,
                )
            )
    return T["visualization_msgs/msg/MarkerArray"](markers=out)


class Ros2Profile:
    def __init__(self, folder: Path, site: Site) -> None:
        if folder.exists():
            raise ValueError(f"{folder}: a ROS 2 bag folder must not exist yet")
        folder.parent.mkdir(parents=True, exist_ok=True)
        self.path = folder
        self.writer = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.scene = SiteScene(site)
        self._connections: dict[str, Any] = {}
        self._marker_ids: dict[str, int] = {}
        self._handlers = {
            RobotPose: self._pose,
            CameraTruth: self._truth,
            Intent: self._intent,
            CameraFrame: self._frame,
            DoorState: self._door,
            Event: self._described,
            Feedback: self._described,
            FeedbackAck: self._described,
        }

    def _write(self, topic: str, msgtype: str, msg: Any, t: float) -> None:
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._connections[topic] = self.writer.add_connection(topic, msgtype, typestore=STORE)
        self.writer.write(connection, ns(t), bytes(STORE.serialize_cdr(msg, msgtype)))

    def start(self, t: float) -> None:
        self._write(
            topics.SCENE, "visualization_msgs/msg/MarkerArray", markers(self.scene.entities(), t, self._marker_ids), t
        )

    def handle(self, msg: Message, key: str) -> None:
        handler = self._handlers.get(type(msg))
        if handler is not None:
            handler(msg)

    def log_line(self, t: float, level: str, name: str, text: str) -> None:
        self._rosout(t, LOG_LEVELS.get(level, 20), name, text)

    def close(self) -> None:
        self.writer.close()

    # ------------------------------------------------------------------ per message type

    def _pose(self, msg: RobotPose) -> None:
        q = yaw_q(msg.theta)
        self._write(
            topics.TF,
            "tf2_msgs/msg/TFMessage",
            T["tf2_msgs/msg/TFMessage"](
                transforms=[transform(msg.stamp, topics.robot_frame(msg.robot), (msg.x, msg.y, 0.0), q)]
            ),
            msg.stamp,
        )
        self._write(
            f"/robot/{msg.robot}/pose",
            "geometry_msgs/msg/PoseStamped",
            T["geometry_msgs/msg/PoseStamped"](
                header=header(msg.stamp, topics.WORLD_FRAME), pose=pose(msg.x, msg.y, 0.0, q)
            ),
            msg.stamp,
        )

    def _truth(self, msg: CameraTruth) -> None:
        tf = transform(msg.stamp, topics.camera_frame(msg.camera), tuple(msg.position), quaternion(*msg.quaternion))
        self._write(topics.TF, "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](transforms=[tf]), msg.stamp)

    def _intent(self, msg: Intent) -> None:
        poses = [
            T["geometry_msgs/msg/PoseStamped"](
                header=header(row[0], topics.WORLD_FRAME), pose=pose(row[1], row[2], 0.0, yaw_q(row[3]))
            )
            for row in msg.trajectory
        ]
        self._write(
            f"/robot/{msg.robot}/path",
            "nav_msgs/msg/Path",
            T["nav_msgs/msg/Path"](header=header(msg.stamp, topics.WORLD_FRAME), poses=poses),
            msg.stamp,
        )

    def _frame(self, msg: CameraFrame) -> None:
        frame = topics.camera_frame(msg.camera)
        self._write(
            f"/camera/{msg.camera}/image/compressed",
            "sensor_msgs/msg/CompressedImage",
            T["sensor_msgs/msg/CompressedImage"](
                header=header(msg.stamp, frame), format="jpeg", data=np.frombuffer(msg.jpeg, dtype=np.uint8)
            ),
            msg.stamp,
        )
        fx, fy, cx, cy = msg.intrinsics
        info = T["sensor_msgs/msg/CameraInfo"](
            header=header(msg.stamp, frame),
            height=msg.height,
            width=msg.width,
            distortion_model="plumb_bob",
            d=np.array(msg.distortion, dtype=np.float64),
            k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64),
            r=np.eye(3).ravel(),
            p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64),
            binning_x=0,
            binning_y=0,
            roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        )
        self._write(f"/camera/{msg.camera}/camera_info", "sensor_msgs/msg/CameraInfo", info, msg.stamp)

    def _door(self, msg: DoorState) -> None:
        changed = self.scene.door_changed(msg.door, msg.open)
        if changed is not None:
            self._write(
                topics.SCENE,
                "visualization_msgs/msg/MarkerArray",
                markers([changed], msg.stamp, self._marker_ids),
                msg.stamp,
            )

    def _described(self, msg: Feedback | FeedbackAck | Event) -> None:
        level, text = convert.describe(msg)
        self._rosout(msg.stamp, LOG_LEVELS[level], msg.src, text)

    def _rosout(self, t: float, level: int, name: str, text: str) -> None:
        self._write(
            "/rosout",
            "rcl_interfaces/msg/Log",
            T["rcl_interfaces/msg/Log"](
                stamp=ros_time(t), level=level, name=name, msg=text, file="", function="", line=0
            ),
            t,
        )
