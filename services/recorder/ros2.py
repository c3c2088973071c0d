"""The ``ros2`` recording profile: the run as ROS 2 messages in a rosbag2 folder (MCAP storage) of one
distribution (``--ros-distro humble|jazzy``, :mod:`.rosbag`), which that distribution's ``ros2 bag
play`` and RViz 2 take as they are. The same code converts a recorded ``run.mcap`` offline
(``arroch runs export RUN --ros2 OUT``, :mod:`.export`).

Topics, frames and marker namespaces are those of ``arroch ros2 bridge`` (its default
``--ros-namespace /arroch``; :mod:`runtime.ros2.markers`), so an RViz 2 set-up for the live bridge
shows a bag too:

| topic | type |
|---|---|
| ``/clock`` | ``rosgraph_msgs/msg/Clock``: the site clock, at every ``Clock`` message |
| ``/tf`` | ``tf2_msgs/msg/TFMessage``: ``map`` → ``<rid>/base_link``, ``map`` → ``<cid>/camera_optical_frame`` |
| ``/arroch/<rid>/pose`` | ``geometry_msgs/msg/PoseStamped`` (``map``) |
| ``/arroch/<rid>/path`` | ``nav_msgs/msg/Path``: the robot's intent (motion plan), stamped per point |
| ``/arroch/site`` | ``visualization_msgs/msg/MarkerArray``: the bridge's markers, again at every change (latched) |
| ``/arroch/camera/<cid>/image/compressed`` | ``sensor_msgs/msg/CompressedImage`` |
| ``/arroch/camera/<cid>/camera_info`` | ``sensor_msgs/msg/CameraInfo`` |
| ``/rosout`` | ``rcl_interfaces/msg/Log``: events, feedback, acks, the services' log lines |

Every stamp, and every message's time in the bag, is the wall clock of the run's start plus site time
(:mod:`.timebase`), as in ``run.mcap``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from protocol.events import Delivered
from protocol.messages import (
    CameraFrame,
    CameraTruth,
    Clock,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    Intent,
    Message,
    RobotPose,
    RobotStatus,
)
from protocol.site import Site
from runtime.ros2 import types as ros
from runtime.ros2.markers import MAP_FRAME, SiteState, robot_frame, site_markers

from . import convert
from .logtail import LogLine
from .rosbag import BagWriter, Distro, qos
from .timebase import ORIGIN_KEY, Timebase
from .topics import camera_frame

ROS_NAMESPACE = "/arroch"  # the bridge's default --ros-namespace
SITE = f"{ROS_NAMESPACE}/site"
LOG_LEVELS = {"DEBUG": 10, "INFO": 20, "WARNING": 30, "ERROR": 40, "CRITICAL": 50}
# QoS as the publishers' would be: tf2's broadcaster, rcl's /rosout, latched markers (RViz joining late).
QOS = {"/tf": qos(depth=100), "/rosout": qos(depth=1000), "/clock": qos(depth=1), SITE: qos(depth=1, latched=True)}


def ros_time(at: int) -> Any:
    """A log time (ns) as ``builtin_interfaces/Time``, exactly."""
    return ros.t("builtin_interfaces/msg/Time")(sec=at // 1_000_000_000, nanosec=at % 1_000_000_000)


def header(at: int, frame: str) -> Any:
    return ros.t("std_msgs/msg/Header")(stamp=ros_time(at), frame_id=frame)


def transform(at: int, child: str, xyz: tuple[float, float, float], rotation: Any) -> Any:
    return ros.t("geometry_msgs/msg/TransformStamped")(
        header=header(at, MAP_FRAME),
        child_frame_id=child,
        transform=ros.t("geometry_msgs/msg/Transform")(translation=ros.vector3(*xyz), rotation=rotation),
    )


class Ros2Profile:
    def __init__(self, folder: Path, site: Site, timebase: Timebase, distro: Distro, namespace: str) -> None:
        self.bag = BagWriter(folder, distro, {"namespace": namespace, "site": site.name})
        self.path = folder
        self.site = site
        self.time = timebase
        self.namespace = namespace
        self.state = SiteState()
        self.poses: dict[str, tuple[float, float]] = {}
        self._handlers = {
            Clock: self._clock,
            RobotPose: self._pose,
            RobotStatus: self._status,
            CameraTruth: self._truth,
            Intent: self._intent,
            CameraFrame: self._frame,
            DoorState: self._door,
            Event: self._event,
            Feedback: self._described,
            FeedbackAck: self._described,
        }

    def _write(self, topic: str, msgtype: str, msg: Any, at: int) -> None:
        self.bag.write(topic, msgtype, msg, at, QOS.get(topic))

    def start(self, at: int) -> None:
        self.bag.open()
        self._markers(at)

    def origin_fixed(self) -> None:
        self.bag.custom_data[ORIGIN_KEY] = str(self.time.origin_ns or 0)

    def resend(self, topic: str, at: int) -> None:
        """Nothing to send again: a bag has no viewers."""

    def tick(self) -> None:
        """Nothing to do between messages."""

    def handle(self, msg: Message, key: str, payload: bytes) -> None:
        handler = self._handlers.get(type(msg))
        if handler is not None:
            handler(msg, self.time.at(msg.stamp))

    def log_line(self, line: LogLine, at: int, file: str = "") -> None:
        self._rosout(at, LOG_LEVELS.get(line.level, 20), line.name, line.text, file, line.number)

    def close(self) -> None:
        self.bag.close()

    def abort(self) -> None:
        self.bag.abort()

    # ------------------------------------------------------------------ per message type

    def _clock(self, msg: Clock, at: int) -> None:
        clock = ros_time(self.time.at(msg.time))
        self._write("/clock", "rosgraph_msgs/msg/Clock", ros.t("rosgraph_msgs/msg/Clock")(clock=clock), at)

    def _pose(self, msg: RobotPose, at: int) -> None:
        self.poses[msg.robot] = (msg.x, msg.y)
        tf = transform(at, robot_frame(msg.robot), (msg.x, msg.y, 0.0), ros.quaternion(msg.theta))
        self._write("/tf", ros.TF_MESSAGE, ros.t(ros.TF_MESSAGE)(transforms=[tf]), at)
        pose = ros.pose(msg.x, msg.y, msg.theta)
        stamped = ros.t("geometry_msgs/msg/PoseStamped")(header=header(at, MAP_FRAME), pose=pose)
        self._write(f"{ROS_NAMESPACE}/{msg.robot}/pose", "geometry_msgs/msg/PoseStamped", stamped, at)

    def _truth(self, msg: CameraTruth, at: int) -> None:
        qx, qy, qz, qw = msg.quaternion
        rotation = ros.t("geometry_msgs/msg/Quaternion")(x=qx, y=qy, z=qz, w=qw)
        tf = transform(at, camera_frame(msg.camera), tuple(msg.position), rotation)
        self._write("/tf", ros.TF_MESSAGE, ros.t(ros.TF_MESSAGE)(transforms=[tf]), at)

    def _intent(self, msg: Intent, at: int) -> None:
        PoseStamped = ros.t("geometry_msgs/msg/PoseStamped")
        poses = [
            PoseStamped(header=header(self.time.at(t), MAP_FRAME), pose=ros.pose(x, y, theta))
            for t, x, y, theta in msg.trajectory
        ]
        path = ros.t(ros.PATH)(header=header(at, MAP_FRAME), poses=poses)
        self._write(f"{ROS_NAMESPACE}/{msg.robot}/path", ros.PATH, path, at)

    def _frame(self, msg: CameraFrame, at: int) -> None:
        frame = camera_frame(msg.camera)
        base = f"{ROS_NAMESPACE}/camera/{msg.camera}"
        image = ros.t("sensor_msgs/msg/CompressedImage")(
            header=header(at, frame), format="jpeg", data=np.frombuffer(msg.jpeg, dtype=np.uint8)
        )
        self._write(f"{base}/image/compressed", "sensor_msgs/msg/CompressedImage", image, at)
        fx, fy, cx, cy = msg.intrinsics
        info = ros.t("sensor_msgs/msg/CameraInfo")(
            header=header(at, frame),
            height=msg.height,
            width=msg.width,
            distortion_model="plumb_bob",
            d=np.array(msg.distortion, dtype=np.float64),
            k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64),
            r=np.eye(3).ravel(),
            p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64),
            binning_x=0,
            binning_y=0,
            roi=ros.t("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        )
        self._write(f"{base}/camera_info", "sensor_msgs/msg/CameraInfo", info, at)

    def _markers(self, at: int) -> None:
        self._write(SITE, ros.MARKER_ARRAY, site_markers(self.site, self.state, at / 1e9), at)

    def _door(self, msg: DoorState, at: int) -> None:
        if self.state.door(msg.door, msg.open):
            self._markers(at)

    def _status(self, msg: RobotStatus, at: int) -> None:
        if self.state.carrying(msg.robot, list(msg.carrying), self.poses.get(msg.robot, (0.0, 0.0))):
            self._markers(at)

    def _event(self, msg: Event, at: int) -> None:
        self._described(msg, at)
        if msg.kind == "delivered" and msg.object:
            pose = msg.data.pose if isinstance(msg.data, Delivered) else None
            where = (float(pose[0]), float(pose[1])) if isinstance(pose, list) else None
            if self.state.delivered_at(msg.object, where or self.poses.get(msg.robot)):
                self._markers(at)

    def _described(self, msg: Feedback | FeedbackAck | Event, at: int) -> None:
        level, text = convert.describe(msg)
        self._rosout(at, LOG_LEVELS[level], msg.src, text)

    def _rosout(self, at: int, level: int, name: str, text: str, file: str = "", line: int = 0) -> None:
        log = ros.t("rcl_interfaces/msg/Log")(
            stamp=ros_time(at), level=level, name=name, msg=text, file=file, function="", line=line
        )
        self._write("/rosout", "rcl_interfaces/msg/Log", log, at)
