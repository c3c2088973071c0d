"""Building a :class:`Site` from checked entries, refusing worlds that cannot work.

The format (types, keys) is already checked by :mod:`protocol.site.fileformat`; here the values
are checked against each other, in this order, and the first problem is raised as a
:class:`SiteError` naming the entry: duplicate ids and tag ids; overlapping rooms; doors and
passages off the edge their two rooms share (or too close to its end, too narrow for a robot,
overlapping another opening, a leaf that does not fit its room); landmarks not on a wall;
robots and objects outside every room, in a wall, too close to one, or in a door's swing;
objects for unknown rooms or robots; the human outside her room; rooms no robot can reach.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from .errors import SiteError
from .fileformat import Entry, params_from
from .geometry import (
    EPS,
    box_distance,
    build_leaf,
    build_walls,
    in_swing,
    normal_into,
    opening_interval,
    opening_line,
    rooms_overlap,
    shared_edge,
    swing_room,
    wall_lines,
)
from .model import DoorLeaf, HumanSpec, Landmark, ObjectSpec, Opening, Params, RobotSpec, Room, Site

YAW_TOLERANCE = math.radians(2.0)  # how far off perpendicular a landmark's yaw may be
LANDMARK_OFFSET_MAX = 0.1  # a landmark must be within this of a wall centre line (metres)


def _fmt(*values: float) -> str:
    return "(" + ", ".join(f"{v:g}" for v in values) + ")"


def _edge_text(axis: str, coord: float, lo: float, hi: float) -> str:
    return f"y = {coord:g} for x in [{lo:g}, {hi:g}]" if axis == "x" else f"x = {coord:g} for y in [{lo:g}, {hi:g}]"


class _Builder:
    def __init__(self, doc: dict[str, Any], file: str, source: str) -> None:
        self.doc = doc
        self.file = file
        self.source = source
        self.params: Params = params_from(doc["params"])
        self.labels: dict[str, str] = {}  # id -> entry label, for "already used by ..."

    def fail(self, entry: Entry | str, problem: str) -> SiteError:
        return SiteError(self.file, entry.label if isinstance(entry, Entry) else entry, problem)

    # --- ids --------------------------------------------------------------------------------------

    def passage_ids(self) -> None:
        """Give passages without an id their default ``p_<roomA>_<roomB>``."""
        for e in self.doc["passages"]:
            if e["id"] is None:
                a, b = e["rooms"]
                e.values["id"] = f"p_{a}_{b}"
                e.label += f' (id "{e["id"]}")'

    def unique_ids(self) -> None:
        for kind in ("rooms", "doors", "passages", "robots", "objects"):
            for e in self.doc[kind]:
                if e["id"] in self.labels:
                    raise self.fail(e, f'id "{e["id"]}" is already used by {self.labels[e["id"]]}')
                self.labels[e["id"]] = e.label
        tags: dict[int, str] = {}
        for e in self.doc["landmarks"]:
            if e["tag"] in tags:
                raise self.fail(e, f"tag id {e['tag']} is already used by {tags[e['tag']]}")
            tags[e["tag"]] = e.label

    # --- rooms and openings -----------------------------------------------------------------------

    def rooms(self) -> dict[str, Room]:
        rooms: dict[str, Room] = {}
        entries = self.doc["rooms"]
        for e in entries:
            room = Room(e["id"], e["rect"])
            for other_entry in entries:
                other = rooms.get(other_entry["id"])
                if other is not None and rooms_overlap(room, other):
                    raise self.fail(e, f"rect {_fmt(*room.rect)} overlaps {other_entry.label} rect {_fmt(*other.rect)}")
            rooms[room.id] = room
        return rooms

    def room_ref(self, e: Entry, key: str, room_id: str, rooms: dict[str, Room]) -> Room:
        if room_id not in rooms:
            raise self.fail(e, f'{key}: unknown room "{room_id}" (rooms are {", ".join(rooms)})')
        return rooms[room_id]

    def opening(self, e: Entry, kind: str, rooms: dict[str, Room]) -> Opening:
        a_id, b_id = e["rooms"]
        a = self.room_ref(e, "rooms", a_id, rooms)
        b = self.room_ref(e, "rooms", b_id, rooms)
        cx, cy = e["center"]
        width = e["width"]
        where = f'is not on an edge shared by rooms "{a_id}" and "{b_id}"'
        edge = shared_edge(a, b)
        if edge is None:
            raise self.fail(e, f"center {_fmt(cx, cy)} {where} (they share no wall)")
        along, across = (cx, cy) if edge.axis == "x" else (cy, cx)
        if abs(across - edge.coord) > EPS or not edge.lo - EPS <= along <= edge.hi + EPS:
            raise self.fail(
                e,
                f"center {_fmt(cx, cy)} {where} (their shared edge is "
                f"{_edge_text(edge.axis, edge.coord, edge.lo, edge.hi)})",
            )
        lo, hi = along - width / 2.0, along + width / 2.0
        if lo < edge.lo - EPS or hi > edge.hi + EPS:
            raise self.fail(
                e,
                f'width {width:g} at center {_fmt(cx, cy)} does not fit on the edge shared by rooms "{a_id}" and '
                f'"{b_id}" '
                f"({_edge_text(edge.axis, edge.coord, edge.lo, edge.hi)}): its whole width must lie on it",
            )
        half = self.params.wall_thickness / 2.0
        if lo < edge.lo + half - EPS or hi > edge.hi - half + EPS:
            raise self.fail(
                e,
                f"the gap [{lo:g}, {hi:g}] must stay {half:g} m (half a wall) from the ends of the shared edge "
                f"({_edge_text(edge.axis, edge.coord, edge.lo, edge.hi)}), where another wall meets it",
            )
        needed = 2.0 * self.params.robot_radius
        if width <= needed:
            raise self.fail(
                e,
                f"width {width:g} is too narrow for a robot of radius {self.params.robot_radius:g} (needs more than "
                f"{needed:g})",
            )
        normals = ((a_id, normal_into(a, edge.axis, edge.coord)), (b_id, normal_into(b, edge.axis, edge.coord)))
        return Opening(
            id=e["id"],
            kind=kind,
            rooms=(a_id, b_id),
            center=(cx, cy),
            width=width,
            human_operated=bool(e.values.get("human_operated") or False),
            axis=edge.axis,
            normals=normals,
        )

    def openings(self, rooms: dict[str, Room]) -> tuple[dict[str, Opening], dict[str, Entry]]:
        openings: dict[str, Opening] = {}
        entries: dict[str, Entry] = {}
        for kind, key in (("door", "doors"), ("passage", "passages")):
            for e in self.doc[key]:
                o = self.opening(e, kind, rooms)
                lo, hi = opening_interval(o)
                for other in openings.values():
                    olo, ohi = opening_interval(other)
                    if opening_line(other) == opening_line(o) and min(hi, ohi) - max(lo, olo) > -EPS:
                        raise self.fail(
                            e,
                            f"its gap [{lo:g}, {hi:g}] overlaps or touches {entries[other.id].label} [{olo:g}, "
                            f"{ohi:g}] on the same wall",
                        )
                openings[o.id] = o
                entries[o.id] = e
        return openings, entries

    def aliases(self, openings: dict[str, Opening]) -> dict[str, str]:
        aliases: dict[str, str] = {}
        for o in openings.values():
            a, b = o.rooms
            if o.kind == "passage" and o.id == f"p_{a}_{b}" and f"p_{b}_{a}" not in self.labels:
                aliases[f"p_{b}_{a}"] = o.id
        return aliases

    def leaves(
        self, openings: dict[str, Opening], entries: dict[str, Entry], rooms: dict[str, Room]
    ) -> dict[str, DoorLeaf]:
        human_room = self.doc["human"]["room"]
        leaves: dict[str, DoorLeaf] = {}
        for o in openings.values():
            if o.kind != "door":
                continue
            e = entries[o.id]
            explicit = e["swing_into"]
            if explicit is not None and explicit not in o.rooms:
                raise self.fail(
                    e, f'swing_into: "{explicit}" is not one of the door\'s rooms ("{o.rooms[0]}", "{o.rooms[1]}")'
                )
            leaf = build_leaf(o, swing_room(o, explicit, human_room))
            room = rooms[leaf.swing_into]
            depth = room.size[1] if o.axis == "x" else room.size[0]
            if leaf.length > depth - self.params.wall_thickness / 2.0 + EPS:
                raise self.fail(
                    e, f'its leaf ({leaf.length:g} m) does not fit in room "{room.id}" (depth {depth:g} m) when open'
                )
            leaves[o.id] = leaf
        return leaves

    # --- landmarks --------------------------------------------------------------------------------

    def landmark(
        self,
        e: Entry,
        rooms: dict[str, Room],
        lines: dict,
        openings: dict[str, Opening],
        opening_entries: dict[str, Entry],
        leaves: dict[str, DoorLeaf],
    ) -> Landmark:
        lm = Landmark(tag=e["tag"], size=e["size"], position=e["position"], yaw=e["yaw"])
        t = self.params.wall_thickness
        quarter = round(lm.yaw / (math.pi / 2.0))
        if abs(lm.yaw - quarter * math.pi / 2.0) > YAW_TOLERANCE:
            raise self.fail(
                e, f"yaw {lm.yaw:g} is not perpendicular to any wall (walls run along x or y: use a multiple of pi/2)"
            )
        nx, ny = round(math.cos(quarter * math.pi / 2.0)), round(math.sin(quarter * math.pi / 2.0))
        axis = "y" if nx else "x"  # the wall the tag hangs on runs perpendicular to its normal
        sign = nx or ny
        px, py, pz = lm.position
        along, across = (py, px) if axis == "y" else (px, py)
        max_offset = max(LANDMARK_OFFSET_MAX, t / 2.0 + 0.05)
        front = sorted(
            ((across - coord) * sign, coord)
            for (ax, coord) in lines
            if ax == axis and 0.0 <= (across - coord) * sign <= max_offset + EPS
        )
        if not front:
            behind = [coord for (ax, coord) in lines if ax == axis and -max_offset <= (across - coord) * sign < 0.0]
            name = "x" if axis == "y" else "y"
            if behind:
                raise self.fail(
                    e,
                    f"faces into the wall at {name} = {behind[0]:g} (yaw {lm.yaw:g} points away from the room it "
                    "should face)",
                )
            nearest = min((abs(across - coord), coord) for (ax, coord) in lines if ax == axis)
            raise self.fail(
                e,
                f"position {_fmt(px, py, pz)} is not on a wall: the nearest wall parallel to its face ({name} = "
                f"{nearest[1]:g}) "
                f"is {nearest[0]:.3g} m away; a tag must be within {max_offset:g} m of a wall's centre line, on the "
                "side it faces",
            )
        _, coord = front[0]
        half = lm.printed_size / 2.0
        lo, hi = along - half, along + half
        for o in openings.values():
            if opening_line(o) == (axis, coord):
                glo, ghi = opening_interval(o)
                if min(hi, ghi) - max(lo, glo) > EPS:
                    raise self.fail(
                        e,
                        f"is over {opening_entries[o.id].label}: the printed tag spans [{lo:g}, {hi:g}], the gap "
                        f"[{glo:g}, {ghi:g}]",
                    )
        if not any(ilo - EPS <= lo and hi <= ihi + EPS for ilo, ihi in lines[(axis, coord)]):
            raise self.fail(e, f"extends past the end of the wall (the printed tag spans [{lo:g}, {hi:g}])")
        ahead = t / 2.0 + 0.05
        facing = next((r for r in rooms.values() if r.contains(px + nx * ahead, py + ny * ahead)), None)
        if facing is None:
            raise self.fail(e, "faces no room (in front of it is outside the building)")
        x0, y0, x1, y1 = facing.rect
        flo, fhi = (y0, y1) if axis == "y" else (x0, x1)
        if lo < flo + t / 2.0 - EPS or hi > fhi - t / 2.0 + EPS:
            raise self.fail(
                e,
                f'extends past the corner of room "{facing.id}": the printed tag spans [{lo:g}, {hi:g}], '
                f"the wall face [{flo + t / 2.0:g}, {fhi - t / 2.0:g}]",
            )
        for leaf in leaves.values():
            bx0, by0, bx1, by1 = leaf.box(open=True)
            llo, lhi, alo, ahi = (by0, by1, bx0, bx1) if axis == "y" else (bx0, bx1, by0, by1)
            if alo - EPS <= across <= ahi + EPS and min(hi, lhi) - max(lo, llo) > EPS:
                raise self.fail(
                    e,
                    f'is covered by door "{leaf.door}"\'s leaf when it is open (the leaf spans [{llo:g}, {lhi:g}] '
                    "along this wall)",
                )
        if pz - half < 0.0 or pz + half > self.params.wall_height + EPS:
            raise self.fail(
                e,
                f"height z = {pz:g} puts the printed tag at [{pz - half:g}, {pz + half:g}] m, "
                f"not within the wall (0 to {self.params.wall_height:g} m)",
            )
        return lm

    # --- things in rooms --------------------------------------------------------------------------

    def placed(
        self,
        e: Entry,
        key: str,
        x: float,
        y: float,
        rooms: dict[str, Room],
        walls: list,
        leaves: dict[str, DoorLeaf],
        clearance: float,
        what: str,
    ) -> Room:
        """The room a robot or object at (x, y) lies in, refusing walls, their surroundings and door swings."""
        room = next((r for r in rooms.values() if r.contains(x, y)), None)
        if room is None:
            raise self.fail(e, f"{key} {_fmt(x, y)} is outside every room")
        gap = min(box_distance(w.box, x, y) for w in walls)
        if gap <= EPS:
            raise self.fail(e, f"{key} {_fmt(x, y)} is inside a wall")
        if gap < clearance - EPS:
            raise self.fail(
                e, f"{key} {_fmt(x, y)} is {gap:.3g} m from a wall; {what} needs {clearance:g} m (the robot radius)"
            )
        for leaf in leaves.values():
            if in_swing(leaf, x, y, clearance):
                raise self.fail(
                    e,
                    f'{key} {_fmt(x, y)} is where door "{leaf.door}"\'s leaf swings (hinge {_fmt(*leaf.hinge)}, length '
                    f"{leaf.length:g})",
                )
        return room

    def robots(self, rooms: dict[str, Room], walls: list, leaves: dict[str, DoorLeaf]) -> dict[str, RobotSpec]:
        r = self.params.robot_radius
        robots: dict[str, RobotSpec] = {}
        for e in self.doc["robots"]:
            x, y, theta = e["start"]
            room = self.placed(e, "start", x, y, rooms, walls, leaves, r, "a robot")
            for other in robots.values():
                if math.dist((x, y), other.start[:2]) < 2.0 * r - EPS:
                    raise self.fail(
                        e,
                        f'start {_fmt(x, y)} overlaps robot "{other.id}" at {_fmt(*other.start[:2])} (robots are '
                        f"{2 * r:g} m wide)",
                    )
            robots[e["id"]] = RobotSpec(id=e["id"], start=(x, y, theta), room=room.id)
        return robots

    def objects(
        self, rooms: dict[str, Room], robots: dict[str, RobotSpec], walls: list, leaves: dict[str, DoorLeaf]
    ) -> dict[str, ObjectSpec]:
        objects: dict[str, ObjectSpec] = {}
        for e in self.doc["objects"]:
            self.room_ref(e, "deliver_to", e["deliver_to"], rooms)
            if e["robot"] not in robots:
                raise self.fail(e, f'robot: unknown robot "{e["robot"]}" (robots are {", ".join(robots)})')
            x, y = e["position"]
            room = self.placed(
                e, "position", x, y, rooms, walls, leaves, self.params.robot_radius, "a robot reaching it"
            )
            objects[e["id"]] = ObjectSpec(
                id=e["id"], position=(x, y), deliver_to=e["deliver_to"], robot=e["robot"], room=room.id
            )
        return objects

    def human(self, rooms: dict[str, Room]) -> HumanSpec:
        e = self.doc["human"]
        room = self.room_ref(e, "room", e["room"], rooms)
        x, y = e["position"]
        if not room.contains(x, y, margin=self.params.wall_thickness / 2.0):
            raise self.fail(
                e, f'position {_fmt(x, y)} is outside her room "{room.id}" {_fmt(*room.rect)} (or inside its walls)'
            )
        return HumanSpec(room=room.id, position=(x, y))

    def reachable(self, rooms: dict[str, Room], openings: dict[str, Opening], robots: dict[str, RobotSpec]) -> None:
        seen = {r.room for r in robots.values()}
        todo = deque(seen)
        while todo:
            here = todo.popleft()
            for o in openings.values():
                if here in o.rooms and o.other(here) not in seen:
                    seen.add(o.other(here))
                    todo.append(o.other(here))
        for e in self.doc["rooms"]:
            if e["id"] not in seen:
                starts = ", ".join(sorted({r.room for r in robots.values()}))
                raise self.fail(e, f"is not reachable from the robots' rooms ({starts}) through any door or passage")

    # --- all together ------------------------------------------------------------------------------

    def build(self) -> Site:
        self.passage_ids()
        self.unique_ids()
        rooms = self.rooms()
        openings, opening_entries = self.openings(rooms)
        walls = build_walls(rooms.values(), openings.values(), self.params.wall_thickness, self.params.wall_height)
        leaves = self.leaves(openings, opening_entries, rooms)
        lines = wall_lines(rooms.values())
        landmarks = [self.landmark(e, rooms, lines, openings, opening_entries, leaves) for e in self.doc["landmarks"]]
        robots = self.robots(rooms, walls, leaves)
        objects = self.objects(rooms, robots, walls, leaves)
        human = self.human(rooms)
        self.reachable(rooms, openings, robots)
        return Site(
            name=self.doc["site"]["name"],
            source=self.source,
            params=self.params,
            rooms=rooms,
            openings=openings,
            landmarks=landmarks,
            robots=robots,
            objects=objects,
            human=human,
            walls=walls,
            door_leaves=leaves,
            aliases=self.aliases(openings),
        )


def build_site(doc: dict[str, Any], file: str, source: str) -> Site:
    """Validate checked entries against each other and build the site (first problem raises)."""
    return _Builder(doc, file, source).build()
