"""Placing wall landmarks in a room so a tablet anywhere in it sees at least two.

The guarantee is for a level tablet camera at ``camera_height`` whose centre is at least
``min_wall_distance`` from every wall face of the room, looking straight at any of the four
walls, with a ``vfov_deg`` vertical field of view at ``aspect`` (width/height). Facing a wall
from distance ``d`` the camera sees the strip ``x ± d·tan(hfov/2)`` of it, narrowest at the
minimum distance; so along each wall the placement sweeps that narrowest window over every
camera position and, wherever fewer than two black squares lie fully inside it, adds the
right-most tag that fits (printed images never overlap, never cover an opening or an open
door leaf, never pass a corner). Heights alternate between ``heights`` along each wall.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from protocol.site.model import TAG_PRINT_SCALE, DoorLeaf, Opening, Room

FACE_OFFSET = 0.001  # tags hang this far in front of the wall face, so a renderer sees them
STEP = 0.005  # sweep and candidate resolution along a wall (metres)
WINDOW_MARGIN = 0.01  # keep black squares this far inside the view window
CLEARANCE = 0.01  # between printed tags, and from jambs and open leaves


@dataclass(frozen=True)
class ViewSpec:
    camera_height: float = 1.3
    min_wall_distance: float = 0.7  # from the wall face
    vfov_deg: float = 60.0
    aspect: float = 4.0 / 3.0

    @property
    def tan_half_h(self) -> float:
        return self.aspect * math.tan(math.radians(self.vfov_deg) / 2.0)

    @property
    def tan_half_v(self) -> float:
        return math.tan(math.radians(self.vfov_deg) / 2.0)


@dataclass(frozen=True)
class _Wall:
    """One wall of a room seen from inside: the face line and the direction the tags face."""

    axis: str  # "x": a wall along x (y = coord)
    coord: float  # centre line
    face_lo: float  # the face's extent along the wall, between the side walls' faces
    face_hi: float
    normal: tuple[int, int]  # into the room


def _walls(room: Room, thickness: float) -> list[_Wall]:
    x0, y0, x1, y1 = room.rect
    h = thickness / 2.0
    return [
        _Wall("x", y0, x0 + h, x1 - h, (0, 1)),  # south wall, tags face north
        _Wall("y", x1, y0 + h, y1 - h, (-1, 0)),  # east wall, tags face west
        _Wall("x", y1, x0 + h, x1 - h, (0, -1)),  # north wall, tags face south
        _Wall("y", x0, y0 + h, y1 - h, (1, 0)),  # west wall, tags face east
    ]


def _blocked(
    wall: _Wall, openings: Iterable[Opening], leaves: Iterable[DoorLeaf], thickness: float
) -> list[tuple[float, float]]:
    """Intervals along the wall where no printed tag may go: openings' gaps and open leaves."""
    blocked = []
    for o in openings:
        on_line = o.axis == wall.axis and abs((o.center[1] if o.axis == "x" else o.center[0]) - wall.coord) < 1e-6
        if on_line:
            along = o.center[0] if o.axis == "x" else o.center[1]
            blocked.append((along - o.width / 2.0, along + o.width / 2.0))
    face = wall.coord + (wall.normal[1] if wall.axis == "x" else wall.normal[0]) * (thickness / 2.0 + FACE_OFFSET)
    for leaf in leaves:
        bx0, by0, bx1, by1 = leaf.box(open=True)
        lo, hi, across_lo, across_hi = (bx0, bx1, by0, by1) if wall.axis == "x" else (by0, by1, bx0, bx1)
        if across_lo - CLEARANCE <= face <= across_hi + CLEARANCE:
            blocked.append((lo, hi))
    return blocked


def _place_on_wall(wall: _Wall, blocked: list[tuple[float, float]], size: float, view: ViewSpec) -> list[float]:
    """Tag centres along one wall (see the module docstring for the rule).

    The greedy sweep can paint itself into a corner next to an obstacle at the far end, so it
    runs both ways and keeps the result with fewer tags.
    """
    results = []
    for mirrored in (False, True):
        w, b = wall, blocked
        if mirrored:
            w = _Wall(wall.axis, wall.coord, -wall.face_hi, -wall.face_lo, wall.normal)
            b = [(-hi, -lo) for lo, hi in blocked]
        try:
            centres = _sweep(w, b, size, view)
        except ValueError as exc:
            error = exc
            continue
        results.append(sorted(-c for c in centres) if mirrored else centres)
    if not results:
        raise error
    return min(results, key=len)


def _sweep(wall: _Wall, blocked: list[tuple[float, float]], size: float, view: ViewSpec) -> list[float]:
    """One greedy sweep from low to high coordinates along the wall."""
    printed = size * TAG_PRINT_SCALE
    half_black, half_printed = size / 2.0, printed / 2.0

    def free(c: float) -> bool:
        lo, hi = c - half_printed, c + half_printed
        if lo < wall.face_lo or hi > wall.face_hi:
            return False
        return all(hi + CLEARANCE <= blo or lo - CLEARANCE >= bhi for blo, bhi in blocked)

    n = int((wall.face_hi - wall.face_lo) / STEP) + 1
    candidates = [c for c in (wall.face_lo + i * STEP for i in range(n)) if free(c)]
    half_window = view.min_wall_distance * view.tan_half_h - WINDOW_MARGIN
    cam_lo, cam_hi = wall.face_lo + view.min_wall_distance, wall.face_hi - view.min_wall_distance
    chosen: list[float] = []

    def inside(c: float, x: float) -> bool:
        return x - half_window <= c - half_black and c + half_black <= x + half_window

    x = cam_lo
    while x <= cam_hi + 1e-9:
        while sum(inside(c, x) for c in chosen) < 2:
            fits = [c for c in candidates if inside(c, x) and all(abs(c - o) >= printed + CLEARANCE for o in chosen)]
            if not fits:
                raise ValueError(
                    f"no room for two tags in view of a camera at {x:.2f} m along the wall {wall.axis} = {wall.coord:g}"
                )
            chosen.append(max(fits))
        x += STEP
    return sorted(chosen)


def place_room_tags(
    room: Room,
    openings: Iterable[Opening],
    leaves: Iterable[DoorLeaf],
    thickness: float,
    size: float = 0.16,
    first_tag: int = 0,
    heights: tuple[float, float] = (1.25, 1.45),
    view: ViewSpec = ViewSpec(),
) -> list[dict]:
    """Landmark entries (``tag``, ``size``, ``position``, ``yaw``) for the walls of ``room``.

    ``openings`` and ``leaves`` are the room's doors and passages and the leaves swinging into
    it. Raises ``ValueError`` when a wall leaves no room for the guarantee.
    """
    reach = view.min_wall_distance * view.tan_half_v
    for z in heights:
        if z - size / 2.0 < view.camera_height - reach or z + size / 2.0 > view.camera_height + reach:
            raise ValueError(
                f"tags at {z:g} m are out of the vertical view "
                f"({view.camera_height - reach:.2f}..{view.camera_height + reach:.2f} m)"
            )
    openings, leaves = list(openings), list(leaves)
    out: list[dict] = []
    tag = first_tag
    for wall in _walls(room, thickness):
        nx, ny = wall.normal
        across = wall.coord + (ny if wall.axis == "x" else nx) * (thickness / 2.0 + FACE_OFFSET)
        yaw = round(math.atan2(ny, nx), 6)
        for i, along in enumerate(_place_on_wall(wall, _blocked(wall, openings, leaves, thickness), size, view)):
            x, y = (along, across) if wall.axis == "x" else (across, along)
            out.append({"tag": tag, "size": size, "position": [round(x, 4), round(y, 4), heights[i % 2]], "yaw": yaw})
            tag += 1
    return out
