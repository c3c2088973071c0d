"""Collision-free team motion for the dispatcher: each new command timed against the committed ones.

Per dispatch (one TeamPlan), :meth:`TeamMotion.begin` fills the reservation table with what is
committed: the trajectory of every robot whose command stands (it goes on driving it), and the pose
of every other robot (a robot about to get a new command is taken as standing where it is: robots
timed after it avoid that spot, which is conservative but never wrong). Then the robots that get a
new command are timed one after the other in id order (:meth:`TeamMotion.timed`), each against the
table, and reserved in turn - prioritised planning (see :mod:`services.planner.spacetime`).

The plan's own waits are kept too: a ``gothrough`` is held until its planned start, so a robot that
ran ahead of its plan does not enter a doorway the plan gives to another robot first. A wait the
timing adds makes the action end later than planned; :meth:`TeamMotion.delays` says by how much,
and :func:`delay_plan` moves the rest of the robot's plan by that, so the plan's step times and the
trajectory's timestamps agree.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from itertools import pairwise

from runtime.plane import segment_distance

from .key_points import BESIDE_MARGIN
from .motion import MotionPlanner, NoPath, Point
from .plan import RobotPlan, Step
from .reservations import ReservationTable
from .spacetime import SPOTS_TRIED, PathTimer, Timed
from .world import World

log = logging.getLogger(__name__)
SPOT_RADII = (0.7, 1.0, 1.4, 1.9)  # m from the start at which safe spots are looked for
SPOT_ANGLES = 16
# searches per dispatch (about 10 ms each) after which no more spots are tried: a count, not a
# time, so a lockstep run gives the same trajectories on a loaded machine as on a quiet one
BUDGET = 20
LEAVE_PATH = 1.0  # m before an occupied goal where the way to a spot near it leaves the path


@dataclass
class TeamMotion:
    motion: MotionPlanner
    table: ReservationTable = field(init=False)
    timer: PathTimer = field(init=False)
    delays: dict[str, int] = field(default_factory=dict)  # robot -> s its front action ends late by
    budget: int = BUDGET
    _lanes: list[tuple[Point, Point]] | None = None
    _searches_at_start: int = 0
    # trajectories timed: clear (waits and pull-asides included), goal_moved (to a spot near an
    # occupied goal), unclear (sent with the plain timing)
    stats: Counter = field(default_factory=Counter)

    def __post_init__(self) -> None:
        self.table = ReservationTable(self.motion.site.params.robot_radius)
        self.timer = PathTimer(self.table, self.motion.speed)

    def begin(self, world: World, committed: dict[str, list[list[float]]]) -> None:
        """A new dispatch: ``committed`` trajectories stand, every other robot stands at its pose."""
        self.table = ReservationTable(self.table.radius, self.table.margin)
        self.timer.table = self.table
        self.delays = {}
        self._searches_at_start = self.timer.stats["timings"]
        for rid, state in sorted(world.robots.items()):
            rows = committed.get(rid)
            x, y, theta = state.pose
            if rows:
                self.table.reserve(rid, reanchored(rows, (x, y), world.now))
            else:
                self.table.reserve(rid, [[world.now, x, y, theta]])

    def timed(
        self,
        rid: str,
        rows: list[list[float]],
        now: float,
        *,
        not_before: float | None,
        planned_end: float | None,
        movable_goal: bool = False,
    ) -> list[list[float]]:
        """``rows`` (a front action's plain trajectory) timed against the table, then reserved.

        ``movable_goal``: the action only has to get the robot near its end point (``approach``,
        ``gothrough``); when another robot stands there (e.g. waiting at the same door), the robot
        stops at the nearest free spot in the same room instead - a queue forms."""
        points: list[Point] = []
        for row in rows:
            p = (row[1], row[2])
            if not points or math.dist(p, points[-1]) > 1e-9:
                points.append(p)
        if not points:
            return rows
        theta0 = rows[0][3]
        if self.timer.stats["timings"] - self._searches_at_start > self.budget:
            # past the budget: waits on the path only (one search), no spots to pull aside to
            timed = self.timer.time(rid, points, now, theta0=theta0, not_before=not_before)
            movable_goal = False
        else:
            timed = self.timer.time_or_yield(
                rid, points, now, self._route, self.spots, theta0=theta0, not_before=not_before
            )
        outcome = "clear" if timed.clear else "unclear"
        if not timed.clear and movable_goal:
            moved = self._elsewhere(rid, points, now, theta0, not_before)
            if moved is not None:
                timed, outcome = moved, "goal_moved"
        self.stats[outcome] += 1
        out = timed.rows
        if not timed.clear:
            conflict = self.table.first_conflict(rid, out)
            log.debug("no clear timing for %s at %.1f (first conflict: %s)", rid, now, conflict)
        if planned_end is not None and out[-1][0] > planned_end + 1e-6:
            self.delays[rid] = int(math.ceil(out[-1][0] - planned_end - 1e-6))
        self.table.reserve(rid, out)
        return out

    def _route(self, a: Point, b: Point) -> tuple[Point, ...]:
        return self.motion.path(a, b).points

    def _elsewhere(
        self, rid: str, points: list[Point], now: float, theta0: float, not_before: float | None
    ) -> Timed | None:
        """A clear timing to a free spot near the goal, in the goal's room (None: there is none)."""
        goal = points[-1]
        room = self.motion.site.room_at(*goal)
        for spot in self.spots(goal, nearest_first=True)[:SPOTS_TRIED]:
            if room is not None and self.motion.site.room_at(*spot) is not room:
                continue
            # from the last point well short of the goal (for a gothrough: still before the opening)
            cut = max([i for i, p in enumerate(points) if math.dist(p, goal) >= LEAVE_PATH] or [0])
            try:
                via = [*points[:cut], *self._route(points[cut], spot)]
            except NoPath:
                continue
            timed = self.timer.time(rid, via, now, theta0=theta0, not_before=not_before)
            if timed.clear:
                return timed
        return None

    def spots(self, centre: Point, *, nearest_first: bool = False) -> list[Point]:
        """Free points around ``centre`` (reachable in a straight line) at least a clearance from every
        reserved path: the farthest from those paths first, or the nearest to ``centre``."""
        found: list[tuple[float, float, Point]] = []
        for radius in SPOT_RADII:
            for k in range(SPOT_ANGLES):
                a = 2.0 * math.pi * k / SPOT_ANGLES
                p = (centre[0] + radius * math.cos(a), centre[1] + radius * math.sin(a))
                if not self.motion.is_free(p) or not self.motion.segment_free(centre, p):
                    continue
                away = self._distance_to_paths(p)
                if away >= self.table.clearance and self._off_lanes(p):
                    found.append((radius, -min(away, 2.0), p) if nearest_first else (-min(away, 2.0), radius, p))
        found.sort()
        return [p for _, _, p in found]

    def _off_lanes(self, p: Point) -> bool:
        """Whether ``p`` leaves every opening's lane free: the line between its two beside points,
        where robots line up and pass (a robot waiting on it would block the doorway)."""
        if self._lanes is None:
            site = self.motion.site
            standoff = site.params.robot_radius + BESIDE_MARGIN
            self._lanes = [
                (o.beside(o.rooms[0], standoff), o.beside(o.rooms[1], standoff)) for o in site.openings.values()
            ]
        return all(segment_distance(p, a, b) >= self.table.clearance for a, b in self._lanes)

    def _distance_to_paths(self, p: Point) -> float:
        best = math.inf
        for rows in self.table.paths().values():
            for a, b in pairwise(rows):
                best = min(best, segment_distance(p, (a[1], a[2]), (b[1], b[2])))
            if len(rows) == 1:
                best = min(best, math.dist(p, (rows[0][1], rows[0][2])))
        return best


def reanchored(rows: list[list[float]], pose: Point, now: float) -> list[list[float]]:
    """The rest of a committed trajectory as the robot will really drive it: from the row nearest
    its pose on, with times moved so that it leaves there ``now`` (unless the rows say later). A robot
    held at a door is late on its rows; reserving the rows as sent would reserve where it is not."""
    nearest = min(range(len(rows)), key=lambda i: math.dist(pose, (rows[i][1], rows[i][2])))
    shift = max(now - rows[nearest][0], 0.0)
    rest = [[now, pose[0], pose[1], rows[nearest][3]]]
    rest += [[r[0] + shift, r[1], r[2], r[3]] for r in rows[nearest:] if r[0] + shift > now]
    return rest


def delay_plan(plan: RobotPlan, index: int, seconds: int) -> RobotPlan:
    """``plan`` with its front step (``index``) ending ``seconds`` later and everything after it moved
    by as much (passes that start after the front step's start included)."""
    if seconds <= 0 or index >= len(plan.steps):
        return plan
    front = plan.steps[index]
    steps = list(plan.steps)
    steps[index] = Step(front.action, front.args, front.start, front.end + seconds)
    for i in range(index + 1, len(steps)):
        s = steps[i]
        steps[i] = Step(s.action, s.args, s.start + seconds, s.end + seconds)
    passes = tuple(
        replace(p, start=p.start + seconds, end=p.end + seconds) if p.start >= front.start else p for p in plan.passes
    )
    return replace(plan, steps=tuple(steps), passes=passes, finish=plan.finish + seconds)
