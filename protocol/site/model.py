"""The site model: plain records for what a site file says and what follows from it.

Units are metres, seconds and radians. World frame: x east, y north, z up; yaw is
counter-clockwise from +x. Records are immutable; a :class:`Site` is built once by
:func:`protocol.site.load_site` and then only read.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the grid module imports this one
    from .grid import OccupancyGrid

Point = tuple[float, float]

# The official tag36h11 image is 10x10 cells: a 1-cell white border around the 8-cell black
# square. ``Landmark.size`` is the black square, so the printed image is 10/8 of it.
TAG_PRINT_SCALE = 10.0 / 8.0
TAG36H11_CODES = 587  # tag ids 0..586


@dataclass(frozen=True)
class Params:
    """Team and building parameters (``[params]``); every field is optional in the file."""

    robot_speed: float = 0.5  # m/s along a trajectory
    robot_radius: float = 0.25
    load_time: float = 10.0  # s to load or unload one object
    door_hold_time: float = 20.0  # s a door stays open after the human opens it
    robot_capacity: int = 1  # objects a robot carries at once
    wall_height: float = 2.5
    wall_thickness: float = 0.1


@dataclass(frozen=True)
class Room:
    """An axis-aligned rectangle ``rect = (xmin, ymin, xmax, ymax)``; its edges are wall centre lines."""

    id: str
    rect: tuple[float, float, float, float]

    def contains(self, x: float, y: float, margin: float = 0.0) -> bool:
        """True when (x, y) is inside the rectangle shrunk by ``margin`` on every side (edges count)."""
        x0, y0, x1, y1 = self.rect
        return x0 + margin <= x <= x1 - margin and y0 + margin <= y <= y1 - margin

    @property
    def center(self) -> Point:
        x0, y0, x1, y1 = self.rect
        return ((x0 + x1) / 2.0, (y0 + y1) / 2.0)

    @property
    def size(self) -> Point:
        """(width along x, depth along y)."""
        x0, y0, x1, y1 = self.rect
        return (x1 - x0, y1 - y0)


@dataclass(frozen=True)
class Opening:
    """A gap in the wall two rooms share: a ``door`` (with a leaf) or a ``passage`` (always open).

    ``axis`` is ``"x"`` when the opening lies on a wall running along x (a horizontal wall in a
    top-down view), else ``"y"``. ``normals`` holds, per room, the unit normal pointing into it.
    """

    id: str
    kind: str  # "door" | "passage"
    rooms: tuple[str, str]
    center: Point
    width: float
    human_operated: bool
    axis: str
    normals: tuple[tuple[str, Point], tuple[str, Point]] = field(repr=False)

    @property
    def endpoints(self) -> tuple[Point, Point]:
        """The gap's two ends on the wall centre line, lower coordinate first."""
        cx, cy = self.center
        h = self.width / 2.0
        # Rounded so derived walls and leaves print as the file's decimals (6.85, not 6.8500000000000005).
        if self.axis == "x":
            return ((round(cx - h, 9), cy), (round(cx + h, 9), cy))
        return ((cx, round(cy - h, 9)), (cx, round(cy + h, 9)))

    def other(self, room_id: str) -> str:
        """The room on the other side from ``room_id``."""
        a, b = self.rooms
        if room_id == a:
            return b
        if room_id == b:
            return a
        raise ValueError(f"opening {self.id!r} does not connect room {room_id!r} (it joins {a!r} and {b!r})")

    def normal_into(self, room_id: str) -> Point:
        """Unit normal of the wall at this opening, pointing into ``room_id``."""
        for rid, normal in self.normals:
            if rid == room_id:
                return normal
        raise ValueError(
            f"opening {self.id!r} does not connect room {room_id!r} (it joins {self.rooms[0]!r} and {self.rooms[1]!r})"
        )

    def beside(self, room_id: str, distance: float) -> Point:
        """The point ``distance`` metres in front of the opening's centre, on ``room_id``'s side."""
        nx, ny = self.normal_into(room_id)
        return (self.center[0] + nx * distance, self.center[1] + ny * distance)

    def aside(self, room_id: str, distance: float, lateral: float) -> Point:
        """The point ``beside(room_id, distance)`` moved ``lateral`` metres to the right of a robot
        that crosses from ``room_id``: where it waits to cross, off the lane of robots coming the
        other way (keep right)."""
        nx, ny = self.normal_into(room_id)  # the crossing goes along (-nx, -ny); its right is (-ny, nx)
        bx, by = self.beside(room_id, distance)
        return (bx - ny * lateral, by + nx * lateral)


@dataclass(frozen=True)
class Landmark:
    """An AprilTag 36h11 marker on a wall, for tablet localisation.

    ``position`` is the centre of the tag, ``yaw`` the direction its face points (its outward
    normal, horizontal), ``size`` the edge of the black square. The printed official image
    (black square plus its one-cell white border) is ``printed_size = size * 10/8``.
    """

    tag: int
    size: float
    position: tuple[float, float, float]
    yaw: float

    @property
    def normal(self) -> tuple[float, float, float]:
        return (math.cos(self.yaw), math.sin(self.yaw), 0.0)

    @property
    def printed_size(self) -> float:
        return self.size * TAG_PRINT_SCALE

    def corners(self, printed: bool = False) -> np.ndarray:
        """The tag's four corners in the world frame, shape (4, 3), rows TL, TR, BR, BL.

        Convention (DESIGN §3): the tag hangs upright on a vertical wall, the official
        ``tag36_11_<id>.png`` image's top row at the top (+z). Stand in front of it, looking at
        its face (along ``-normal``): TL is the top-left corner as you see it, then TR, BR, BL,
        clockwise in your view. With ``n = (cos yaw, sin yaw, 0)`` the viewer's right is
        ``r = (-sin yaw, cos yaw, 0)`` and up is ``u = (0, 0, 1)``; with ``h = size / 2``::

            TL = p + h(-r + u)   TR = p + h(r + u)   BR = p + h(r - u)   BL = p + h(-r - u)

        E.g. a tag on a south wall facing north (yaw = pi/2) has its TL at the west (-x), top.
        ``size`` is the black square's edge; ``printed=True`` gives the corners of the whole
        printed image (10/8 larger) instead, for drawing the tag.
        """
        h = (self.printed_size if printed else self.size) / 2.0
        p = np.asarray(self.position, dtype=float)
        r = np.array([-math.sin(self.yaw), math.cos(self.yaw), 0.0])
        u = np.array([0.0, 0.0, 1.0])
        return np.stack([p + h * (-r + u), p + h * (r + u), p + h * (r - u), p + h * (-r - u)])


@dataclass(frozen=True)
class RobotSpec:
    id: str
    start: tuple[float, float, float]  # x, y, theta
    room: str  # the room the start lies in


@dataclass(frozen=True)
class ObjectSpec:
    id: str
    position: Point
    deliver_to: str  # a room id
    robot: str  # the one robot that may carry it (tasks are non-transferable)
    room: str  # the room it starts in


@dataclass(frozen=True)
class HumanSpec:
    room: str
    position: Point


@dataclass(frozen=True)
class WallSegment:
    """A straight piece of wall between openings or corners.

    ``a``/``b`` are the ends of its centre line (lower coordinate first). ``box`` is the solid
    wall as an axis-aligned rectangle ``(xmin, ymin, xmax, ymax)``: ``thickness`` across, and
    along its length extended by ``thickness / 2`` at ends that meet another wall (so corners
    are filled) but not at an opening's jamb (so a gap keeps its full ``width``).
    """

    a: Point
    b: Point
    thickness: float
    height: float
    box: tuple[float, float, float, float]

    @property
    def axis(self) -> str:
        """``"x"`` for a wall running along x, else ``"y"``."""
        return "x" if self.a[1] == self.b[1] else "y"

    @property
    def length(self) -> float:
        return math.dist(self.a, self.b)


@dataclass(frozen=True)
class DoorLeaf:
    """A door's leaf: a slab of ``length`` × ``thickness`` turning about a vertical hinge.

    The hinge sits on the wall centre line at the gap's lower-coordinate end. The leaf runs from
    the hinge in direction ``closed_yaw`` (along the wall, filling the gap) when closed and
    ``open_yaw`` (the wall normal into ``swing_into``, 90° from closed) when open; it is centred
    on that line, ``thickness`` wide. ``length`` equals the door's width.
    """

    door: str
    hinge: Point
    length: float
    closed_yaw: float
    open_yaw: float
    swing_into: str
    thickness: float = 0.04

    def tip(self, open: bool = False) -> Point:
        """The free end of the leaf, closed or open."""
        yaw = self.open_yaw if open else self.closed_yaw
        return (self.hinge[0] + self.length * math.cos(yaw), self.hinge[1] + self.length * math.sin(yaw))

    def box(self, open: bool = False) -> tuple[float, float, float, float]:
        """The leaf's axis-aligned extent ``(xmin, ymin, xmax, ymax)`` closed or open (both are axis-aligned)."""
        (hx, hy), (tx, ty) = self.hinge, self.tip(open)
        h = self.thickness / 2.0
        if abs(hy - ty) < 1e-9:  # runs along x
            return (min(hx, tx), hy - h, max(hx, tx), hy + h)
        return (hx - h, min(hy, ty), hx + h, max(hy, ty))


@dataclass(eq=False)
class Site:
    """A loaded, validated site and the geometry every service derives from it."""

    name: str
    source: str
    params: Params
    rooms: dict[str, Room]
    openings: dict[str, Opening]
    landmarks: list[Landmark]
    robots: dict[str, RobotSpec]
    objects: dict[str, ObjectSpec]
    human: HumanSpec
    walls: list[WallSegment]
    door_leaves: dict[str, DoorLeaf]
    aliases: dict[str, str] = field(default_factory=dict)  # p_<b>_<a> -> p_<a>_<b>
    _grids: dict = field(default_factory=dict, repr=False)

    @property
    def doors(self) -> dict[str, Opening]:
        return {k: o for k, o in self.openings.items() if o.kind == "door"}

    @property
    def passages(self) -> dict[str, Opening]:
        return {k: o for k, o in self.openings.items() if o.kind == "passage"}

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """The rectangle around every room (wall centre lines)."""
        rects = [r.rect for r in self.rooms.values()]
        return (min(r[0] for r in rects), min(r[1] for r in rects), max(r[2] for r in rects), max(r[3] for r in rects))

    def opening(self, opening_id: str) -> Opening:
        """The door or passage ``opening_id``; a default passage id works with its rooms in either order."""
        key = self.aliases.get(opening_id, opening_id)
        try:
            return self.openings[key]
        except KeyError:
            raise KeyError(f"site {self.name!r} has no door or passage {opening_id!r}") from None

    def room_at(self, x: float, y: float) -> Room | None:
        """The room containing (x, y) (edges count; on a shared edge, the first in file order)."""
        for room in self.rooms.values():
            if room.contains(x, y):
                return room
        return None

    def neighbours(self, room_id: str) -> list[tuple[str, str]]:
        """``(opening_id, other_room_id)`` for every door and passage of ``room_id``, in file order."""
        if room_id not in self.rooms:
            raise KeyError(f"site {self.name!r} has no room {room_id!r}")
        return [(o.id, o.other(room_id)) for o in self.openings.values() if room_id in o.rooms]

    def occupancy_grid(
        self, resolution: float = 0.05, open_doors: Iterable[str] = (), inflate: float = 0.0
    ) -> OccupancyGrid:
        """A top-down grid of what a robot centre cannot occupy (see :mod:`protocol.site.grid`).

        Results are cached per arguments and read-only, so planners may call this freely.
        """
        from .grid import build_grid

        key = (float(resolution), frozenset(open_doors), float(inflate))
        grid = self._grids.get(key)
        if grid is None:
            grid = build_grid(self, resolution, key[1], inflate)
            self._grids[key] = grid
        return grid
