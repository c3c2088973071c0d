"""Geometry derived from rooms and openings: shared edges, wall segments, door leaves.

Rooms are axis-aligned rectangles whose edges are wall centre lines, so every computation
here works on horizontal and vertical lines and intervals along them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from .model import DoorLeaf, Opening, Point, Room, WallSegment

EPS = 1e-6  # coordinates closer than this are the same (site files use centimetres at best)


@dataclass(frozen=True)
class Edge:
    """A piece of a wall centre line: ``axis`` "x" is the line y = ``coord`` for x in [lo, hi]."""

    axis: str
    coord: float
    lo: float
    hi: float


def shared_edge(a: Room, b: Room) -> Edge | None:
    """The part of the boundary rooms ``a`` and ``b`` have in common (positive length), if any."""
    ax0, ay0, ax1, ay1 = a.rect
    bx0, by0, bx1, by1 = b.rect
    for y in ((ay1,) if abs(ay1 - by0) < EPS else ()) + ((ay0,) if abs(ay0 - by1) < EPS else ()):
        lo, hi = max(ax0, bx0), min(ax1, bx1)
        if hi - lo > EPS:
            return Edge("x", y, lo, hi)
    for x in ((ax1,) if abs(ax1 - bx0) < EPS else ()) + ((ax0,) if abs(ax0 - bx1) < EPS else ()):
        lo, hi = max(ay0, by0), min(ay1, by1)
        if hi - lo > EPS:
            return Edge("y", x, lo, hi)
    return None


def rooms_overlap(a: Room, b: Room) -> bool:
    """True when the rectangles share area (touching edges do not count)."""
    ax0, ay0, ax1, ay1 = a.rect
    bx0, by0, bx1, by1 = b.rect
    return min(ax1, bx1) - max(ax0, bx0) > EPS and min(ay1, by1) - max(ay0, by0) > EPS


def normal_into(room: Room, edge_axis: str, coord: float) -> Point:
    """Unit normal of the wall line (``edge_axis``, ``coord``) pointing into ``room``."""
    cx, cy = room.center
    if edge_axis == "x":
        return (0.0, 1.0) if cy > coord else (0.0, -1.0)
    return (1.0, 0.0) if cx > coord else (-1.0, 0.0)


def opening_interval(o: Opening) -> tuple[float, float]:
    """The gap along its wall line."""
    along = o.center[0] if o.axis == "x" else o.center[1]
    return (round(along - o.width / 2.0, 9), round(along + o.width / 2.0, 9))


def opening_line(o: Opening) -> tuple[str, float]:
    """The wall line an opening sits on, keyed like :func:`wall_lines` (coordinate rounded to 1 µm)."""
    return (o.axis, round(o.center[1] if o.axis == "x" else o.center[0], 6))


def _merge(intervals: Iterable[tuple[float, float]]) -> list[tuple[float, float]]:
    merged: list[list[float]] = []
    for lo, hi in sorted(intervals):
        if merged and lo <= merged[-1][1] + EPS:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return [(lo, hi) for lo, hi in merged]


def _subtract(pieces: list[tuple[float, float]], gaps: list[tuple[float, float]]) -> list[tuple[float, float]]:
    for glo, ghi in gaps:
        out: list[tuple[float, float]] = []
        for lo, hi in pieces:
            if ghi <= lo + EPS or glo >= hi - EPS:
                out.append((lo, hi))
                continue
            if glo - lo > EPS:
                out.append((lo, glo))
            if hi - ghi > EPS:
                out.append((ghi, hi))
        pieces = out
    return pieces


def wall_lines(rooms: Iterable[Room]) -> dict[tuple[str, float], list[tuple[float, float]]]:
    """Every room edge, grouped by line and merged, so a shared edge counts once."""
    raw: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for room in rooms:
        x0, y0, x1, y1 = room.rect
        for axis, coord, lo, hi in (("x", y0, x0, x1), ("x", y1, x0, x1), ("y", x0, y0, y1), ("y", x1, y0, y1)):
            raw.setdefault((axis, round(coord, 6)), []).append((lo, hi))
    return {line: _merge(iv) for line, iv in sorted(raw.items())}


def build_walls(
    rooms: Iterable[Room], openings: Iterable[Opening], thickness: float, height: float
) -> list[WallSegment]:
    """Wall segments: every room edge, shared edges once, with each opening's gap cut out."""
    gaps: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for o in openings:
        gaps.setdefault(opening_line(o), []).append(opening_interval(o))
    half = thickness / 2.0
    walls: list[WallSegment] = []
    for (axis, coord), merged in wall_lines(rooms).items():
        line_gaps = sorted(gaps.get((axis, coord), []))
        jambs = [end for gap in line_gaps for end in gap]
        for lo, hi in _subtract(merged, line_gaps):
            # Extend into corners and junctions, but never into a gap.
            ext_lo = 0.0 if any(abs(lo - j) < EPS for j in jambs) else half
            ext_hi = 0.0 if any(abs(hi - j) < EPS for j in jambs) else half
            if axis == "x":
                a, b = (lo, coord), (hi, coord)
                box = (lo - ext_lo, coord - half, hi + ext_hi, coord + half)
            else:
                a, b = (coord, lo), (coord, hi)
                box = (coord - half, lo - ext_lo, coord + half, hi + ext_hi)
            walls.append(WallSegment(a=a, b=b, thickness=thickness, height=height, box=box))
    return walls


def swing_room(door: Opening, explicit: str | None, human_room: str | None) -> str:
    """Which room a door's leaf swings into.

    An explicit ``swing_into`` wins; a human-operated door swings into the human's room when it
    is one of the door's rooms (she pulls it open towards herself); any other door swings
    into the second room listed in ``rooms`` (the room you enter coming from the first).
    """
    if explicit is not None:
        return explicit
    if door.human_operated and human_room in door.rooms:
        return human_room  # type: ignore[return-value]
    return door.rooms[1]


def build_leaf(door: Opening, into: str) -> DoorLeaf:
    """The leaf of ``door``, hinged at the gap's lower-coordinate end, swinging into ``into``."""
    nx, ny = door.normal_into(into)
    return DoorLeaf(
        door=door.id,
        hinge=door.endpoints[0],
        length=door.width,
        closed_yaw=0.0 if door.axis == "x" else math.pi / 2.0,
        open_yaw=math.atan2(ny, nx),
        swing_into=into,
    )


def in_swing(leaf: DoorLeaf, x: float, y: float, clearance: float = 0.0) -> bool:
    """True when a disc of radius ``clearance`` at (x, y) meets the quarter disc the leaf sweeps."""
    vx, vy = x - leaf.hinge[0], y - leaf.hinge[1]
    along = vx * math.cos(leaf.closed_yaw) + vy * math.sin(leaf.closed_yaw)
    across = vx * math.cos(leaf.open_yaw) + vy * math.sin(leaf.open_yaw)
    return along > -clearance and across > -clearance and math.hypot(vx, vy) < leaf.length + clearance


def box_distance(box: tuple[float, float, float, float], x: float, y: float) -> float:
    """Distance from (x, y) to an axis-aligned box (0 inside)."""
    x0, y0, x1, y1 = box
    dx = max(x0 - x, 0.0, x - x1)
    dy = max(y0 - y, 0.0, y - y1)
    return math.hypot(dx, dy)
