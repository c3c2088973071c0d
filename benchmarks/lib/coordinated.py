"""A planner stand-in whose robots do not block one another, so a simulated mission completes.

The plain stand-in (tests/sim/standin.py) sends every robot along its own chain of openings at
once; the simulator's robots are solid and keep apart, so robots meeting head-on in a doorway wedge,
their actions fail, and the mission runs to the time limit. Timing such a mission measures a
deadlocked world, not the simulator's work on a mission. This stand-in coordinates as a planner
would, without a solver:

- a robot's *trip* (from where it stands to its next load or unload: approach, open, go through
  each opening on the way) starts only once every opening on the way is reserved for it, all at
  once (no robot holds one opening while waiting for another, so reservations never deadlock);
  each opening is released as soon as the robot has gone through it;
- each robot unloads at its own slot of the delivery room (slots a robot's width apart), so
  robots do not queue for the room's centre;
- a failed action is sent again from where the robot stands (up to ``attempts`` times in a row);
  then the robot gives up, releases what it holds, and the mission will not complete.

It answers like :class:`tests.sim.standin.ScriptedPlanner` (same interface), so it drives the engine
in process (:func:`tests.sim.helpers.run_mission`) and over Zenoh (:class:`CoordinatedStandIn`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from protocol.messages import RobotCommand
from protocol.site.model import Site
from tests.sim.standin import STANDOFF, ScriptedPlanner, StandInPlanner, Task, route

SLOT_SPACING = 0.3  # m between two robots' discs at neighbouring unload slots
WALL_CLEARANCE = 0.3  # m between a slot's disc and the room's walls
ATTEMPTS = 5  # consecutive failures of one action before its robot gives up


@dataclass
class Leg(Task):
    """One action of a trip, with the openings to reserve before it starts and the one it frees."""

    reserve: frozenset[str] = field(default_factory=frozenset)  # the whole trip's openings (its first leg)
    release: str = ""  # the opening this leg went through (a gothrough)


def unload_slots(site: Site, room: str, radius: float) -> list[tuple[float, float]]:
    """Points of ``room`` a robot's width apart and clear of its walls, nearest its centre first."""
    x0, y0, x1, y1 = site.rooms[room].rect
    pitch = 2 * radius + SLOT_SPACING
    margin = radius + WALL_CLEARANCE
    columns = max(1, int((x1 - x0 - 2 * margin) // pitch) + 1)
    rows = max(1, int((y1 - y0 - 2 * margin) // pitch) + 1)
    # centred in the room: the spare width split on both sides
    left = x0 + margin + (x1 - x0 - 2 * margin - (columns - 1) * pitch) / 2
    bottom = y0 + margin + (y1 - y0 - 2 * margin - (rows - 1) * pitch) / 2
    points = [(left + c * pitch, bottom + r * pitch) for r in range(rows) for c in range(columns)]
    cx, cy = site.rooms[room].center
    return sorted(points, key=lambda p: ((p[0] - cx) ** 2 + (p[1] - cy) ** 2, p))


def trips_for(site: Site, robot: str, slot: int) -> list[Leg]:
    """Every leg of ``robot``'s mission: for each of its objects a trip to load it and a trip to
    deliver it (to slot ``slot`` of the delivery room, modulo the room's slots)."""
    legs: list[Leg] = []
    room = site.robots[robot].room
    radius = site.params.robot_radius
    for obj in sorted((o for o in site.objects.values() if o.robot == robot), key=lambda o: o.id):
        for goal, action, arg in ((obj.room, "load", obj.id), (obj.deliver_to, "unload", obj.id)):
            hops = route(site, room, goal)
            trip: list[Leg] = []
            for opening_id, a, b in hops:
                o = site.opening(opening_id)
                trip.append(Leg("approach", [o.id], o.beside(a, STANDOFF)))
                if o.kind == "door" and o.human_operated:
                    trip.append(Leg("opendoor", [o.id], None))
                trip.append(Leg("gothrough", [o.id], o.beside(b, STANDOFF), o.beside(a, STANDOFF), release=o.id))
            if action == "load":
                target = obj.position
            else:
                slots = unload_slots(site, goal, radius)
                target = slots[slot % len(slots)]
            trip.append(Leg(action, [arg], target))
            trip[0].reserve = frozenset(site.opening(h[0]).id for h in hops)
            legs.extend(trip)
            room = goal
    return legs


class CoordinatedPlanner(ScriptedPlanner):
    """:class:`ScriptedPlanner` with reserved openings, own unload slots and retries (module docstring)."""

    def __init__(self, site: Site, *, attempts: int = ATTEMPTS) -> None:
        super().__init__(site)
        self.attempts = attempts
        self.todo = {rid: trips_for(site, rid, i) for i, rid in enumerate(sorted(site.robots))}
        self.holder: dict[str, str] = {}  # opening -> robot that reserved it
        self.gave_up: list[str] = []

    def finished(self, robot: str, action_id: int, ok: bool) -> None:
        if self.busy.get(robot) != action_id:
            return
        del self.busy[robot]
        leg = self.todo[robot][0]
        if ok:
            self.todo[robot].pop(0)
            self.failures[robot] = 0
            if leg.release and self.holder.get(leg.release) == robot:
                del self.holder[leg.release]
            return
        self.failures[robot] += 1
        if self.failures[robot] >= self.attempts:
            self.todo[robot] = []
            self.gave_up.append(robot)
            for opening in [o for o, holder in self.holder.items() if holder == robot]:
                del self.holder[opening]

    def _may_start(self, robot: str, leg: Leg) -> bool:
        """Reserve the trip's openings for ``robot`` if none is another robot's; say whether it may go."""
        if any(self.holder.get(o, robot) != robot for o in leg.reserve):
            return False
        for opening in leg.reserve:
            self.holder[opening] = robot
        return True

    def commands(self, plan_id: int, now: float, poses: dict[str, tuple[float, float, float]]) -> list[RobotCommand]:
        waiting = {
            rid
            for rid, legs in self.todo.items()
            if rid not in self.busy and legs and not self._may_start(rid, legs[0])
        }
        held_back = {rid: self.todo[rid] for rid in waiting}
        for rid in waiting:  # no command now: the base class skips robots with nothing to do
            self.todo[rid] = []
        try:
            return super().commands(plan_id, now, poses)
        finally:
            self.todo.update(held_back)


class CoordinatedStandIn(StandInPlanner):
    """The stand-in on Zenoh (:class:`tests.sim.standin.StandInPlanner`) planning with :class:`CoordinatedPlanner`."""

    def __init__(self, site: Site, namespace: str, endpoint: str) -> None:
        super().__init__(site, namespace, endpoint)
        self.script = CoordinatedPlanner(site)
