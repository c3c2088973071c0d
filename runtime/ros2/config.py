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
from typing import Annotated, Any, Literal

import msgspec
import msgspec.inspect
import msgspec.structs
from msgspec import Meta

from .keys import KEY_FORMATS, TopicNaming, full_topic
from .types import CMD_VEL_TYPES, HASH_NOT_SUPPORTED, POSE_TYPES

DURABILITIES = ("volatile", "transient_local")
DEFAULT_KEY_FORMAT = "rmw_zenoh"
DEFAULT_DOMAIN = 0

# The file's vocabulary, for msgspec (the words come from the ROS 2 modules, so each is written once).
KeyFormat = Literal[KEY_FORMATS]  # type: ignore[valid-type]
Domain = Annotated[int, Meta(ge=0, le=232)]  # ROS_DOMAIN_ID
Positive = Annotated[float, Meta(gt=0)]  # finiteness is checked after decoding (Meta has no bound for it)
PoseType = Literal[tuple(POSE_TYPES)]  # type: ignore[valid-type]
CmdVelType = Literal[tuple(CMD_VEL_TYPES)]  # type: ignore[valid-type]
Durability = Literal[DURABILITIES]  # type: ignore[valid-type]
TypeHash = Literal["", HASH_NOT_SUPPORTED]  # "" : RIHS01 (Jazzy and later); "TypeHashNotSupported": Humble


class RosConfigError(ValueError):
    """A robot config file that cannot be used: the message names the file and the key."""


class RobotLink(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[ros2.robots.<id>]`` table (its schema: every field but ``robot`` is a key of the table)."""

    robot: str
    namespace: str
    cmd_vel: str = "cmd_vel"
    pose_topic: str = "odom"
    pose_type: PoseType = "odometry"
    map_to_odom: tuple[float, float, float] | None = None  # None: the site start pose
    tf_topic: str = ""
    map_frame: str = "map"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    max_speed: Positive | None = None
    max_turn_rate: Positive = 1.5
    pose_timeout: Positive = 0.3
    control_period: Positive = 0.05
    key_format: KeyFormat | None = None  # None: the [ros2] table's
    domain: Domain | None = None
    cmd_vel_type: CmdVelType = "twist"
    pose_durability: Durability = "volatile"
    odom_topic: str = ""  # with pose_type "pose": odometry between localisation updates ("" none)
    scan_topic: str = ""  # "" : no safety field
    scan_timeout: Positive = 0.5
    obstacle_patience: Positive = 15.0
    type_hash: TypeHash = ""

    @property
    def pose_typename(self) -> str:
        return POSE_TYPES[self.pose_type]

    @property
    def cmd_vel_typename(self) -> str:
        return CMD_VEL_TYPES[self.cmd_vel_type]

    def topic(self, name: str) -> str:
        return full_topic(self.namespace, name)


class DoorLink(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A real door's sensor on ROS 2: ``std_msgs/Bool`` on ``topic`` (true: open); one ``[ros2.doors.<id>]``
    table (every field but ``door`` is a key of the table)."""

    door: str
    topic: str

    @staticmethod
    def default_topic(door: str) -> str:
        return f"/doors/{door}/open"


class _Ros2Table(msgspec.Struct, forbid_unknown_fields=True):
    """The ``[ros2]`` table; its robot and door tables are decoded one by one, so errors name their id."""

    key_format: KeyFormat = DEFAULT_KEY_FORMAT
    domain: Domain = DEFAULT_DOMAIN
    bridge_namespace: str = ""  # ros2dds only: the bridge's `namespace` setting
    robots: dict[str, Any] = {}
    doors: dict[str, Any] = {}


@dataclass(frozen=True)
class Ros2Config:
    key_format: str = DEFAULT_KEY_FORMAT
    domain: int = DEFAULT_DOMAIN
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
            rid: msgspec.structs.replace(
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
    """The ``[ros2]`` table (as tomllib reads it) of the file ``name``; RosConfigError naming file and key."""
    ros2 = _decode(table, _Ros2Table, name, "ros2")
    robots = {rid: _parse_link(rid, entry, name) for rid, entry in ros2.robots.items()}
    doors = {did: _parse_door(did, entry, name) for did, entry in ros2.doors.items()}
    return Ros2Config(ros2.key_format, ros2.domain, ros2.bridge_namespace, robots, name, doors)


_DOOR_ID = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]{0,63}$")


def _parse_door(did: str, entry: Any, name: str) -> DoorLink:
    where = f"ros2.doors.{did}"
    if not _DOOR_ID.match(did):
        raise RosConfigError(f"{name}: {where}: not a door id (letters, digits, '_' or '-', at most 64)")
    door = _decode(entry, DoorLink, name, where, given={"door": did}, defaults={"topic": DoorLink.default_topic(did)})
    try:
        full_topic("/", door.topic)
    except ValueError as exc:
        raise RosConfigError(f"{name}: {where}.topic: {exc}") from None
    return door


def _parse_link(rid: str, entry: Any, name: str) -> RobotLink:
    where = f"ros2.robots.{rid}"
    link = _decode(entry, RobotLink, name, where, given={"robot": rid}, defaults={"namespace": f"/{rid}"})

    def fail(key: str, problem: str) -> RosConfigError:
        return RosConfigError(f"{name}: {where}.{key}: {problem}")

    for key in msgspec.structs.fields(link):  # TOML has inf and nan; no time, speed or offset may be either
        value = getattr(link, key.name)
        numbers = value if isinstance(value, tuple) else (value,)
        if any(isinstance(v, float) and not math.isfinite(v) for v in numbers):
            expected = "finite numbers" if len(numbers) > 1 else "a finite number"
            raise fail(key.name, f"expected {expected}, got {value!r}")
    if link.odom_topic and link.pose_type != "pose":
        raise fail("odom_topic", 'odometry between localisation updates goes with pose_type = "pose"')
    optional = tuple(key for key in ("tf_topic", "odom_topic", "scan_topic") if getattr(link, key))
    for key in ("cmd_vel", "pose_topic") + optional:
        try:
            link.topic(getattr(link, key))
        except ValueError as exc:
            raise fail(key, str(exc)) from None
    return link


def _decode(
    value: Any,
    schema: type[msgspec.Struct],
    name: str,
    where: str,
    *,
    given: dict[str, Any] | None = None,
    defaults: dict[str, Any] | None = None,
) -> Any:
    """``value`` (a TOML table) as ``schema``, with ``given`` (what the table's name says: not a key of it)
    and ``defaults`` (keys the table may set) added; RosConfigError naming the file and the key."""
    given, defaults = given or {}, defaults or {}
    known = sorted(f.name for f in msgspec.structs.fields(schema) if f.name not in given)
    if isinstance(value, dict):
        if named := sorted(value.keys() & given.keys()):
            raise RosConfigError(f"{name}: {where}.{named[0]}: unknown key (known: {', '.join(known)})")
        value = {**defaults, **value, **given}
    try:
        return msgspec.convert(value, schema)
    except msgspec.ValidationError as exc:
        problem, _, at = str(exc).partition(" - at `$")
        path = at.removesuffix("`")
        if unknown := re.fullmatch(r"Object contains unknown field `(.*)`", problem):
            path, problem = f"{path}.{unknown.group(1)}", f"unknown key (known: {', '.join(known)})"
        elif problem.startswith("Invalid enum value ") and (choices := _choices(schema, path.lstrip("."))):
            got = problem.removeprefix("Invalid enum value ")
            problem = f"expected one of {', '.join(repr(c) for c in choices)}, got {got}"
        else:  # msgspec's words, in TOML's: a table, not an object
            problem = problem.replace("`object`", "a table")
            problem = problem[0].lower() + problem[1:]
        raise RosConfigError(f"{name}: {where}{path}: {problem}") from None


def _choices(schema: type[msgspec.Struct], key: str) -> tuple[Any, ...]:
    """The words a key of ``schema`` may take (its Literal's values), or () when it is not one of a few words."""
    for info in msgspec.inspect.type_info(schema).fields:  # type: ignore[union-attr]
        if info.name == key:
            kinds = info.type.types if isinstance(info.type, msgspec.inspect.UnionType) else (info.type,)
            return next((kind.values for kind in kinds if isinstance(kind, msgspec.inspect.LiteralType)), ())
    return ()


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
