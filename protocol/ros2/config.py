"""How each robot is reached through ROS 2: the ``[ros2]`` tables of a robot config file (TOML).

```toml
[ros2]
key_format = "rmw_zenoh"        # or "ros2dds" (zenoh-bridge-ros2dds)
domain = 0                      # ROS_DOMAIN_ID (rmw_zenoh keys and tokens)
bridge_namespace = ""           # ros2dds only: the bridge's `namespace` setting

[ros2.robots.r0]
# key_format = "ros2dds"        # this robot only (a mixed fleet); likewise domain
namespace = "/r0"               # ROS namespace of the robot's topics (default "/<robot id>")
cmd_vel = "cmd_vel"             # velocity commands in
cmd_vel_type = "twist"          # geometry_msgs/Twist, or "twist_stamped" (Jazzy's diff_drive_controller)
pose_topic = "odom"             # where its pose comes from
pose_type = "odometry"          # nav_msgs/Odometry (odom frame), or "pose":
                                # geometry_msgs/PoseWithCovarianceStamped (map frame, e.g. amcl_pose)
pose_durability = "volatile"    # or "transient_local" (amcl_pose: its last pose is asked for on start)
# odom_topic = "odom"           # with pose_type "pose": odometry carries the pose between two
                                # (sparse) localisation updates
# scan_topic = "scan"           # sensor_msgs/LaserScan: the safety field (off when not set)
scan_timeout = 0.5              # s of site time without a scan before the base is stopped
obstacle_patience = 15.0        # s held by an obstacle before the action fails (the planner replans)
# type_hash = "TypeHashNotSupported"  # Humble's rmw_zenoh (no RIHS01 hashes in its keys)
map_to_odom = [1.0, 2.0, 0.0]   # fixed map->odom transform (x, y, yaw rad); default: the robot's
                                # start pose in the site file (odometry starts at zero where it boots)
# tf_topic = "/tf"              # instead: take map->odom from tf2_msgs/TFMessage on this topic
map_frame = "map"
odom_frame = "odom"
base_frame = "base_link"
max_speed = 0.5                 # m/s sent at most (default: the site's robot_speed)
max_turn_rate = 1.5             # rad/s
pose_timeout = 0.3              # s of site time without a pose before the base is stopped
control_period = 0.05           # s between two poses (odometry rate); the controller's step

[ros2.doors.d_storage]
# A real door's sensor, std_msgs/Bool (true: open), which `arroch ros2 bridge` turns into
# DoorState on door/d_storage/sensor (the simulator with --doors sensor follows it).
topic = "/doors/d_storage/open" # the default; a relative name is in the bridge's --ros-namespace
```

Every key is optional; a robot without a table gets the defaults. Errors name the file and key.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .keys import KEY_FORMATS, TopicNaming, full_topic
from .types import CMD_VEL_TYPES, HASH_NOT_SUPPORTED, POSE_TYPES

DURABILITIES = ("volatile", "transient_local")


class RosConfigError(ValueError):
    """A robot config file that cannot be used: the message names the file and the key."""


@dataclass(frozen=True)
class RobotLink:
    robot: str
    namespace: str
    cmd_vel: str = "cmd_vel"
    pose_topic: str = "odom"
    pose_type: str = "odometry"
    map_to_odom: tuple[float, float, float] | None = None  # None: the site start pose
    tf_topic: str = ""
    map_frame: str = "map"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    max_speed: float | None = None
    max_turn_rate: float = 1.5
    pose_timeout: float = 0.3
    control_period: float = 0.05
    key_format: str | None = None  # None: the [ros2] table's
    domain: int | None = None
    cmd_vel_type: str = "twist"
    pose_durability: str = "volatile"
    odom_topic: str = ""  # with pose_type "pose": odometry between localisation updates ("" none)
    scan_topic: str = ""  # "" : no safety field
    scan_timeout: float = 0.5
    obstacle_patience: float = 15.0
    type_hash: str = ""  # "" : RIHS01 (Jazzy and later); "TypeHashNotSupported": Humble

    @property
    def pose_typename(self) -> str:
        return POSE_TYPES[self.pose_type]

    @property
    def cmd_vel_typename(self) -> str:
        return CMD_VEL_TYPES[self.cmd_vel_type]

    def topic(self, name: str) -> str:
        return full_topic(self.namespace, name)


@dataclass(frozen=True)
class DoorLink:
    """A real door's sensor on ROS 2: ``std_msgs/Bool`` on ``topic`` (true: open)."""

    door: str
    topic: str

    @staticmethod
    def default_topic(door: str) -> str:
        return f"/doors/{door}/open"


@dataclass(frozen=True)
class Ros2Config:
    key_format: str = "rmw_zenoh"
    domain: int = 0
    bridge_namespace: str = ""
    robots: dict[str, RobotLink] = field(default_factory=dict)
    source: str = "<defaults>"
    doors: dict[str, DoorLink] = field(default_factory=dict)  # door id -> its sensor's topic

    def naming(self, robot: str | None = None) -> TopicNaming:
        """Keys for the whole deployment, or for ``robot`` (its own key format and domain, if set)."""
        link = self.robots.get(robot) if robot else None
        key_format = (link.key_format if link else None) or self.key_format
        domain = link.domain if link is not None and link.domain is not None else self.domain
        humble = link is not None and link.type_hash == HASH_NOT_SUPPORTED
        return TopicNaming(key_format, domain, self.bridge_namespace, hashless=humble)

    def link(self, robot: str) -> RobotLink:
        return self.robots.get(robot) or RobotLink(robot, f"/{robot}")

    def with_overrides(self, *, key_format: str | None = None, domain: int | None = None) -> Ros2Config:
        """The command line's key format and domain, for every robot."""
        robots = {
            rid: replace(
                link, key_format=key_format or link.key_format, domain=link.domain if domain is None else domain
            )
            for rid, link in self.robots.items()
        }
        changed = replace(
            self,
            key_format=key_format or self.key_format,
            domain=self.domain if domain is None else domain,
            robots=robots,
        )
        changed.naming()  # checks them
        return changed


_FLOATS = ("max_speed", "max_turn_rate", "pose_timeout", "control_period", "scan_timeout", "obstacle_patience")
_STRINGS = (
    "namespace",
    "cmd_vel",
    "pose_topic",
    "pose_type",
    "tf_topic",
    "map_frame",
    "odom_frame",
    "base_frame",
    "cmd_vel_type",
    "pose_durability",
    "odom_topic",
    "scan_topic",
    "type_hash",
)
# Keys whose string value is one of a few words, and those words.
_CHOICES = {
    "pose_type": tuple(POSE_TYPES),
    "cmd_vel_type": tuple(CMD_VEL_TYPES),
    "pose_durability": DURABILITIES,
    "type_hash": ("", HASH_NOT_SUPPORTED),
}


def load_ros2_config(path: str | Path | None) -> Ros2Config:
    """The config in ``path`` (``None``: all defaults)."""
    if path is None:
        return Ros2Config()
    name = Path(path).name
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise RosConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise RosConfigError(f"{name}: not TOML: {exc}") from None
    return parse_ros2_config(data.get("ros2", {}), name)


def parse_ros2_config(table: Any, name: str = "<config>") -> Ros2Config:
    def fail(key: str, problem: str) -> RosConfigError:
        return RosConfigError(f"{name}: ros2.{key}: {problem}")

    if not isinstance(table, dict):
        raise fail("", "must be a table")
    key_format = table.get("key_format", "rmw_zenoh")
    if key_format not in KEY_FORMATS:
        raise fail("key_format", f"expected one of {', '.join(KEY_FORMATS)}, got {key_format!r}")
    domain = table.get("domain", 0)
    if not _is_domain(domain):
        raise fail("domain", f"expected an integer 0..232, got {domain!r}")
    bridge_ns = table.get("bridge_namespace", "")
    if not isinstance(bridge_ns, str):
        raise fail("bridge_namespace", "expected a string")
    robots: dict[str, RobotLink] = {}
    for rid, entry in (table.get("robots") or {}).items():
        robots[rid] = _parse_link(rid, entry, lambda key, problem, rid=rid: fail(f"robots.{rid}.{key}", problem))
    doors_table = table.get("doors", {})
    if not isinstance(doors_table, dict):
        raise fail("doors", "must be a table of [ros2.doors.<door id>] tables")
    doors = {
        did: _parse_door(did, entry, lambda key, problem, did=did: fail(f"doors.{did}{key}", problem))
        for did, entry in doors_table.items()
    }
    return Ros2Config(key_format, domain, bridge_ns, robots, name, doors)


_DOOR_ID = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]{0,63}$")


def _parse_door(did: str, entry: Any, fail: Any) -> DoorLink:
    if not _DOOR_ID.match(did):
        raise fail("", "not a door id (letters, digits, '_' or '-', at most 64)")
    if not isinstance(entry, dict):
        raise fail("", 'must be a table (topic = "/doors/<door>/open")')
    for key in entry:
        if key != "topic":
            raise fail(f".{key}", "unknown key (known: topic)")
    topic = entry.get("topic", DoorLink.default_topic(did))
    if not isinstance(topic, str):
        raise fail(".topic", f"expected a string, got {topic!r}")
    try:
        full_topic("/", topic)
    except ValueError as exc:
        raise fail(".topic", str(exc)) from None
    return DoorLink(did, topic)


def check_doors(config: Ros2Config, site: Any) -> None:
    """Every door of ``config.doors`` is a human-operated door of ``site`` (RosConfigError if not):
    a sensor of a door the site lacks, or of an automatic one, would be listened to for nothing."""
    human = sorted(d.id for d in site.doors.values() if d.human_operated)
    for did in config.doors:
        door = site.doors.get(did)
        if door is None or not door.human_operated:
            problem = "no such door on" if door is None else "an automatic door of"
            raise RosConfigError(
                f"{config.source}: ros2.doors.{did}: {problem} site {site.name} "
                f"(its human-operated doors: {', '.join(human) or 'none'})"
            )


def _is_domain(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 232


def _parse_link(rid: str, entry: Any, fail: Any) -> RobotLink:
    if not isinstance(entry, dict):
        raise fail("", "must be a table")
    known = set(_FLOATS) | set(_STRINGS) | {"map_to_odom", "key_format", "domain"}
    for key in entry:
        if key not in known:
            raise fail(key, f"unknown key (known: {', '.join(sorted(known))})")
    values: dict[str, Any] = {"namespace": f"/{rid}"}
    for key in _STRINGS:
        if key in entry:
            if not isinstance(entry[key], str):
                raise fail(key, f"expected a string, got {entry[key]!r}")
            values[key] = entry[key]
    for key in _FLOATS:
        if key in entry:
            value = entry[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise fail(key, f"expected a number > 0, got {value!r}")
            values[key] = float(value)
    if "map_to_odom" in entry:
        value = entry["map_to_odom"]
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        ):
            raise fail("map_to_odom", f"expected [x, y, yaw] (metres, radians), got {value!r}")
        values["map_to_odom"] = tuple(float(v) for v in value)
    if "key_format" in entry:
        if entry["key_format"] not in KEY_FORMATS:
            raise fail("key_format", f"expected one of {', '.join(KEY_FORMATS)}, got {entry['key_format']!r}")
        values["key_format"] = entry["key_format"]
    if "domain" in entry:
        if not _is_domain(entry["domain"]):
            raise fail("domain", f"expected an integer 0..232, got {entry['domain']!r}")
        values["domain"] = entry["domain"]
    for key, words in _CHOICES.items():
        if key in values and values[key] not in words:
            raise fail(key, f"expected one of {', '.join(repr(w) for w in words)}, got {values[key]!r}")
    if values.get("odom_topic") and values.get("pose_type", "odometry") != "pose":
        raise fail("odom_topic", 'odometry between localisation updates goes with pose_type = "pose"')
    link = RobotLink(rid, **values)
    optional = tuple(key for key in ("tf_topic", "odom_topic", "scan_topic") if getattr(link, key))
    for key in ("cmd_vel", "pose_topic") + optional:
        try:
            link.topic(getattr(link, key))
        except ValueError as exc:
            raise fail(key, str(exc)) from None
    return link


def add_ros2_link_arguments(parser: Any) -> None:
    """The ROS 2 options every ROS 2 facing command shares (robot driver, simulated bases, bridge)."""
    parser.add_argument(
        "--ros2-config",
        metavar="FILE",
        help="robot config file with [ros2] tables (docs/ros2.md); default: built-in defaults",
    )
    parser.add_argument(
        "--key-format", choices=KEY_FORMATS, help="ROS 2 key format (overrides the config file; default rmw_zenoh)"
    )
    parser.add_argument("--domain", type=int, metavar="N", help="ROS domain id (overrides the config file; default 0)")


def ros2_config_from(args: Any) -> Ros2Config:
    """The config the options above name (raises RosConfigError, a ValueError, when it is bad)."""
    return load_ros2_config(args.ros2_config).with_overrides(key_format=args.key_format, domain=args.domain)
