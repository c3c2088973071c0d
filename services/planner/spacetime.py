"""Timing one robot's path against the others' reservations: where to wait, and until when.

Prioritised planning: robots are timed one after the other, each against the trajectories already
committed (:class:`~services.planner.reservations.ReservationTable`), and a robot only ever gives
way - it never pushes a committed robot aside. We chose it over conflict-based search because the
planner dispatches one front action per robot at a time, most of them while the other robots'
commands are already out and being driven: those cannot be changed, so they are constraints, not
search variables, and CBS's joint search would have little to choose. Its cost is one small search
per new command, and it is complete for what it is asked (a clear timing of a given path, if one
exists within the wait bound), not for the team.

The path (from the grid planner, :mod:`services.planner.motion`) is kept; only its timing is
searched. The path is cut into ``n`` points a time step ``DT`` apart at ``robot_speed``; a state is
(point, step); from each state the robot either stays or moves to the next point. A state is free
when the robot's disc there is :attr:`ReservationTable.clearance` from every reserved robot at that
instant. The search is a sweep over time steps of the set of reachable points (numpy, so a few
milliseconds); the first step at which the last point is reachable and stays free from then on (an
arrived robot stands there) gives the arrival, and walking back gives where the waits go - as early
as possible, i.e. where the robot already stands or at a point before the conflict, which is the
safe spot. When no timing within ``max_wait`` is clear (e.g. a reserved robot parked on the goal, or
a head-on in a passage with nowhere to wait), the plain timing is returned and marked not clear;
the simulator's right of way (services/sim/right_of_way.py) is then the last line of defence.

A wait becomes two rows at the same point (the second one later): a *hold*, which the robots'
controller (runtime/pursuit.py) keeps - it does not leave that point before the hold's time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from .motion import NoPath
from .reservations import DT, ReservationTable

Point = tuple[float, float]
ROW_EVERY = 5  # steps between two rows while driving (0.5 m at 0.5 m/s)
SPOTS_TRIED = 4  # safe spots tried before giving up on a clear timing


@dataclass(frozen=True)
class Timed:
    rows: list[list[float]]  # [t, x, y, theta], holds included
    wait: float  # s spent waiting for other robots (beyond a hold until ``not_before``)
    clear: bool  # False: no clear timing was found; ``rows`` are the plain ones


class PathTimer:
    """Times paths against a reservation table (see the module docstring)."""

    def __init__(self, table: ReservationTable, speed: float, *, max_wait: float = 60.0) -> None:
        self.table = table
        self.speed = speed
        self.max_wait = max_wait
        self.stats = {"timings": 0, "waited": 0, "yielded": 0}  # searches; clear ones with a wait; pull-asides

    def samples(self, points: Sequence[Point]) -> tuple[list[Point], list[float]]:
        """Points along the path at most one step apart (the path's corners kept), and headings."""
        out: list[Point] = [points[0]]
        heads: list[float] = []
        ds = self.speed * DT
        for a, b in pairwise(points):
            length = math.dist(a, b)
            if length < 1e-9:
                continue
            heading = math.atan2(b[1] - a[1], b[0] - a[0])
            n = max(int(math.ceil(length / ds - 1e-9)), 1)
            for k in range(1, n + 1):
                f = k / n
                out.append((a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])))
                heads.append(heading)
        return out, heads

    def time(
        self, robot: str, points: Sequence[Point], now: float, *, theta0: float = 0.0, not_before: float | None = None
    ) -> Timed:
        """Rows along ``points`` from ``now``: hold until ``not_before`` (the plan's start for this
        action), then drive, waiting wherever the reserved robots require."""
        self.stats["timings"] += 1
        start = max(now, not_before if not_before is not None else now)
        pts, heads = self.samples(points)
        n = len(pts)
        if n == 1:
            return Timed(self._rows([0], pts, heads, start, now, theta0), 0.0, True)
        horizon = max(self.table.horizon() - start, 0.0)
        steps = int(math.ceil((min(horizon, self.max_wait) + self.max_wait) / DT)) + n
        times = start + DT * np.arange(steps + 1)
        xy = np.asarray(pts)
        box = (float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max()))
        others = self.table.positions(times, exclude=robot, near=box)
        if others.shape[1]:
            # A robot already closer than the clearance (two robots that stopped near each other)
            # only must not come closer still.
            now_gap = np.linalg.norm(others[0] - xy[0], axis=-1)
            need = np.minimum(self.table.clearance, now_gap) - 1e-6
            gap = np.linalg.norm(others[:, None, :, :] - xy[None, :, None, :], axis=-1)
            free = (gap >= need[None, None, :]).all(axis=-1)
        else:
            free = np.ones((steps + 1, n), dtype=bool)
        free[0, 0] = True  # where the robot stands now: it can only leave it
        reach = np.zeros((steps + 1, n), dtype=bool)
        reach[0, 0] = True
        goal_free_after = np.flip(np.logical_and.accumulate(np.flip(free[:, -1])))
        arrival = -1
        if goal_free_after.any():  # else someone stays on the goal: no timing can be clear
            for k in range(1, steps + 1):
                row = reach[k - 1].copy()
                row[1:] |= reach[k - 1][:-1]
                reach[k] = row & free[k]
                if reach[k, -1] and goal_free_after[k]:
                    arrival = k
                    break
                if not reach[k].any():
                    break  # trapped: every point it could be at is taken
        if arrival < 0:
            return Timed(self._rows(list(range(n)), pts, heads, start, now, theta0), 0.0, False)
        index = [n - 1]
        i = n - 1
        for k in range(arrival, 0, -1):
            if i > 0 and reach[k - 1, i - 1]:
                i -= 1  # came here by moving: waits go as early as possible
            index.append(i)
        index.reverse()
        wait = DT * (arrival - (n - 1))
        if wait > 1e-9:
            self.stats["waited"] += 1
        return Timed(self._rows(index, pts, heads, start, now, theta0), round(wait, 6), True)

    def time_or_yield(
        self,
        robot: str,
        points: Sequence[Point],
        now: float,
        route: Callable[[Point, Point], Sequence[Point]],
        spots: Callable[[Point], Sequence[Point]],
        *,
        theta0: float = 0.0,
        not_before: float | None = None,
    ) -> Timed:
        """:meth:`time`, and when that finds no clear timing, the same through a *safe spot* near
        the start (``spots``, nearest first; ``route`` joins two points): the robot pulls aside there,
        lets the others by, then goes on. The plain timing (not clear) when no spot helps."""
        timed = self.time(robot, points, now, theta0=theta0, not_before=not_before)
        if timed.clear or len(points) < 2:
            return timed
        for spot in list(spots(points[0]))[:SPOTS_TRIED]:
            try:
                via = [*route(points[0], spot), *route(spot, points[-1])[1:]]
            except NoPath:
                continue
            detour = self.time(robot, via, now, theta0=theta0, not_before=not_before)
            if detour.clear:
                self.stats["yielded"] += 1
                return detour
        return timed

    @staticmethod
    def _rows(
        index: list[int], pts: list[Point], heads: list[float], start: float, now: float, theta0: float
    ) -> list[list[float]]:
        """Rows for a walk ``index`` (one point index per step): a row where a wait starts or ends,
        at corners, and every ``ROW_EVERY`` steps while driving."""

        def heading(i: int) -> float:
            return heads[i] if i < len(heads) else (heads[-1] if heads else theta0)

        x0, y0 = pts[index[0]]
        rows: list[list[float]] = [[now, x0, y0, heading(index[0])]]
        if start > now:
            rows.append([start, x0, y0, heading(index[0])])
        last_row = 0
        for k in range(1, len(index)):
            moved = index[k] != index[k - 1]
            ends = k == len(index) - 1
            waits_next = not ends and index[k + 1] == index[k]
            corner = moved and 0 < index[k] < len(heads) and abs(heads[index[k]] - heads[index[k] - 1]) > 1e-6
            if ends or corner or (moved and waits_next) or (not moved and not waits_next) or k - last_row >= ROW_EVERY:
                x, y = pts[index[k]]
                rows.append([start + DT * k, x, y, heading(index[k]) if not ends else heading(index[k] - 1)])
                last_row = k
        return rows
