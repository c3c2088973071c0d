"""Doorways are taken one crossing robot at a time.

A robot told to go through an opening (``gothrough``) first asks for it. The opening is granted to
the asking robot nearest to it (then the one that asked first, then the smallest id) once nobody
holds it, or - while the holder has not left the spot where it got it - to an asking robot nearer
than the holder (it stands in the holder's way; a holder already on its way keeps it, so it is not
stopped where it would be in the way); the others stay where they are (the queue spots the planner sent
them to). The holder keeps the opening while it drives through and until it is out of the
opening's *lane* - the strip in front of the gap on both sides, ``LANE_DEPTH`` deep, as wide as the
gap and ``LANE_MARGIN`` more - or is told something else, or stops driving. Meanwhile no other robot
steps into that lane, and one that is in it gets out of the way (:meth:`Doorways.lane_to_leave`).
So two robots do not meet in a doorway or in front of one, whatever the timing of their commands.

Between robot processes (``arroch robot``) each robot's asks and holds travel in its
``RobotTraffic`` (:mod:`.traffic`, :meth:`Doorways.adopt`); two robots that each took an opening
before hearing of the other settle it by :func:`_claim`, the same way in both processes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

from protocol.site.model import Opening, Site

# m either side of an opening's line: where a crossing robot comes out (the planner's point beside
# the opening, 0.6 m) and a robot's width and a margin beyond
LANE_DEPTH = 1.2
SETTLED = 0.2  # m a holder may have moved from where it got the doorway and still give it to a nearer robot
LANE_MARGIN = 0.15  # m beyond the gap's half-width (a robot waiting beside it is clear of one coming out)


def across(opening: Opening, x: float, y: float) -> float:
    """Signed distance of (x, y) from the opening's line."""
    return (y - opening.center[1]) if opening.axis == "x" else (x - opening.center[0])


def in_lane(opening: Opening, x: float, y: float, reach: float = 0.0) -> bool:
    """Whether (x, y) is in the lane through ``opening`` (``reach``: whether a disc of that radius
    there reaches into it along the wall)."""
    along = (x - opening.center[0]) if opening.axis == "x" else (y - opening.center[1])
    return abs(along) <= opening.width / 2.0 + LANE_MARGIN + reach and abs(across(opening, x, y)) <= LANE_DEPTH


def _claim(opening: Opening, at: tuple[float, float], entered: bool, robot: str) -> tuple:
    """Orders two claims to one opening, the first keeps it: a robot that has been in the lane (it
    is crossing), then the one that got it nearer the opening (it stood in the other's way), then
    the smaller id."""
    return (not entered, round(math.dist(at, opening.center), 3), robot)


def _put(table: dict, key: str, value: object) -> None:
    if value is None:
        table.pop(key, None)
    else:
        table[key] = value


def lane_rect(opening: Opening) -> tuple[float, float, float, float]:
    """The lane through ``opening`` as a rectangle (x0, y0, x1, y1): where :func:`in_lane` holds."""
    half = opening.width / 2.0 + LANE_MARGIN
    cx, cy = opening.center
    if opening.axis == "x":
        return (cx - half, cy - LANE_DEPTH, cx + half, cy + LANE_DEPTH)
    return (cx - LANE_DEPTH, cy - half, cx + LANE_DEPTH, cy + half)


@dataclass(frozen=True)
class Hold:
    """An opening a robot holds: where its centre was when it got it, whether it has been in the lane."""

    opening: str
    at: tuple[float, float]
    entered: bool = False


@dataclass(frozen=True)
class DoorwayRows:
    """What one robot has of the doorways' table: the opening its command goes through (``""``:
    none), the one it asks for and since when, the ones it holds."""

    crossing: str = ""
    asking: tuple[str, float] | None = None
    holds: tuple[Hold, ...] = ()


class Mover(Protocol):
    """What the rule reads from a robot (:class:`.executor.Robot`)."""

    id: str
    x: float
    y: float
    phase: str


@dataclass
class Doorways:
    site: Site
    holders: dict[str, str] = field(default_factory=dict)  # opening -> robot holding it
    _asked: dict[str, tuple[str, float]] = field(default_factory=dict)  # robot -> (opening, since)
    _entered: set[str] = field(default_factory=set)  # openings whose holder has been in the lane
    _told: dict[str, str] = field(default_factory=dict)  # robot -> opening its command goes through
    _granted_at: dict[str, tuple[float, float]] = field(default_factory=dict)  # opening -> where its holder got it

    def may_cross(self, robot: Mover, opening_id: str, now: float, fleet: Mapping[str, Mover]) -> bool:
        """Whether ``robot``, told to go through ``opening_id``, may drive now (it holds the opening,
        or gets it); otherwise it waits where it is."""
        self._told[robot.id] = opening_id
        self._release(fleet)
        if self.holders.get(opening_id) == robot.id:
            return True
        if self._asked.get(robot.id, ("", 0.0))[0] != opening_id:
            self._asked[robot.id] = (opening_id, now)
        center = self.site.opening(opening_id).center
        holder = self.holders.get(opening_id)
        if holder is not None:
            theirs = fleet[holder]
            if opening_id in self._entered or math.dist((theirs.x, theirs.y), self._granted_at[opening_id]) > SETTLED:
                return False  # in the lane, or on its way: stopping it now could leave it in the way
            # still where it was granted the doorway: a robot nearer the opening (in its way) goes first
            if math.dist((robot.x, robot.y), center) >= math.dist((theirs.x, theirs.y), center):
                return False
            self._asked[holder] = (opening_id, now)
            del self.holders[opening_id]
        # the one nearest the opening first (the queue's head: the others' ways in pass where it
        # stands), then the one that asked first
        first = min(
            (round(math.dist((fleet[rid].x, fleet[rid].y), center), 3), since, rid)
            for rid, (o, since) in self._asked.items()
            if o == opening_id and rid in fleet
        )
        if first[2] != robot.id:
            return False
        self.holders[opening_id] = robot.id
        self._granted_at[opening_id] = (robot.x, robot.y)
        self._entered.discard(opening_id)
        del self._asked[robot.id]
        return True

    def hand_back(self, robot: str) -> bool:
        """``robot`` gives back the openings it holds and has not entered yet, and asks for none;
        whether it held any. (A robot making way for it may have no way out but through their lanes.)"""
        mine = [o for o, holder in self.holders.items() if holder == robot and o not in self._entered]
        for opening_id in mine:
            del self.holders[opening_id]
            self._granted_at.pop(opening_id, None)
        self._asked.pop(robot, None)
        return bool(mine)

    def holds(self, robot: str) -> bool:
        """Whether ``robot`` holds an opening (it is crossing it)."""
        return robot in self.holders.values()

    def forget(self, robot: str) -> None:
        """The robot is told something else: it asks for nothing (what it holds it keeps until out)."""
        self._asked.pop(robot, None)
        self._told.pop(robot, None)

    def lane_taken(self, robot: Mover, x: float, y: float, fleet: Mapping[str, Mover]) -> bool:
        """Whether stepping to (x, y) takes ``robot`` into the lane of an opening another robot holds."""
        return bool(self.lane_holder(robot, x, y, fleet))

    def lane_holder(self, robot: Mover, x: float, y: float, fleet: Mapping[str, Mover]) -> str:
        """The robot holding the opening whose lane stepping to (x, y) takes ``robot`` into, else ""."""
        self._release(fleet)
        for opening_id, holder in self.holders.items():
            if holder == robot.id:
                continue
            opening = self.site.opening(opening_id)
            if in_lane(opening, x, y) and not in_lane(opening, robot.x, robot.y):
                return holder
        return ""

    def held_lanes(self, robot: Mover, fleet: Mapping[str, Mover]) -> list[tuple[float, float, float, float]]:
        """The lanes (x0, y0, x1, y1) of the openings other robots hold: ``robot`` may not step in."""
        self._release(fleet)
        return [lane_rect(self.site.opening(o)) for o, holder in self.holders.items() if holder != robot.id]

    def lane_to_leave(self, robot: Mover, fleet: Mapping[str, Mover]) -> Opening | None:
        """The opening whose lane ``robot`` stands in while another robot holds it (it should get
        out of the way), if any."""
        self._release(fleet)
        for opening_id, holder in self.holders.items():
            opening = self.site.opening(opening_id)
            if holder != robot.id and in_lane(opening, robot.x, robot.y):
                return opening
        return None

    # ------------------------------------------------------------------ between robot processes

    def rows(self, robot: str) -> DoorwayRows:
        """``robot``'s rows of the table, for the other robot processes (:mod:`.traffic`)."""
        mine = sorted(o for o, holder in self.holders.items() if holder == robot)
        holds = tuple(Hold(o, self._granted_at[o], o in self._entered) for o in mine)
        return DoorwayRows(self._told.get(robot, ""), self._asked.get(robot), holds)

    def adopt(self, robot: str, rows: DoorwayRows) -> None:
        """Take ``rows`` as what ``robot`` (another process's) has now. Two robots that both hold an
        opening (each granted it before hearing of the other) settle it by :func:`_claim`, the same
        way in both processes: the one that loses gives it up (this process's robot asks again at
        its next step, and waits)."""
        _put(self._told, robot, rows.crossing or None)
        _put(self._asked, robot, rows.asking)
        kept = {h.opening for h in rows.holds}
        for opening_id, holder in list(self.holders.items()):
            if holder == robot and opening_id not in kept:
                del self.holders[opening_id]
        for hold in rows.holds:
            holder = self.holders.get(hold.opening)
            if holder is not None and holder != robot:
                opening = self.site.opening(hold.opening)
                known = _claim(opening, self._granted_at[hold.opening], hold.opening in self._entered, holder)
                if known <= _claim(opening, hold.at, hold.entered, robot):
                    continue  # the holder we know of keeps it (the other learns so from its traffic)
            if holder != robot:
                self._entered.discard(hold.opening)  # a new holder: its own way into the lane counts
            self.holders[hold.opening] = robot
            self._granted_at[hold.opening] = hold.at
            if hold.entered:
                self._entered.add(hold.opening)

    def _release(self, fleet: Mapping[str, Mover]) -> None:
        """Free the openings whose holder is through (it was in the lane and is out), was told
        something else, or stopped driving."""
        for opening_id, holder in list(self.holders.items()):
            other = fleet.get(holder)
            if other is None or other.phase != "drive" or self._told.get(holder) != opening_id:
                del self.holders[opening_id]
                continue
            if in_lane(self.site.opening(opening_id), other.x, other.y):
                self._entered.add(opening_id)
            elif opening_id in self._entered:
                del self.holders[opening_id]
