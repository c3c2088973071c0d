"""A robot that cannot get past another asks it to make way.

Driving around (:mod:`.avoidance`) needs room; where there is none - a robot standing
on the only way along a queue line, two robots meeting where neither can step aside, a robot
parked on another's way out of a room - the robot kept back asks the one in its way to make way,
as people do in a corridor. Robots are ranked, and only a robot of higher rank may ask:

- a robot holding a doorway (it is crossing: :mod:`.doorways`) first,
- then robots driving a trajectory,
- then robots waiting for a door to open,
- then parked robots (their action over, or stopped);
- within a rank, the smaller id first (the right of way's fixed priority).

A robot loading or unloading is never asked (it is done within seconds, then it is parked).
Because the ranks are a total order, two robots never ask each other, and the highest-ranked robot
kept back always gets its way cleared when there is room anywhere nearby.

A robot asked steps off the asker's way ahead (``horizon`` metres of its trajectory) to the nearest
free point at least a robot's width from it (a robot off the way's points that the asker still
stops for - its drive cuts a corner nearer than them - steps further: :mod:`.executor`), and waits
there until the asker has gone past (it is no longer kept back and is ``passed`` metres away) or
stopped driving; then it goes on with what it was doing (a driving robot plans its way back onto
its trajectory).

A robot wedged in a waiting cycle (each robot of it waits on the next: :mod:`.waiting`) that has
waited ``Avoidance.give_up`` seconds makes way for the robot that waits on it, unasked
(:meth:`MakeWay.offer`), if it has somewhere to go: its action would otherwise fail and the replan
would leave both robots where they are, to meet again. It does so once per action; the next time
its action fails, as before.

A robot asked that is boxed in (in a crowd at a door every free point is behind another robot)
passes the request on: it asks the robot standing where it could go to make way in turn - off the
first asker's way and off its own way out - whatever that robot's rank, as long as it is not
loading or unloading, holding a doorway, or already in the chain (``chain`` robots at most). The
robots of a chain answer for the first asker: when its request ends, theirs do.

Between robot processes (``arroch robot``) each asker's requests travel in its ``RobotTraffic``
(:mod:`.traffic`): the robot asked answers a request it heard of (:meth:`MakeWay.adopt`), and the
asker drops its own requests once over by the test the robot asked applies (:meth:`MakeWay.prune`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from itertools import pairwise

from runtime.pursuit import Path

from .right_of_way import Body

PHASE_RANK = {"drive": 2, "wait_open": 1, "done": 0, "idle": 0, "failed": 0}  # "dwell": never asked
HOLDER_RANK = 3


@dataclass
class Request:
    """``asker`` needs the asked robot off ``way`` (points of its trajectory ahead)."""

    asker: str
    way: list[tuple[float, float]]
    since: float
    renewed: float
    root: str = ""  # passed on: the robot whose way the chain clears ("": the asker)
    offered: bool = False  # made by the robot asked itself, unasked (:meth:`MakeWay.offer`)

    @property
    def first_asker(self) -> str:
        return self.root or self.asker


@dataclass
class MakeWay:
    radius: float
    holds_doorway: Callable[[str], bool]  # whether a robot holds a doorway (it is crossing one)
    clearance: float = 0.05  # m between discs: what "off the way" keeps
    ask_after: float = 3.0  # s kept back (not getting around) before asking
    horizon: float = 3.0  # m of the asker's trajectory ahead that is cleared
    step: float = 0.1  # m between the points of the way
    linger: float = 2.0  # s a request outlives the asker's last ask (it drives off first)
    passed: float = 1.0  # m beyond touching: the asker is this far away, the request ends
    longest: float = 30.0  # s a request lasts at most (the asker is stuck for another reason)
    chain: int = 3  # robots a request may be passed on to, one after another
    requests: dict[str, Request] = field(default_factory=dict)  # asked robot -> its request

    @property
    def keep(self) -> float:
        return 2.0 * self.radius + self.clearance

    def priority(self, robot: Body) -> tuple:
        """Sorts first the robot that goes first: the rank of what it does, then its id in natural
        order (r2 before r10)."""
        level = HOLDER_RANK if self.holds_doorway(robot.id) else PHASE_RANK.get(robot.phase, -1)
        return (-level, natural(robot.id))

    def way_ahead(self, path: Path, progress: float) -> list[tuple[float, float]]:
        """The points of ``path`` from ``progress`` to ``horizon`` metres on."""
        end = min(progress + self.horizon, path.length)
        count = max(int((end - progress) / self.step), 0)
        return [path.point_at(progress + i * self.step) for i in range(count + 1)]

    def in_the_way(self, robot: Body, way: list[tuple[float, float]], fleet: Mapping[str, Body]) -> Body | None:
        """The first robot along ``way`` that stands on it (nearer than ``keep`` to one of its points)."""
        for point in way:
            for other in fleet.values():
                if other.id != robot.id and math.dist(point, (other.x, other.y)) < self.keep:
                    return other
        return None

    def ask(self, asker: Body, asked: Body, way: list[tuple[float, float]], now: float) -> bool:
        """``asker`` asks ``asked`` to get off ``way``; whether it may (it outranks it, and no
        higher-ranked robot's request is pending)."""
        if asked.phase not in PHASE_RANK or self.priority(asker) >= self.priority(asked):
            return False
        mine = self.requests.get(asked.id)
        if mine is not None and mine.asker == asker.id:
            mine.way, mine.renewed = way, now
            return True
        if mine is not None and now - mine.renewed <= self.linger and mine.asker != asker.id:
            return False  # it is making way for another robot first
        self.requests[asked.id] = Request(asker.id, way, now, now)
        return True

    def offer(self, robot: Body, to: Body, now: float) -> Request:
        """``robot``, wedged in a waiting cycle with ``to`` (``to`` waits on it), makes way for it
        unasked: off the straight way from ``to`` through where ``robot`` stands and ``horizon``
        metres on - where ``to`` was going when ``robot``'s disc stopped it. Ranks do not matter:
        the request comes from the robot that moves."""
        dx, dy = robot.x - to.x, robot.y - to.y
        length = math.hypot(dx, dy) or 1.0
        end = (robot.x + dx / length * self.horizon, robot.y + dy / length * self.horizon)
        request = Request(to.id, along([(to.x, to.y), end], self.step), now, now, offered=True)
        self.requests[robot.id] = request
        return request

    def pass_on(self, robot: Body, other: Body, escape: list[tuple[float, float]], now: float) -> bool:
        """``robot``, making way but boxed in, asks ``other`` to make way in turn: off the way
        ``robot`` makes way for and off ``escape`` (its own way out); whether it may."""
        mine = self.requests.get(robot.id)
        if mine is None or other.phase not in PHASE_RANK or self.holds_doorway(other.id):
            return False
        chain = self._chain(robot.id)  # [robot, ..., first asker]: len - 2 passes so far
        if other.id in chain or len(chain) - 2 >= self.chain:
            return False
        way = [*mine.way, *escape]
        theirs = self.requests.get(other.id)
        if theirs is not None and theirs.asker != robot.id and now - theirs.renewed <= self.linger:
            if theirs.first_asker != mine.first_asker:
                return False  # making way for another robot first
            theirs.way = [*theirs.way, *(p for p in escape if p not in theirs.way)]  # for the same one: both ways
            return True
        if theirs is not None and theirs.asker == robot.id:
            theirs.way, theirs.renewed = way, now
            return True
        self.requests[other.id] = Request(robot.id, way, now, now, mine.first_asker)
        return True

    def _chain(self, robot: str) -> list[str]:
        """``robot`` and the robots it makes way for, back to the first asker."""
        chain = [robot]
        request = self.requests.get(robot)
        while request is not None and request.asker not in chain:
            chain.append(request.asker)
            request = self.requests.get(request.asker)
        return chain

    def request_for(self, robot: Body, now: float, fleet: Mapping[str, Body]) -> Request | None:
        """The request ``robot`` is to answer now, if any (ended requests are dropped)."""
        request = self.requests.get(robot.id)
        if request is None:
            return None
        if self._ended(request, robot, now, fleet):
            del self.requests[robot.id]
            return None
        return request

    def _ended(self, request: Request, robot: Body, now: float, fleet: Mapping[str, Body]) -> bool:
        """Whether ``request`` to ``robot`` is over: its askers are gone or done driving, the one it
        helped is done, it lasted ``longest``, or the asker stopped asking and is away."""
        asker = fleet.get(request.asker)
        first = fleet.get(request.first_asker)
        return (
            asker is None
            or first is None
            or first.phase != "drive"
            or (request.root != "" and request.asker not in self.requests)  # the one it helped is done
            or now - request.since > self.longest
            or (
                now - request.renewed > self.linger
                and math.dist((asker.x, asker.y), (robot.x, robot.y)) > self.keep + self.passed
            )
        )

    def prune(self, asker: str, now: float, fleet: Mapping[str, Body]) -> None:
        """Drop the requests ``asker`` made that are over. The robot asked drops them as it answers
        (:meth:`request_for`); an asker that does not step the robot it asked (a robot process, which
        steps only its own) drops them so, so that asking again is a new request."""
        for asked, request in list(self.requests.items()):
            if request.asker == asker:
                other = fleet.get(asked)
                if other is None or self._ended(request, other, now, fleet):
                    del self.requests[asked]

    def made_by(self, asker: str) -> dict[str, Request]:
        """The requests ``asker`` made, by the robot asked."""
        return {asked: r for asked, r in self.requests.items() if r.asker == asker}

    def adopt(self, asker: str, made: Mapping[str, Request], now: float) -> None:
        """Take ``made`` as the requests ``asker`` (another robot process's robot) has made now. A
        robot already asked by someone else keeps that request while it is fresh and older (the
        first robot to ask is answered first, as :meth:`ask` has it)."""
        for asked, request in list(self.requests.items()):
            if request.asker == asker and asked not in made and not request.offered:
                del self.requests[asked]
        for asked, request in made.items():
            held = self.requests.get(asked)
            fresh = held is not None and held.asker != asker and now - held.renewed <= self.linger
            if fresh and (held.since, held.asker) <= (request.since, request.asker):
                continue
            self.requests[asked] = request

    def off_the_way(self, request: Request, x: float, y: float) -> bool:
        """Whether a robot at (x, y) leaves ``request``'s way free."""
        return all(math.dist(point, (x, y)) >= self.keep for point in request.way)

    def forget(self, robot: str) -> None:
        self.requests.pop(robot, None)


def natural(name: str) -> tuple:
    """``name`` as a key that orders its numbers by value: r2 before r10."""
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", name) if part)


def along(points: list[tuple[float, float]], step: float) -> list[tuple[float, float]]:
    """The polyline through ``points`` as points at most ``step`` apart."""
    out = points[:1]
    for a, b in pairwise(points):
        count = max(math.ceil(math.dist(a, b) / step), 1)
        out.extend((a[0] + (b[0] - a[0]) * i / count, a[1] + (b[1] - a[1]) * i / count) for i in range(1, count + 1))
    return out
