"""Where robots stand in a site: in front of an opening, waiting to cross it, queueing at it, at an
object and at a drop slot. Every point is a free cell of the motion planner's grid (snapped), and is
cached: it depends on the site only.

Keep right: a robot waits to cross an opening beside it, to the right of the lane through the gap
(:meth:`KeyPoints.wait_point`), and a gothrough ends on the lane on the far side
(:meth:`KeyPoints.beside`), so a robot coming through passes one waiting to go the other way. More
robots waiting at one side queue in a line along the wall (:meth:`KeyPoints.queue_spots`; the
dispatcher sends each to the first free one), with a spot for every robot of the site where the wall
is long enough, none in another opening's lane and none where it leaves no way past it. Each robot
unloads at its own slot in the destination room (:meth:`KeyPoints.drop_point`), so a robot that has
finished and stays there is under nobody's slot.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

from protocol.site import Opening, Site
from runtime.executor.doorways import in_lane

from .motion import MotionPlanner, Point

BESIDE_MARGIN = 0.35  # m between the robot's edge and the wall when standing beside an opening
# m, beyond two radii, between the lane through an opening and a robot waiting to cross it: a robot
# coming through the other way passes it (keep right, Opening.aside)
WAIT_CLEARANCE = 0.15
WAIT_BESIDE_GAP = 0.2  # m beyond a wide gap's half-width (a crossing robot holds the lane in front of the gap)
QUEUE_SPACING = 0.65  # m between the spots where robots queue at an opening (two radii and a margin)
# spots per side of an opening, at least; as many as the site has robots where there is room (with
# six, the seventh robot to queue was sent to the sixth's spot and twelve robots jammed a corridor)
QUEUE_LENGTH = 6
QUEUE_COLUMNS = 3  # how far along the wall the line may run: this many spots' lengths per spot wanted
# m of the room left between a queued robot and the far wall beyond two radii: a robot gets past it
PASSING_ROOM = 0.3
KEEP_CLEAR = 1.0  # m between a drop point and the points beside an opening
HUMAN_CLEAR = 0.8  # m between a drop point and where the human works
DROP_SPACING = 1.3  # m between drop points in a destination room: a robot passes between two robots parked at them


def wait_offset(robot_radius: float, width: float) -> float:
    """How far to the right of an opening's centre line a robot waits to cross it
    (ProblemBuilder.wait_point): clear of a robot coming through, and beside the gap."""
    return max(2.0 * robot_radius + WAIT_CLEARANCE, width / 2.0 + WAIT_BESIDE_GAP)


@dataclass
class KeyPoints:
    """The key points of one site (ProblemBuilder adds the legs between them)."""

    site: Site
    motion: MotionPlanner
    _beside: dict[tuple[str, str, float], Point] = field(default_factory=dict)
    _drop: dict[str, Point] = field(default_factory=dict)
    _queues: dict[tuple[str, str, str], list[Point]] = field(default_factory=dict)
    _object: dict[str, Point] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.params = self.site.params
        self.beside_distance = self.params.robot_radius + BESIDE_MARGIN

    def beside(self, opening: str, room: str) -> Point:
        """The point in front of ``opening`` on ``room``'s side, on its lane: where a gothrough into
        ``room`` ends."""
        return self._key_point(opening, room, 0.0)

    def wait_point(self, opening: str, room: str) -> Point:
        """Where a robot in ``room`` approaches to and waits to cross ``opening``: beside it, to the
        right of the lane, so robots coming through the other way pass it."""
        return self._key_point(opening, room, self._wait_offset(opening))

    def queue_spots(self, opening: str, room: str) -> list[Point]:
        """Where robots in ``room`` wait to cross ``opening``, first to last: its wait point, then
        further along the wall to the right of the lane and back from it, each QUEUE_SPACING from
        the others, no robot's disc in another opening's lane, and room left to pass a queued robot;
        robots queueing at a door do not stand in a heap, in a doorway's way or across a corridor."""
        key = ("queue", opening, room)
        spots = self._queues.get(key)
        if spots is None:
            first = self.wait_point(opening, room)
            spots = [first]
            side = self.site.opening(opening)
            wanted = max(QUEUE_LENGTH, len(self.site.robots))
            radius = self.params.robot_radius
            others = [o for o in self.site.openings.values() if o.id != opening]
            # a line along the wall (a block of spots would stand in the way into the room), then
            # a second line where the wall is short
            for row, col in itertools.product(range(2), range(QUEUE_COLUMNS * wanted)):
                if (row, col) == (0, 0):
                    continue
                lateral = self._wait_offset(opening) + col * QUEUE_SPACING
                distance = self.beside_distance + row * QUEUE_SPACING
                p = side.aside(room, distance, lateral)
                free = (
                    self.motion.is_free(p)
                    and self.site.rooms[room].contains(*p)
                    and not any(in_lane(o, *p, reach=radius) for o in others)
                    and self._room_beyond(side, room, distance) >= 3.0 * radius + PASSING_ROOM
                )
                if free and all(math.dist(p, q) >= QUEUE_SPACING - 1e-6 for q in spots):
                    spots.append(p)
                if len(spots) == wanted:
                    break
            self._queues[key] = spots
        return spots

    def _room_beyond(self, side: Opening, room: str, distance: float) -> float:
        """How far ``room`` reaches, across the wall of ``side``, beyond a point ``distance`` from it."""
        x0, y0, x1, y1 = self.site.rooms[room].rect
        return ((y1 - y0) if side.axis == "x" else (x1 - x0)) - distance

    def _wait_offset(self, opening: str) -> float:
        return wait_offset(self.params.robot_radius, self.site.opening(opening).width)

    def _key_point(self, opening: str, room: str, lateral: float) -> Point:
        key = (opening, room, lateral)
        p = self._beside.get(key)
        if p is None:
            raw = self.site.opening(opening).aside(room, self.beside_distance, lateral)
            p = self.motion.snap(raw, room)
            self._beside[key] = p
        return p

    def object_point(self, obj: str) -> Point:
        p = self._object.get(obj)
        if p is None:
            spec = self.site.objects[obj]
            p = self.motion.snap(spec.position, spec.room)
            self._object[obj] = p
        return p

    def drop_point(self, obj: str) -> Point:
        """Where ``obj`` is unloaded: its robot's slot in its destination room, away from doors and the human."""
        p = self._drop.get(obj)
        if p is None:
            self._place_drops(self.site.objects[obj].deliver_to)
            p = self._drop[obj]
        return p

    def _place_drops(self, room_id: str) -> None:
        room = self.site.rooms[room_id]
        x0, y0, x1, y1 = room.rect
        m = self.params.robot_radius + 0.15
        keep_clear = [
            p for o, _ in self.site.neighbours(room_id) for p in (self.beside(o, room_id), self.wait_point(o, room_id))
        ]
        queues = [p for o, _ in self.site.neighbours(room_id) for p in self.queue_spots(o, room_id)]
        human = [self.site.human.position] if self.site.human.room == room_id else []
        # One slot per robot, not per object: a robot that has delivered everything stays at its
        # slot, and another robot's slot is then never under it.
        objs = {o: spec.robot for o, spec in self.site.objects.items() if spec.deliver_to == room_id}
        robots = sorted(set(objs.values()))
        # Slots packed greedily from the room's centre outwards on a fine lattice, DROP_SPACING apart.
        cx, cy = room.center
        step = 0.1
        lattice = itertools.product(range(int((x1 - x0 - 2 * m) / step) + 1), range(int((y1 - y0 - 2 * m) / step) + 1))
        candidates = sorted(
            (round(math.dist(p, (cx, cy)), 6), p)
            for p in ((round(x0 + m + i * step, 6), round(y0 + m + j * step, 6)) for i, j in lattice)
        )
        slots: list[tuple[float, Point]] = []
        for d, p in candidates:
            if len(slots) == len(robots):
                break
            if not self.motion.is_free(p) or any(math.dist(p, q) < KEEP_CLEAR for q in keep_clear):
                continue
            if any(math.dist(p, q) < HUMAN_CLEAR for q in human):
                continue
            if any(math.dist(p, q) < QUEUE_SPACING for q in queues) or any(
                math.dist(p, q) < DROP_SPACING for _, q in slots
            ):
                continue
            slots.append((d, p))
        if not slots:
            slots = [(0.0, self.motion.snap((cx, cy), room_id))]
        for obj, robot in objs.items():
            self._drop[obj] = slots[robots.index(robot) % len(slots)][1]
