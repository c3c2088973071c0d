"""From the site and the world to each robot's planning problem: stops, key points and candidate legs.

A robot's remaining work is a set of *stops* (``ld(O)``: drive to object O and load it; ``ul(O)``:
drive to O's drop point and unload it). Between two consecutive stops the robot follows a *leg*:
a route through the room graph, each opening on it crossed as ``approach(X)`` (drive to the point
beside X), ``opendoor(X)`` for a human-operated door (the robot waits beside it for the human), and
``gothrough(X)`` (drive through X to the point beside it in the next room). Durations come from the
motion planner's path lengths at ``robot_speed`` and from ``load_time``, rounded up to whole
seconds so that plan times are never earlier than the robot can manage.

For every ordered pair of stops that can follow one another, up to ``routes_per_leg`` loop-free
routes are offered to the solver (the shortest first, alternatives no longer than
``ROUTE_SLACK`` times it): the ASP program picks the order of stops and the route of each leg.
Times here are integers relative to the plan's base second (see :mod:`.facts`).
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field

from protocol.actions import Action

from .key_points import KeyPoints
from .motion import Point
from .robot_problem import Crossing, Leg, PrefixStep, RobotProblem, Route, Stop
from .world import RobotState, World

ROUTE_SLACK = 1.5  # an alternative route may be at most this many times the shortest
MAX_ROUTE_EXPANSIONS = 20_000


class PlanningError(Exception):
    """The problem cannot be set up (e.g. a robot cannot reach one of its objects)."""


@dataclass
class ProblemBuilder(KeyPoints):
    """Key points (:mod:`.key_points`) and legs for one site; caches everything that does not
    depend on the world."""

    routes_per_leg: int = 1
    _routes: dict[tuple, list[Route]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.human_doors = frozenset(d for d, o in self.site.doors.items() if o.human_operated)

    # ------------------------------------------------------------------ key points

    def stop_point(self, stop: Stop) -> Point:
        return stop.point

    # ------------------------------------------------------------------ routes

    def seconds(self, length: float, extra: float = 0.0) -> int:
        """Whole seconds (rounded up) to drive ``length`` metres and then spend ``extra`` seconds."""
        return max(int(math.ceil(length / self.params.robot_speed + extra - 1e-6)), 0)

    def routes(self, a: Point, room_a: str, b: Point, room_b: str, k: int | None = None) -> list[Route]:
        """Up to ``k`` (default ``routes_per_leg``) loop-free room routes from ``a`` to ``b``, shortest first."""
        k = self.routes_per_leg if k is None else k
        key = ((round(a[0], 3), round(a[1], 3)), room_a, (round(b[0], 3), round(b[1], 3)), room_b, k)
        hit = self._routes.get(key)
        if hit is not None:
            return hit
        found: list[Route] = []
        counter = itertools.count()
        # (f, g, tiebreak, room, point, rooms visited, openings so far)
        heap: list = [(math.dist(a, b), 0.0, next(counter), room_a, a, (room_a,), ())]
        expansions = 0
        while heap and len(found) < k and expansions < MAX_ROUTE_EXPANSIONS:
            f, g, _t, room, point, visited, path = heapq.heappop(heap)
            expansions += 1
            if found and f > found[0].length * ROUTE_SLACK:
                break
            if room == "":
                found.append(Route(path, g))
                continue
            if room == room_b:
                # Re-queue the completed route with its true length so routes pop in length order;
                # a loop-free route cannot leave room_b and come back, so stop expanding here.
                total = g + self.motion.distance(point, b, (room,))
                heapq.heappush(heap, (total, total, next(counter), "", b, visited, path))
                continue
            for opening, other in self.site.neighbours(room):
                if other in visited:
                    continue
                near = self.wait_point(opening, room)
                far = self.beside(opening, other)
                step = self.motion.distance(point, near, (room,)) + self.motion.distance(near, far, (room, other))
                g2 = g + step
                heapq.heappush(
                    heap,
                    (
                        g2 + math.dist(far, b),
                        g2,
                        next(counter),
                        other,
                        far,
                        visited + (other,),
                        path + ((opening, room, other),),
                    ),
                )
        self._routes[key] = found
        return found

    # ------------------------------------------------------------------ per robot

    def robot_room(self, state: RobotState) -> str:
        x, y, _ = state.pose
        room = self.site.room_at(x, y)
        if room is not None:
            return room.id

        # Outside every rectangle (in a wall's thickness, or in a doorway): the nearest room.
        def gap(r) -> float:
            x0, y0, x1, y1 = r.rect
            return math.hypot(max(x0 - x, 0, x - x1), max(y0 - y, 0, y - y1))

        return min(self.site.rooms.values(), key=gap).id

    def problem(self, world: World, robot: str, base: int, routes: int | None = None) -> RobotProblem:
        """The planning problem of ``robot`` in ``world``; times relative to ``base`` (a whole second).

        ``routes`` overrides ``routes_per_leg`` (alternatives matter when rooms may be forbidden)."""
        state = world.robots[robot]
        now = max(int(math.ceil(world.now - base - 1e-9)), 0)
        point: Point = (state.pose[0], state.pose[1])
        room = self.robot_room(state)
        carrying = set(state.carrying)
        delivered = set(world.delivered)
        prefix: list[PrefixStep] = []
        rooms_at_start: list[tuple[str, int, int]] = []
        ready = now
        ip = state.in_progress
        beside = state.beside
        if ip is not None and ip.action == Action.GOTHROUGH and ip.args and ip.target:
            opening = ip.args[0]
            src = self.site.opening(opening).other(ip.target)
            far = self.beside(opening, ip.target)
            end = max(now + self.seconds(math.dist(point, far)), self._rel(ip.until, base), now)
            prefix.append(PrefixStep(Action.GOTHROUGH.value, (opening,), now, end, opening))
            rooms_at_start.append((src, now, end))
            # through it, the robot stands in front of the opening but has not approached anything
            room, point, ready, beside = ip.target, far, end, ""
        elif ip is not None and ip.action in (Action.LOAD, Action.UNLOAD) and ip.args:
            obj = ip.args[0]
            end = max(self._rel(ip.until, base), now)
            prefix.append(PrefixStep(ip.action, (obj,), now, end))
            if ip.action == Action.LOAD:
                carrying.add(obj)
            else:
                carrying.discard(obj)
                delivered.add(obj)
            ready = end
            beside = ""
        stops: dict[str, Stop] = {}
        for obj, spec in sorted(self.site.objects.items()):
            if spec.robot != robot or obj in delivered:
                continue
            if obj not in carrying:
                stops[f"ld({obj})"] = Stop(
                    f"ld({obj})", "ld", obj, spec.room, self.object_point(obj), self.params.load_time
                )
            stops[f"ul({obj})"] = Stop(
                f"ul({obj})", "ul", obj, spec.deliver_to, self.drop_point(obj), self.params.load_time
            )
        capacity = self.params.robot_capacity
        legs = self._legs(robot, point, room, beside, stops, carrying, capacity, routes)
        return RobotProblem(
            robot=robot,
            room=room,
            ready=ready,
            point=point,
            beside=beside,
            carrying=tuple(sorted(carrying & {s.obj for s in stops.values()})),
            stops=stops,
            legs=tuple(legs),
            capacity=capacity,
            prefix=tuple(prefix),
            rooms_at_start=tuple(rooms_at_start),
        )

    @staticmethod
    def _rel(t: float, base: int) -> int:
        return int(math.ceil(t - base - 1e-9))

    def _legs(
        self,
        robot: str,
        start: Point,
        start_room: str,
        beside: str,
        stops: dict[str, Stop],
        carrying: set[str],
        capacity: int,
        k: int | None,
    ) -> list[Leg]:
        """Candidate legs between every pair of stops that may follow one another."""
        origins: list[tuple[str, Point, str]] = [("start", start, start_room)]
        origins += [(s.key, s.point, s.room) for s in stops.values()]
        legs: list[Leg] = []
        n = 0
        for origin, p, room_p in origins:
            for stop in stops.values():
                if stop.key == origin or not self._may_follow(origin, stop, stops, carrying, capacity):
                    continue
                routes = self.routes(p, room_p, stop.point, stop.room, k)
                if not routes:
                    raise PlanningError(
                        f"robot {robot} cannot get from room {room_p} to {stop.room} for {stop.action}({stop.obj})"
                    )
                for route in routes:
                    legs.append(
                        self._leg(f"l({robot},{n})", origin, p, stop, route, beside if origin == "start" else "")
                    )
                    n += 1
        return legs

    @staticmethod
    def _may_follow(origin: str, stop: Stop, stops: dict[str, Stop], carrying: set[str], capacity: int) -> bool:
        """False for pairs no valid order contains (sound pruning; the ASP program checks the rest)."""
        if origin == f"ul({stop.obj})":
            return False  # unloaded before loaded
        if origin == "start":
            if stop.kind == "ul":
                return stop.obj in carrying
            return len(carrying) < capacity
        if capacity == 1 and origin.startswith("ld("):
            return stop.key == "ul(" + origin[3:]  # a full robot must unload what it just loaded
        if capacity == 1 and origin.startswith("ul("):
            return stop.kind == "ld"  # an empty robot has nothing else to unload
        return True

    def _leg(self, leg_id: str, origin: str, p: Point, stop: Stop, route: Route, beside: str) -> Leg:
        crossings: list[Crossing] = []
        point = p
        for k, (opening, src, dst) in enumerate(route.openings):
            near = self.wait_point(opening, src)
            far = self.beside(opening, dst)
            already = k == 0 and beside == opening
            approach = 0 if already else self.seconds(self.motion.distance(point, near, (src,)))
            through = max(self.seconds(self.motion.distance(near, far, (src, dst))), 1)
            crossings.append(Crossing(opening, src, dst, approach, through, opening in self.human_doors))
            point = far
        tail = self.seconds(self.motion.distance(point, stop.point, (stop.room,)), stop.work)
        return Leg(leg_id, origin, stop.key, tuple(crossings), tail, stop.room)
