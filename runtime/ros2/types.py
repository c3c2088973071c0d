"""The ROS 2 message types ARROCH speaks, CDR encoding by ``rosbags``, and message builders.

Serialising is the ``rosbags`` typestore's (pure Python, generated per type): nothing here lays
out CDR bytes by hand. The type definitions are those of ROS 2 Jazzy; the messages used here have
not changed since Humble.

RIHS01 type hashes (the last chunk of an ``rmw_zenoh`` data key and of its liveliness tokens) are
computed by ``rosbags`` (``Typestore.hash_rihs01``) and checked against :data:`PUBLISHED_HASHES`,
values that ROS 2 itself reported or that projects talking to ROS 2 through ``rmw_zenoh`` use
(tests/ros2/test_wire.py). A mismatch means ROS 2 nodes would not match our topics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache, lru_cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

TWIST = "geometry_msgs/msg/Twist"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
PATH = "nav_msgs/msg/Path"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
STRING = "std_msgs/msg/String"
BOOL = "std_msgs/msg/Bool"  # a real door's sensor: open or shut
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"  # Jazzy's diff_drive_controller takes only this
LASER_SCAN = "sensor_msgs/msg/LaserScan"  # the safety field's input

USED_TYPES = (
    TWIST,
    ODOMETRY,
    POSE_COV_STAMPED,
    TF_MESSAGE,
    PATH,
    MARKER_ARRAY,
    STRING,
    BOOL,
    TWIST_STAMPED,
    LASER_SCAN,
)
CMD_VEL_TYPES = {"twist": TWIST, "twist_stamped": TWIST_STAMPED}
# What Humble's rmw_zenoh writes in keys and tokens where Jazzy and later write the RIHS01 hash.
HASH_NOT_SUPPORTED = "TypeHashNotSupported"

# RIHS01 hashes as ROS 2 reports them, each with where the value was seen (public sources found by
# code search; no ROS 2 installation on the development machine, see docs/ros2.md):
# - Twist: `ros2 topic info /cmd_vel --verbose` ("Topic type hash: RIHS01_9c45...") in a ROS 2
#   tutorial, and rmw_zenoh data keys `0/<ns>/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45...`
#   of zenoh-pico interop examples.
# - TFMessage: `ros2 topic info /tf --verbose` output (publisher node `amcl`, "Topic type hash:
#   RIHS01_e369..."), and the `type_description_hash` of a Jazzy rosbag2 `metadata.yaml`.
# - String: ros2/rmw_zenoh docs/design.md, the liveliness token of the `talker` demo
#   (`.../MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`).
# - Odometry, PoseWithCovarianceStamped, Path, MarkerArray: golden-hash tables of ROS 2 client
#   libraries that talk to rmw_zenoh nodes (C/C++ `CdrTopicInfo`/`CTYPE` type tables, a `rihs01_hash<>`
#   unit test for PoseWithCovarianceStamped, Rust/Elixir message crates).
# - Bool: the expected subscription token of a `std_msgs/Bool` topic in the tests of a Rust client
#   that talks to rmw_zenoh (`.../MS/%/%/rovi/%rovi%arm/std_msgs::msg::dds_::Bool_/RIHS01_feb9...`);
#   tests/ros2/test_wire.py also recomputes it (and String's) from the .msg definition by ROS 2's
#   rule (rosidl_generator_type_description: SHA-256 of the type description's JSON).
# - TwistStamped: `ros2 topic info /cmd_vel -v` output in a ROS 2 tutorial (publisher
#   `ros_gz_bridge`), and rmw_zenoh keys of zenoh-pico/C teleoperation examples driving Jazzy bases.
# - LaserScan: the message tables of Rust and Elixir clients that talk to rmw_zenoh nodes.
PUBLISHED_HASHES: dict[str, str] = {
    TWIST: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    ODOMETRY: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    POSE_COV_STAMPED: "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
    TF_MESSAGE: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    PATH: "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b",
    MARKER_ARRAY: "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf",
    STRING: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    BOOL: "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9",
    TWIST_STAMPED: "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
    LASER_SCAN: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
}


@lru_cache(maxsize=1)
def typestore() -> Any:
    """The ROS 2 Jazzy typestore (built once per process)."""
    return get_typestore(Stores.ROS2_JAZZY)


def dds_type_name(typename: str) -> str:
    """``geometry_msgs/msg/Twist`` -> ``geometry_msgs::msg::dds_::Twist_`` (the type chunk of rmw_zenoh keys)."""
    package, kind, name = typename.split("/")
    return f"{package}::{kind}::dds_::{name}_"


@cache
def type_hash(typename: str) -> str:
    """The RIHS01 hash of ``typename`` (``RIHS01_<64 hex digits>``)."""
    return typestore().hash_rihs01(typename)


def serialize(msg: Any, typename: str) -> bytes:
    """CDR (little endian, with its 4-byte encapsulation header), as ROS 2 puts it on the wire."""
    return bytes(typestore().serialize_cdr(msg, typename))


def deserialize(payload: bytes, typename: str) -> Any:
    """A message from CDR; raises (``ValueError``, ``struct.error``, ...) on a payload that is not one."""
    return typestore().deserialize_cdr(payload, typename)


def t(name: str) -> Any:
    """The message class of ``name`` (e.g. ``t("geometry_msgs/msg/Twist")``)."""
    return typestore().types[name]


# ---------------------------------------------------------------------- building messages


def stamp(seconds: float) -> Any:
    """``builtin_interfaces/Time`` of ``seconds`` (site-clock or Unix seconds)."""
    sec = math.floor(seconds)
    nanosec = min(int(round((seconds - sec) * 1e9)), 999_999_999)
    return t("builtin_interfaces/msg/Time")(sec=int(sec), nanosec=nanosec)


def seconds(time_msg: Any) -> float:
    return float(time_msg.sec) + float(time_msg.nanosec) * 1e-9


def header(at: float, frame_id: str) -> Any:
    return t("std_msgs/msg/Header")(stamp=stamp(at), frame_id=frame_id)


def quaternion(yaw: float) -> Any:
    """The rotation by ``yaw`` about +z."""
    return t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def yaw_of(q: Any) -> float:
    """Yaw of a quaternion (roll and pitch ignored: ground robots)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def vector3(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return t("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def pose(x: float, y: float, yaw: float, z: float = 0.0) -> Any:
    return t("geometry_msgs/msg/Pose")(
        position=t("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=float(z)), orientation=quaternion(yaw)
    )


def twist(v: float, omega: float) -> Any:
    """``geometry_msgs/Twist`` of a unicycle: ``linear.x`` = v, ``angular.z`` = omega."""
    return t(TWIST)(linear=vector3(v), angular=vector3(0.0, 0.0, omega))


def twist_stamped(at: float, frame: str, v: float, omega: float) -> Any:
    """``geometry_msgs/TwistStamped``: the Twist with a stamp (``at``, the receiver's clock: a
    diff_drive_controller drops commands older than its ``cmd_vel_timeout``) and the base's frame."""
    return t(TWIST_STAMPED)(header=header(at, frame), twist=twist(v, omega))


def cmd_vel(typename: str, v: float, omega: float, at: float, frame: str) -> Any:
    """The velocity command in the base's ``cmd_vel`` type (Twist, or TwistStamped stamped ``at``)."""
    return twist_stamped(at, frame, v, omega) if typename == TWIST_STAMPED else twist(v, omega)


def laser_scan(at: float, frame: str, angle_min: float, angle_increment: float, ranges: Any, range_max: float) -> Any:
    """``sensor_msgs/LaserScan`` of ``ranges`` (m; ``inf``: no return within ``range_max``)."""
    values = np.asarray(ranges, dtype=np.float32)
    return t(LASER_SCAN)(
        header=header(at, frame),
        angle_min=float(angle_min),
        angle_max=float(angle_min + angle_increment * max(len(values) - 1, 0)),
        angle_increment=float(angle_increment),
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.05,
        range_max=float(range_max),
        ranges=values,
        intensities=np.zeros(0, dtype=np.float32),
    )


def odometry(at: float, frame: str, child_frame: str, x: float, y: float, yaw: float, v: float, omega: float) -> Any:
    """``nav_msgs/Odometry`` of a planar base (covariances zero: the simulated base knows its pose)."""
    zeros = np.zeros(36, dtype=np.float64)
    return t(ODOMETRY)(
        header=header(at, frame),
        child_frame_id=child_frame,
        pose=t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(x, y, yaw), covariance=zeros),
        twist=t("geometry_msgs/msg/TwistWithCovariance")(twist=twist(v, omega), covariance=zeros.copy()),
    )


def pose_with_covariance_stamped(at: float, frame: str, x: float, y: float, yaw: float) -> Any:
    """``geometry_msgs/PoseWithCovarianceStamped`` (what a localiser such as amcl publishes)."""
    return t(POSE_COV_STAMPED)(
        header=header(at, frame),
        pose=t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(x, y, yaw), covariance=np.zeros(36, dtype=np.float64)),
    )


def transform_stamped(at: float, parent: str, child: str, x: float, y: float, yaw: float) -> Any:
    return t("geometry_msgs/msg/TransformStamped")(
        header=header(at, parent),
        child_frame_id=child,
        transform=t("geometry_msgs/msg/Transform")(translation=vector3(x, y, 0.0), rotation=quaternion(yaw)),
    )


def string(text: str) -> Any:
    return t(STRING)(data=text)


def boolean(value: bool) -> Any:
    return t(BOOL)(data=bool(value))


# ---------------------------------------------------------------------- reading messages


@dataclass(frozen=True)
class Pose2D:
    x: float
    y: float
    theta: float
    v: float = 0.0
    omega: float = 0.0
    frame: str = ""
    child_frame: str = ""
    stamp: float = 0.0


def pose_2d(msg: Any, typename: str) -> Pose2D:
    """The planar pose (and, from odometry, the velocity) a localisation or odometry message carries."""
    if typename == ODOMETRY:
        p = msg.pose.pose
        tw = msg.twist.twist
        return Pose2D(
            p.position.x,
            p.position.y,
            yaw_of(p.orientation),
            tw.linear.x,
            tw.angular.z,
            msg.header.frame_id,
            msg.child_frame_id,
            seconds(msg.header.stamp),
        )
    if typename == POSE_COV_STAMPED:
        p = msg.pose.pose
        return Pose2D(
            p.position.x,
            p.position.y,
            yaw_of(p.orientation),
            frame=msg.header.frame_id,
            stamp=seconds(msg.header.stamp),
        )
    raise ValueError(f"no planar pose in a {typename}")


def twist_of(msg: Any, typename: str) -> tuple[float, float]:
    """(v, omega) of a Twist or TwistStamped."""
    tw = msg.twist if typename == TWIST_STAMPED else msg
    return float(tw.linear.x), float(tw.angular.z)


POSE_TYPES = {"odometry": ODOMETRY, "pose": POSE_COV_STAMPED}
