"""The site as a 3D scene: walls, door leaves in their live state, rooms, tag landmarks, objects and
robot bodies, described once (:class:`Entity` of :class:`Shape`) and drawn as Foxglove
``SceneUpdate`` entities. (ROS 2 bags draw the site with the bridge's markers instead,
:mod:`runtime.ros2.markers`, so a bag and the live bridge look the same in RViz 2.)

The scene is sent whole once, then only the entities that change: a door opening or closing, an
object loaded (it then rides in its robot's frame) or delivered (left where the robot stood).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from protocol.site import Site
from runtime.palette import robot_colors

from .topics import MAP_FRAME, robot_frame

RGBA = tuple[float, float, float, float]
WALL: RGBA = (0.62, 0.62, 0.66, 1.0)
DOOR_OPEN: RGBA = (0.2, 0.75, 0.3, 0.9)
DOOR_CLOSED: RGBA = (0.85, 0.2, 0.2, 0.9)
DOOR_UNKNOWN: RGBA = (0.5, 0.5, 0.5, 0.9)
FLOOR: RGBA = (0.92, 0.92, 0.88, 0.35)
TAG: RGBA = (0.05, 0.05, 0.05, 1.0)
LABEL: RGBA = (0.1, 0.1, 0.1, 1.0)
OBJECT: RGBA = (0.95, 0.75, 0.1, 1.0)
LEAF_HEIGHT = 2.08  # as the simulator's leaves (services/sim/world.py)
ROBOT_HEIGHT = 0.4
OBJECT_SIZE = 0.25


@dataclass(frozen=True)
class Shape:
    kind: str  # "cube", "cylinder" or "text"
    center: tuple[float, float, float]
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)  # text: size[2] is the font height in metres
    color: RGBA = LABEL
    yaw: float = 0.0
    text: str = ""


@dataclass(frozen=True)
class Entity:
    id: str
    frame: str
    shapes: tuple[Shape, ...]
    locked: bool = False  # follows its frame as it moves (robots, carried objects)


def stamp_of(at: int) -> Timestamp:
    """A log time (Unix nanoseconds, :mod:`.timebase`) as a Foxglove timestamp."""
    return Timestamp(sec=at // 1_000_000_000, nsec=at % 1_000_000_000)


def yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def rgba(rgb: tuple[int, int, int], a: float = 1.0) -> Color:
    return Color(r=rgb[0] / 255.0, g=rgb[1] / 255.0, b=rgb[2] / 255.0, a=a)


def _box(cx: float, cy: float, cz: float, sx: float, sy: float, sz: float, color: RGBA, yaw: float = 0.0) -> Shape:
    return Shape("cube", (cx, cy, cz), (sx, sy, sz), color, yaw)


def _label(x: float, y: float, z: float, text: str, size: float = 0.25) -> Shape:
    return Shape("text", (x, y, z), (size, size, size), LABEL, 0.0, text)


@dataclass
class SiteScene:
    """The site's entities and their live state."""

    site: Site
    doors: dict[str, bool | None] = field(default_factory=dict)  # door -> open (None: not heard yet)
    carried: dict[str, str] = field(default_factory=dict)  # object -> robot carrying it
    dropped: dict[str, tuple[float, float]] = field(default_factory=dict)  # object -> where it was delivered

    def __post_init__(self) -> None:
        self.doors = {did: None for did in self.site.doors}
        self.colors = robot_colors(self.site.robots)

    def entities(self) -> list[Entity]:
        """The whole scene as it is now."""
        site = self.site
        walls = tuple(
            _box(
                (w.box[0] + w.box[2]) / 2,
                (w.box[1] + w.box[3]) / 2,
                w.height / 2,
                w.box[2] - w.box[0],
                w.box[3] - w.box[1],
                w.height,
                WALL,
            )
            for w in site.walls
        )
        out = [Entity("walls", MAP_FRAME, walls)]
        for room in site.rooms.values():
            x0, y0, x1, y1 = room.rect
            out.append(
                Entity(
                    f"room/{room.id}",
                    MAP_FRAME,
                    (
                        _box((x0 + x1) / 2, (y0 + y1) / 2, 0.005, x1 - x0, y1 - y0, 0.01, FLOOR),
                        _label((x0 + x1) / 2, (y0 + y1) / 2, 0.05, room.id, 0.4),
                    ),
                )
            )
        for tag in site.landmarks:
            x, y, z = tag.position
            nx, ny = tag.normal[0], tag.normal[1]
            out.append(
                Entity(
                    f"tag/{tag.tag}",
                    MAP_FRAME,
                    (
                        _box(x + 0.01 * nx, y + 0.01 * ny, z, 0.02, tag.size, tag.size, TAG, tag.yaw),
                        _label(x + 0.15 * nx, y + 0.15 * ny, z + tag.size, f"tag {tag.tag}", 0.15),
                    ),
                )
            )
        radius = site.params.robot_radius
        for rid in site.robots:
            r, g, b = self.colors[rid]
            body = Shape(
                "cylinder",
                (0.0, 0.0, ROBOT_HEIGHT / 2),
                (2 * radius, 2 * radius, ROBOT_HEIGHT),
                (r / 255, g / 255, b / 255, 1.0),
            )
            nose = _box(radius * 0.7, 0.0, ROBOT_HEIGHT + 0.02, 0.15, 0.06, 0.04, LABEL)
            out.append(
                Entity(
                    f"robot/{rid}",
                    robot_frame(rid),
                    (body, nose, _label(0.0, 0.0, ROBOT_HEIGHT + 0.3, rid)),
                    locked=True,
                )
            )
        return out + [self.door(did) for did in site.door_leaves] + [self.object(oid) for oid in site.objects]

    def door(self, did: str) -> Entity:
        leaf = self.site.door_leaves[did]
        height = min(LEAF_HEIGHT, self.site.params.wall_height - 0.02)
        state = self.doors.get(did)
        yaw = leaf.open_yaw if state else leaf.closed_yaw
        cx = leaf.hinge[0] + leaf.length / 2 * math.cos(yaw)
        cy = leaf.hinge[1] + leaf.length / 2 * math.sin(yaw)
        color = DOOR_UNKNOWN if state is None else DOOR_OPEN if state else DOOR_CLOSED
        text = f"{did}: {'?' if state is None else 'open' if state else 'closed'}"
        return Entity(
            f"door/{did}",
            MAP_FRAME,
            (
                _box(cx, cy, height / 2 + 0.01, leaf.length, leaf.thickness, height, color, yaw),
                _label(leaf.hinge[0], leaf.hinge[1], height + 0.2, text, 0.2),
            ),
        )

    def object(self, oid: str) -> Entity:
        obj = self.site.objects[oid]
        if oid in self.carried:
            frame, (x, y, z) = robot_frame(self.carried[oid]), (0.0, 0.0, ROBOT_HEIGHT + OBJECT_SIZE / 2)
        else:
            frame = MAP_FRAME
            x, y = self.dropped.get(oid, obj.position)
            z = OBJECT_SIZE / 2
        return Entity(
            f"object/{oid}",
            frame,
            (
                _box(x, y, z, OBJECT_SIZE, OBJECT_SIZE, OBJECT_SIZE, OBJECT),
                _label(x, y, z + 0.3, f"{oid} → {obj.deliver_to}", 0.15),
            ),
            locked=frame != MAP_FRAME,
        )

    # ------------------------------------------------------------------ changes (None: nothing changed)

    def door_changed(self, door: str, is_open: bool) -> Entity | None:
        if door not in self.doors or self.doors[door] == is_open:
            return None
        self.doors[door] = is_open
        return self.door(door)

    def object_loaded(self, obj: str, robot: str) -> Entity | None:
        if obj not in self.site.objects:
            return None
        self.carried[obj] = robot
        return self.object(obj)

    def object_delivered(self, obj: str, where: tuple[float, float]) -> Entity | None:
        if obj not in self.site.objects:
            return None
        self.carried.pop(obj, None)
        self.dropped[obj] = where
        return self.object(obj)


def _color(c: RGBA) -> Color:
    return Color(r=c[0], g=c[1], b=c[2], a=c[3])


def _pose(shape: Shape) -> Pose:
    x, y, z = shape.center
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=yaw_quaternion(shape.yaw))


def to_foxglove(entities: list[Entity], at: int) -> SceneUpdate:
    ts = stamp_of(at)
    out = []
    for e in entities:
        size = lambda s: Vector3(x=s.size[0], y=s.size[1], z=s.size[2])  # noqa: E731
        out.append(
            SceneEntity(
                timestamp=ts,
                frame_id=e.frame,
                id=e.id,
                frame_locked=e.locked,
                cubes=[
                    CubePrimitive(pose=_pose(s), size=size(s), color=_color(s.color))
                    for s in e.shapes
                    if s.kind == "cube"
                ],
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(s), size=size(s), bottom_scale=1.0, top_scale=1.0, color=_color(s.color)
                    )
                    for s in e.shapes
                    if s.kind == "cylinder"
                ],
                texts=[
                    TextPrimitive(
                        pose=_pose(s), billboard=True, font_size=s.size[2], color=_color(s.color), text=s.text
                    )
                    for s in e.shapes
                    if s.kind == "text"
                ],
            )
        )
    return SceneUpdate(entities=out)
