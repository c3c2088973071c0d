"""A robot's planning problem as the ASP program gets it: its stops, the legs between them (each a
route of opening crossings) and the actions in progress it must finish first. Built by
:class:`.problem.ProblemBuilder`; times are integers relative to the plan's base second."""

from __future__ import annotations

from dataclasses import dataclass, replace

from protocol.actions import Action

from .motion import Point


@dataclass(frozen=True)
class Stop:
    key: str  # ASP term: ld(o1) or ul(o1)
    kind: str  # "ld" | "ul"
    obj: str
    room: str
    point: Point
    work: float  # s spent in place (load_time)

    @property
    def action(self) -> str:
        return (Action.LOAD if self.kind == "ld" else Action.UNLOAD).value


@dataclass(frozen=True)
class Crossing:
    opening: str
    src: str  # room the robot leaves
    dst: str  # room it enters
    approach: int  # s to drive beside the opening (0 when it already stands there)
    through: int  # s to drive through it
    human: bool  # a human-operated door: the human must open it


@dataclass(frozen=True)
class Leg:
    id: str  # ASP term, unique in a program: l(<robot>,<n>)
    origin: str  # "start" or a stop key
    stop: str  # the stop key it leads to
    crossings: tuple[Crossing, ...]
    tail: int  # s from the last opening (or the origin) to the stop point, plus the stop's work
    room: str  # room of the stop


@dataclass(frozen=True)
class PrefixStep:
    """An action in progress that the plan keeps in front (relative times)."""

    action: str
    args: tuple[str, ...]
    start: int
    end: int
    opening: str = ""  # for a gothrough: the opening whose doorway it occupies


@dataclass(frozen=True)
class RobotProblem:
    robot: str
    room: str  # where the robot is when it is free to plan (after its prefix)
    ready: int  # relative second it is free
    point: Point  # where it is then
    beside: str  # opening it already stands beside, or ""
    carrying: tuple[str, ...]
    stops: dict[str, Stop]
    legs: tuple[Leg, ...]
    capacity: int
    prefix: tuple[PrefixStep, ...] = ()
    rooms_at_start: tuple[tuple[str, int, int], ...] = ()  # (room, S, E) visited during the prefix

    @property
    def done(self) -> bool:
        return not self.stops

    def finish_bound(self) -> int:
        """A lower bound on when this robot can finish: every stop is reached by some leg, so it
        costs at least the shortest leg into it (waits and the order are ignored)."""
        into: dict[str, int] = {}
        for leg in self.legs:
            d = leg.tail + sum(c.approach + c.through for c in leg.crossings)
            into[leg.stop] = min(d, into.get(leg.stop, d))
        return self.ready + sum(into.values())

    def following(self, order: tuple[str, ...], routes: tuple[tuple[str, ...], ...] = ()) -> RobotProblem | None:
        """This problem with only the legs of one plan skeleton: ``order`` of the remaining stops (stops
        no longer to do are skipped) and, where still on offer, the same routes. None when ``order``
        does not cover this problem's stops."""
        wanted = [s for s in order if s in self.stops]
        if sorted(wanted) != sorted(self.stops):
            return None
        route_of = dict(zip(order, routes, strict=False))  # routes: () when none is on offer any more
        keep: list[Leg] = []
        origin = "start"
        for stop in wanted:
            options = [leg for leg in self.legs if leg.origin == origin and leg.stop == stop]
            if not options:
                return None
            same = [leg for leg in options if tuple(c.opening for c in leg.crossings) == route_of.get(stop)]
            keep.append((same or options)[0])
            origin = stop
        return replace(self, legs=tuple(keep))


@dataclass(frozen=True)
class Route:
    openings: tuple[tuple[str, str, str], ...]  # (opening, from room, to room)
    length: float  # m
