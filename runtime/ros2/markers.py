"""The site as ``visualization_msgs/MarkerArray`` for RViz 2 (map frame): walls, doors with their
state, tags, objects. Pure: site and state in, a message out. Shared by ``arroch ros2 bridge`` (live)
and the recorder's ROS 2 bags, so a bag shows the same markers and frames as the bridge.

Namespaces (``ns``) and ids are stable, so each publication replaces the last one in RViz:
``walls`` (grey boxes, one per wall segment, id = its index), ``doors`` (the leaf where it stands:
green open, red closed, blue outline for a door the human operates; id = the door's index in the
site), ``door_labels`` (text), ``tags`` (thin black squares at each landmark, id = the tag id),
``objects`` (0.2 m cubes in their robot's colour, faded once delivered; id = the object's index),
``robots`` (cylinders in their colour, id = the robot's index). Robots and carried objects are
frame-locked to ``<rid>/base_link`` (the bridge's tf), so RViz moves them with each transform and the
array needs publishing only when something else changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol.site.model import Site
from runtime.palette import robot_colors
from runtime.ros2 import types as ros

FLOOR_Z = 0.1  # object cubes rest on the floor (centre 0.1 m up)
CARRIED_Z = 0.45  # on a robot's top
ROBOT_HEIGHT = 0.35
MAP_FRAME = "map"


def robot_frame(robot: str) -> str:
    """A robot's base frame, child of the map frame on ``/tf`` (REP 105's ``base_link``, one per robot)."""
    return f"{robot}/base_link"


@dataclass
class SiteState:
    """What changes: doors open or not, where objects are (None: on their robot), delivered ones.

    The ``door``, ``carrying`` and ``delivered_at`` methods apply what the team's messages say and
    return whether the markers changed."""

    doors_open: dict[str, bool] = field(default_factory=dict)
    object_at: dict[str, tuple[float, float] | None] = field(default_factory=dict)
    carried_by: dict[str, str] = field(default_factory=dict)
    delivered: set[str] = field(default_factory=set)

    def door(self, door: str, is_open: bool) -> bool:
        """A DoorState: the door is open (or not) now."""
        if self.doors_open.get(door) == is_open:
            return False
        self.doors_open[door] = is_open
        return True

    def carrying(self, robot: str, objects: list[str], where: tuple[float, float]) -> bool:
        """A RobotStatus: ``robot`` carries ``objects`` now, standing at ``where``; what it carried
        before and no longer does was put down there."""
        changed = False
        for oid, rid in list(self.carried_by.items()):
            if rid == robot and oid not in objects:
                del self.carried_by[oid]
                self.object_at[oid] = where
                changed = True
        for oid in objects:
            if self.carried_by.get(oid) != robot:
                self.carried_by[oid] = robot
                changed = True
        return changed

    def delivered_at(self, obj: str, where: tuple[float, float] | None) -> bool:
        """A ``delivered`` Event: the object is at its destination (at ``where`` when known)."""
        self.delivered.add(obj)
        self.carried_by.pop(obj, None)
        if where is not None:
            self.object_at[obj] = where
        return True


def _color(r: float, g: float, b: float, a: float = 1.0) -> Any:
    return ros.t("std_msgs/msg/ColorRGBA")(r=r, g=g, b=b, a=a)


def marker(
    at: float,
    frame: str,
    ns: str,
    mid: int,
    kind: int,
    x: float,
    y: float,
    z: float,
    yaw: float,
    scale: tuple[float, float, float],
    color: Any,
    text: str = "",
    frame_locked: bool = False,
) -> Any:
    """One ADD marker with every field set (CDR has no optional fields)."""
    t = ros.t
    return t("visualization_msgs/msg/Marker")(
        header=ros.header(at, frame),
        ns=ns,
        id=mid,
        type=kind,
        action=0,
        pose=ros.pose(x, y, yaw, z),
        scale=ros.vector3(*scale),
        color=color,
        lifetime=t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=frame_locked,
        points=[],
        colors=[],
        texture_resource="",
        texture=t("sensor_msgs/msg/CompressedImage")(
            header=ros.header(0.0, ""), format="", data=np.zeros(0, dtype=np.uint8)
        ),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=t("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, dtype=np.uint8)),
        mesh_use_embedded_materials=False,
    )


def site_markers(site: Site, state: SiteState, at: float, frame: str = MAP_FRAME) -> Any:
    """The whole site as one MarkerArray."""
    cube, cylinder, text = 1, 3, 9
    out = []
    for i, wall in enumerate(site.walls):
        x0, y0, x1, y1 = wall.box
        out.append(
            marker(
                at,
                frame,
                "walls",
                i,
                cube,
                (x0 + x1) / 2,
                (y0 + y1) / 2,
                wall.height / 2,
                0.0,
                (x1 - x0, y1 - y0, wall.height),
                _color(0.6, 0.6, 0.6, 0.6),
            )
        )
    for i, (did, leaf) in enumerate(site.door_leaves.items()):
        is_open = state.doors_open.get(did, False)
        hx, hy = leaf.hinge
        yaw = leaf.open_yaw if is_open else leaf.closed_yaw
        cx, cy = hx + math.cos(yaw) * leaf.length / 2, hy + math.sin(yaw) * leaf.length / 2
        color = _color(0.1, 0.8, 0.2) if is_open else _color(0.9, 0.1, 0.1)
        out.append(marker(at, frame, "doors", i, cube, cx, cy, 1.04, yaw, (leaf.length, leaf.thickness, 2.08), color))
        label = f"{did} {'open' if is_open else 'closed'}{' (human)' if site.doors[did].human_operated else ''}"
        ox, oy = site.doors[did].center
        out.append(
            marker(at, frame, "door_labels", i, text, ox, oy, 2.3, 0.0, (0.0, 0.0, 0.25), _color(1, 1, 1), label)
        )
    for lm in site.landmarks:
        x, y, z = lm.position
        out.append(marker(at, frame, "tags", lm.tag, cube, x, y, z, lm.yaw, (0.005, lm.size, lm.size), _color(0, 0, 0)))
    colors = {rid: tuple(c / 255 for c in rgb) for rid, rgb in robot_colors(site.robots).items()}
    radius = site.params.robot_radius
    for i, rid in enumerate(sorted(site.robots)):
        r, g, b = colors[rid]
        out.append(
            marker(
                at,
                robot_frame(rid),
                "robots",
                i,
                cylinder,
                0.0,
                0.0,
                ROBOT_HEIGHT / 2,
                0.0,
                (2 * radius, 2 * radius, ROBOT_HEIGHT),
                _color(r, g, b),
                frame_locked=True,
            )
        )
    for i, (oid, spec) in enumerate(site.objects.items()):
        r, g, b = colors.get(spec.robot, (0.5, 0.5, 0.5))
        color = _color(0.7 * r, 0.7 * g, 0.7 * b, 0.4 if oid in state.delivered else 1.0)
        carrier = state.carried_by.get(oid)
        if carrier:
            out.append(
                marker(
                    at,
                    robot_frame(carrier),
                    "objects",
                    i,
                    cube,
                    0.0,
                    0.0,
                    CARRIED_Z,
                    0.0,
                    (0.2, 0.2, 0.2),
                    color,
                    frame_locked=True,
                )
            )
        else:
            x, y = state.object_at.get(oid) or spec.position
            out.append(marker(at, frame, "objects", i, cube, x, y, FLOOR_Z, 0.0, (0.2, 0.2, 0.2), color))
    return ros.t(ros.MARKER_ARRAY)(markers=out)
