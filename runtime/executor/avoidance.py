"""Robots are solid, and a robot kept back by others drives around them.

Two rules for driving robots, simulated or real (:mod:`.executor`), on top of the right of way
(:mod:`.right_of_way`):

- **Solid bodies.** No step may bring a robot's disc within ``contact_gap`` of another robot's
  disc while closing in on it, whatever produced the step (following the trajectory, backing away,
  driving around). Where the right of way lets a robot go on (it won a waiting cycle, or lost
  patience with a parked robot) it comes up to the other robot and stops.
- **Driving around.** A robot kept back by another robot for ``detour_after`` seconds plans a way
  around, as the local planner of a real robot does: the first point of its trajectory ahead that
  is clear of every other robot (within the room it is in, however far ahead: past a queue of
  robots standing on it) is the goal, and a shortest path on a
  ``resolution`` grid of the room avoids walls and keeps ``clearance`` from every robot's disc. It
  drives that path (turning on the spot first where the path turns sharply); its trajectory's
  follower projects it back onto the trajectory from there. With no such point or path it waits,
  and tries again ``retry`` seconds later.

Where there is no way around, the robot kept back asks the robot in its way to make way
(:mod:`.make_way`). When nothing helps for ``give_up`` seconds of a wait that cannot end by
itself (robots wedged in a cluster, each waiting on the next: :mod:`.waiting`) the robot's action
fails and the planner plans again from where the robots stand (:mod:`.executor`). A robot
never pushes through another: solid bodies hold for every step.

Both rules read other robots where they are now. In the simulator robots are stepped one after
another within a tick, so each sees the others' latest poses and the invariant holds after every
robot's step. A real robot's driver sees each other robot where its last pose, carried on at its
velocity, puts it (:mod:`.peers`), and comes no nearer than ``contact_gap`` grown by
``RobotConfig.allowance`` (what that prediction may miss).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from protocol.site.grid import OccupancyGrid
from protocol.site.model import Room, Site
from runtime.plane import wrap
from runtime.pursuit import ControllerConfig, Path, Step, integrate

from .right_of_way import Body

Rect = tuple[float, float, float, float]  # x0, y0, x1, y1

REACHED = 0.08  # m: a way's point this near the robot is reached
BACK_OFF = 0.1  # m: the shortest back-off from a robot before a way (longer than REACHED: it is driven)
# m: how far from where it stands a robot looks for a free point to step to. Out to 3 m: in a corridor
# lined by a queue, the nearest free point is past the queue's end (twelve robots, trials 0-3 of
# arroch experiment robots --robots 12 --objects 3 --seed 0: failed actions 8/2/6/12 -> 1/4/5/1 with
# rings to 3 m; to 5 m, robots sent far off to make way jammed the corridor, 4/4/39/0)
RING = (0.7, 1.0, 1.3, 1.6, 2.0, 2.5, 3.0)
NEIGHBOURS = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]
STEP = {(dr, dc): math.hypot(dr, dc) for dr, dc in NEIGHBOURS}
EIGHT_WAY = np.ones((3, 3), dtype=bool)  # cells touching at a corner are connected, as NEIGHBOURS


@dataclass
class Detour:
    """A way around: points to drive through, in order, ending on the trajectory."""

    points: list[tuple[float, float]]


@dataclass
class Avoidance:
    site: Site
    # where a robot's centre may be: walls and open leaves inflated by its radius and the motion
    # planner's wall clearance (runtime/clearance.py), so ways around robots keep it too
    free: OccupancyGrid
    radius: float
    controller: ControllerConfig
    contact_gap: float = 0.005  # m: the closest two discs may come while closing in
    clearance: float = 0.05  # m kept between discs along a way around
    detour_after: float = 1.0  # s kept back by a robot before driving around it
    retry: float = 1.0  # s between two attempts to plan a way around
    give_up: float = 12.0  # s kept back after which a robot's action fails (the planner plans again)
    progress: float = 0.5  # m a robot kept back must get from where it was to count as getting somewhere
    rejoin_after: float = 0.3  # m off its trajectory from which a robot plans its way back
    resolution: float = 0.1  # m: cells of the grid a way around is planned on
    # areas a robot may not enter (other robots' doorway lanes: :mod:`.doorways`); a way never
    # enters one, unless it starts in it
    keep_out: Callable[[Body], list[Rect]] = lambda robot: []
    # whether a door or passage may be driven through now (a shut door may not); a way back onto a
    # trajectory that goes on in the next room is planned into it only through openings that may
    passable: Callable[[str], bool] = lambda opening_id: True
    _blocked_since: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # robot -> (t, x, y)
    _detours: dict[str, Detour] = field(default_factory=dict)
    _last_try: dict[str, float] = field(default_factory=dict)
    _rooms: dict[str, tuple[np.ndarray, tuple[float, float]]] = field(default_factory=dict)

    # ------------------------------------------------------------------ solid bodies

    def clear(self, robot: Body, x: float, y: float, fleet: Mapping[str, Body]) -> bool:
        """Whether stepping to (x, y) keeps ``robot`` from touching any other robot."""
        return not self.closing_in_on(robot, x, y, fleet)

    def closing_in_on(self, robot: Body, x: float, y: float, fleet: Mapping[str, Body]) -> str:
        """The first robot (in fleet order) that stepping to (x, y) would bring ``robot`` within
        ``contact_gap`` of while closing in, else ""."""
        limit = 2.0 * self.radius + self.contact_gap
        for other in fleet.values():
            if other.id == robot.id:
                continue
            after = math.hypot(x - other.x, y - other.y)
            if after < limit and after < math.hypot(robot.x - other.x, robot.y - other.y) - 1e-9:
                return other.id
        return ""

    # ------------------------------------------------------------------ driving around

    def mark_kept_back(self, robot: Body, now: float) -> float:
        """Mark the robot kept back at this step (its clock starts at the first such step;
        :meth:`moving_on` stops it) and return the seconds it has been kept back without getting
        anywhere. At ``give_up`` its action fails."""
        return now - self._since(robot, now)

    def moving_on(self, robot: str) -> None:
        """The robot follows its trajectory again (or waits for a door or a hold, not a robot)."""
        self._blocked_since.pop(robot, None)
        self._detours.pop(robot, None)

    def not_kept_back(self, robot: str) -> None:
        """The robot is not kept back (its way, if any, is kept): it does not give up."""
        self._blocked_since.pop(robot, None)

    def stop_driving_around(self, robot: str) -> None:
        """Drop the robot's way around (it waits for another robot to make way instead); it is
        still kept back."""
        self._detours.pop(robot, None)

    def _since(self, robot: Body, now: float) -> float:
        """Since when the robot has been kept back without getting anywhere: the clock starts again
        once it is ``progress`` metres from where it started (around the others, it got somewhere)."""
        since, x, y = self._blocked_since.get(robot.id, (now, robot.x, robot.y))
        if math.hypot(robot.x - x, robot.y - y) > self.progress:
            since, x, y = now, robot.x, robot.y
        self._blocked_since[robot.id] = (since, x, y)
        return since

    def kept_back(self, robot: str, now: float) -> float:
        """Seconds the robot has been kept back by other robots (0 if it is not)."""
        since = self._blocked_since.get(robot)
        return 0.0 if since is None else now - since[0]

    def driving_around(self, robot: str) -> bool:
        return robot in self._detours

    def around(
        self,
        robot: Body,
        theta: float,
        path: Path,
        progress: float,
        now: float,
        dt: float,
        fleet: Mapping[str, Body],
        allowed: Callable[[Step], bool],
    ) -> Step | None:
        """A step on the way around whatever keeps ``robot`` back, or None (it waits).
        ``allowed`` vetoes steps the caller knows are wrong (into a shut doorway)."""
        if robot.id not in self._detours:
            if now - self._since(robot, now) < self.detour_after:
                return None
            self.rejoin(robot, path, progress, now, fleet)
        detour = self._detours.get(robot.id)
        return None if detour is None else self._follow(robot, theta, detour, now, dt, fleet, allowed)

    def rejoin(
        self,
        robot: Body,
        path: Path,
        progress: float,
        now: float,
        fleet: Mapping[str, Body],
        *,
        off_track: bool = False,
    ) -> None:
        """Plan a way (at most one try per ``retry``) to the first clear point of the trajectory
        ahead: around the robots in the way, or back for a robot ``rejoin_after`` metres off it
        (``off_track``: heading straight back could cut a doorway's jamb, or the wall beside a
        doorway when the trajectory goes on in the next room)."""
        if robot.id in self._detours or now - self._last_try.get(robot.id, -math.inf) < self.retry:
            return
        self._last_try[robot.id] = now
        points = self._plan(robot, path, progress, fleet, next_room=off_track)
        if points:
            self._detours[robot.id] = Detour(points)

    def out_of_the_way(
        self,
        robot: Body,
        theta: float,
        now: float,
        dt: float,
        fleet: Mapping[str, Body],
        outside: Callable[[float, float], bool],
        allowed: Callable[[Step], bool],
    ) -> Step | None:
        """A step toward the nearest free point where ``outside`` holds (out of a lane another robot
        needs), or None when there is no way there."""
        detour = self._detours.get(robot.id)
        if detour is None:
            if now - self._last_try.get(robot.id, -math.inf) < self.retry:
                return None
            self._last_try[robot.id] = now
            room = self.site.room_at(robot.x, robot.y)
            if room is None:
                return None
            points = self._free_point(robot, room, outside, [(o.x, o.y) for o in fleet.values() if o.id != robot.id])
            if not points:
                return None
            detour = self._detours[robot.id] = Detour(points)
        return self._follow(robot, theta, detour, now, dt, fleet, allowed)

    def way_off(
        self, robot: Body, fleet: Mapping[str, Body], outside: Callable[[float, float], bool]
    ) -> list[tuple[float, float]]:
        """A way to the nearest free point where ``outside`` holds (as :meth:`out_of_the_way` drives),
        or [] when there is none."""
        room = self.site.room_at(robot.x, robot.y)
        if room is None:
            return []
        return self._free_point(robot, room, outside, [(o.x, o.y) for o in fleet.values() if o.id != robot.id])

    def boxed_in_by(
        self,
        robot: Body,
        fleet: Mapping[str, Body],
        outside: Callable[[float, float], bool],
        movable: Callable[[Body], bool],
    ) -> tuple[Body, list[tuple[float, float]]] | None:
        """For a robot that finds no free point where ``outside`` holds: the nearest robot (of the
        ``movable`` ones) without which it would, and its way there (from where it stands); None
        when no one robot's moving would do."""
        room = self.site.room_at(robot.x, robot.y)
        if room is None:
            return None
        reach = RING[-1] + 2.0 * self.radius + self.clearance
        near = sorted(
            (math.hypot(o.x - robot.x, o.y - robot.y), o.id, o)
            for o in fleet.values()
            if o.id != robot.id and movable(o) and math.hypot(o.x - robot.x, o.y - robot.y) <= reach
        )
        for _, _, other in near[:3]:
            others = [(o.x, o.y) for o in fleet.values() if o.id not in (robot.id, other.id)]
            points = self._free_point(robot, room, outside, others)
            if points:
                return other, [(robot.x, robot.y), *points]
        return None

    def _free_point(
        self, robot: Body, room, outside: Callable[[float, float], bool], others: list[tuple[float, float]]
    ) -> list[tuple[float, float]]:
        """A way to the nearest free point (on rings ``RING`` around the robot, 16 directions) in the
        robot's room where ``outside`` holds, clear of ``others``' discs; [] when there is none."""
        keep = 2.0 * self.radius + self.clearance
        spots = sorted(
            (round(r, 2), k, (robot.x + r * math.cos(k * math.pi / 8), robot.y + r * math.sin(k * math.pi / 8)))
            for r in RING
            for k in range(16)
        )
        field: Field | None = None  # made once, for the first spot worth a search: the same for every spot
        for _, _, p in spots:
            if not (outside(*p) and room.contains(*p) and self.free.is_free(*p)):
                continue
            if any(math.dist(p, o) < keep for o in others):
                continue
            field = field or self._field(robot, (room,), others)
            if not field.reaches(p):
                continue  # (a search would look through every cell it reaches to find that out)
            points = self._route(field, p)
            if points:
                return points
        return []

    def _follow(
        self,
        robot: Body,
        theta: float,
        detour: Detour,
        now: float,
        dt: float,
        fleet: Mapping[str, Body],
        allowed: Callable[[Step], bool],
    ) -> Step | None:
        while detour.points and math.hypot(detour.points[0][0] - robot.x, detour.points[0][1] - robot.y) < REACHED:
            detour.points.pop(0)
        if not detour.points:
            self.moving_on(robot.id)  # there
            return None
        step = self._toward(robot, theta, detour.points[0], dt)
        moved = (step.x, step.y) != (robot.x, robot.y)
        # a robot whose centre is nearer a wall than its radius (beside a jamb) may step on toward the
        # way's next point: the way leads out of there, and ``allowed`` keeps it from going deeper
        free = self.free.is_free(step.x, step.y) or not self.free.is_free(robot.x, robot.y)
        if moved and not (free and self.clear(robot, step.x, step.y, fleet) and allowed(step)):
            # the arc swings it where it may not go: face the point squarely first, else something
            # moved into the way: plan again later
            square = self._toward(robot, theta, detour.points[0], dt, facing=0.05)
            if (square.x, square.y) == (robot.x, robot.y) and square.omega != 0.0:
                return square
            self._detours.pop(robot.id, None)
            return None
        return step

    def _toward(self, robot: Body, theta: float, point: tuple[float, float], dt: float, facing: float = 0.5) -> Step:
        """A step toward ``point``: on the spot while the robot faces more than ``facing`` rad
        away from it (turning on the spot never touches anything), else along an arc."""
        cfg = self.controller
        turn = wrap(math.atan2(point[1] - robot.y, point[0] - robot.x) - theta)
        omega = max(-cfg.max_turn_rate, min(cfg.max_turn_rate, turn / dt))
        if abs(turn) > facing:
            return Step(robot.x, robot.y, wrap(theta + omega * dt), 0.0, omega)
        v = min(cfg.speed, math.hypot(point[0] - robot.x, point[1] - robot.y) / dt)
        nx, ny, nth = integrate(robot.x, robot.y, theta, v, omega, dt)
        return Step(nx, ny, nth, v, omega)

    def _plan(
        self, robot: Body, path: Path, progress: float, fleet: Mapping[str, Body], *, next_room: bool = False
    ) -> list[tuple[float, float]]:
        """A way around the other robots to the first clear point of the trajectory ahead, within
        the robot's room (``next_room``: or the room the trajectory goes on in, when every opening
        between the two may be driven through); [] when there is none."""
        room = self.site.room_at(robot.x, robot.y)
        if room is None:
            return []
        rooms = [room]
        others = [(o.x, o.y) for o in fleet.values() if o.id != robot.id]
        keep = 2.0 * self.radius + self.clearance
        goal = None
        s = min(progress + 0.3, path.length)  # near its end, the end itself is the goal
        while s <= path.length + 1e-9:  # as far as the trajectory stays in the room: past a whole queue line
            p = path.point_at(s)
            if not any(r.contains(p[0], p[1]) for r in rooms):
                beyond = self.site.room_at(p[0], p[1])
                if not next_room or len(rooms) > 1 or beyond is None or not self._open_between(room.id, beyond.id):
                    break
                rooms.append(beyond)
            if self.free.is_free(*p) and all(math.dist(p, o) >= keep for o in others):
                goal = p
                break
            s += 0.1
        if goal is None:
            return []
        return self._search(robot, tuple(rooms), goal, others)

    def _open_between(self, room_id: str, other_id: str) -> bool:
        """Whether the rooms have an opening between them, each of which may be driven through."""
        between = [o for o, other in self.site.neighbours(room_id) if other == other_id]
        return bool(between) and all(self.passable(o) for o in between)

    def _room_cells(self, rooms: tuple[Room, ...]) -> tuple[np.ndarray, tuple[float, float]]:
        """The free cells of the rooms' bounding rectangle that lie in one of the rooms, and its origin."""
        key = "+".join(r.id for r in rooms)
        hit = self._rooms.get(key)
        if hit is None:
            x0, y0 = min(r.rect[0] for r in rooms), min(r.rect[1] for r in rooms)
            x1, y1 = max(r.rect[2] for r in rooms), max(r.rect[3] for r in rooms)
            res = self.resolution
            nx, ny = max(int((x1 - x0) / res), 1), max(int((y1 - y0) / res), 1)

            def usable(x: float, y: float) -> bool:
                return self.free.is_free(x, y) and any(r.contains(x, y) for r in rooms)

            cells = np.array(
                [[usable(x0 + (c + 0.5) * res, y0 + (r + 0.5) * res) for c in range(nx)] for r in range(ny)]
            )
            hit = self._rooms[key] = (cells, (x0, y0))
        return hit

    def _search(
        self,
        robot: Body,
        rooms: tuple[Room, ...],
        goal: tuple[float, float],
        others: list[tuple[float, float]],
    ) -> list[tuple[float, float]]:
        """A* on the cells of ``rooms`` from the robot to ``goal``, robots' discs (grown by
        ``clearance``) and the areas kept out (but one it stands in) as obstacles."""
        return self._route(self._field(robot, rooms, others), goal)

    def _field(self, robot: Body, rooms: tuple[Room, ...], others: list[tuple[float, float]]) -> Field:
        """The cells of ``rooms`` a way of ``robot`` may cross, and where it starts."""
        backed = self._backed_off(robot, others)
        start = backed or (robot.x, robot.y)
        cells, (x0, y0) = self._room_cells(rooms)
        res = self.resolution
        ny, nx = cells.shape
        keep = 2.0 * self.radius + self.clearance
        blocked = ~cells
        ys, xs = np.mgrid[0:ny, 0:nx]
        cx, cy = x0 + (xs + 0.5) * res, y0 + (ys + 0.5) * res
        floor = 2.0 * self.radius + self.contact_gap
        for ox, oy in others:
            # a robot already nearer than ``keep`` may still move off: its disc is shrunk to that
            r = max(min(keep, math.dist(start, (ox, oy)) - 0.01), floor)
            blocked = blocked | ((cx - ox) ** 2 + (cy - oy) ** 2 < r * r)
        for ax, ay, bx, by in self.keep_out(robot):
            if not (ax <= robot.x <= bx and ay <= robot.y <= by):
                blocked = blocked | ((cx >= ax) & (cx <= bx) & (cy >= ay) & (cy <= by))
        field = Field(blocked.ravel().tolist(), nx, ny, (x0, y0), res, backed)
        a = field.cell(start)
        if not cells[a // nx, a % nx]:
            # within the walls' clearance (pushed there, or beside a jamb): every cell around may be
            # in it too, so the way first leaves it through the nearest cell that is not
            rows, cols = np.nonzero(~blocked)
            if rows.size == 0:
                return field
            nearest = int(np.argmin((rows - a // nx) ** 2 + (cols - a % nx) ** 2))
            a = int(rows[nearest]) * nx + int(cols[nearest])
            field.leave = [field.centre(a)]
        field.start = a
        return field

    def _route(self, field: Field, goal: tuple[float, float]) -> list[tuple[float, float]]:
        """The way from the field's start to ``goal``: A* over its cells, then only the cells where
        the way must turn, each leg a straight line over free cells."""
        a, b = field.start, field.cell(goal)
        if a is None or field.blocked[b]:
            return []
        route = field.shortest(a, b)
        if not route:
            return []

        def straight(a: int, b: int) -> bool:
            # over free cells of this grid, and of the fine grid the robot's steps keep to: a leg
            # cutting a corner of the fine grid's free space would come nearer a wall than its clearance
            return field.straight(a, b) and self._leg_free(field.centre(a), field.centre(b))

        points = [field.centre(c) for c in _corners(route, straight)]
        return [*([field.backed] if field.backed else []), *field.leave, *points, goal]

    def _leg_free(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """Whether every point of the straight leg a-b lies on a free cell of ``free`` (sampled at a
        quarter cell)."""
        grid = self.free
        count = max(math.ceil(math.dist(a, b) / (grid.resolution * 0.25)), 1)
        t = np.linspace(0.0, 1.0, count + 1)
        cols = np.floor((a[0] + (b[0] - a[0]) * t - grid.origin[0]) / grid.resolution).astype(np.int64)
        rows = np.floor((a[1] + (b[1] - a[1]) * t - grid.origin[1]) / grid.resolution).astype(np.int64)
        ny, nx = grid.occupied.shape
        if rows.min() < 0 or cols.min() < 0 or rows.max() >= ny or cols.max() >= nx:
            return False
        return not bool(grid.occupied[rows, cols].any())

    def _backed_off(self, robot: Body, others: list[tuple[float, float]]) -> tuple[float, float] | None:
        """Where a robot nearer than ``keep`` to other robots first backs off to before it drives a
        way: straight away from them, until ``keep`` from the nearest (at least ``BACK_OFF``). A way's
        first leg from beside a robot it all but touches runs almost along that robot's disc, and any
        step along it closes in (solid bodies refuse it), so the robot would never set off. None when
        no robot is that near, or the point is not free or would bring it nearer another robot."""
        keep = 2.0 * self.radius + self.clearance
        near = [(o, math.dist((robot.x, robot.y), o)) for o in others]
        near = [(o, d) for o, d in near if 1e-6 < d < keep]
        if not near:
            return None
        ax = sum((robot.x - o[0]) / d for o, d in near)
        ay = sum((robot.y - o[1]) / d for o, d in near)
        norm = math.hypot(ax, ay)
        if norm < 1e-6:
            return None  # between two: no way straight away from both
        length = max(keep - min(d for _, d in near) + 0.01, BACK_OFF)
        point = (robot.x + ax / norm * length, robot.y + ay / norm * length)
        if not self.free.is_free(*point) or self.site.room_at(*point) is None:
            return None
        limit = 2.0 * self.radius + self.contact_gap
        for o in others:
            after = math.dist(point, o)
            if after < limit and after < math.dist((robot.x, robot.y), o):
                return None
        return point


def _corners(route: list[int], straight: Callable[[int, int], bool]) -> list[int]:
    """The cells of ``route`` (after its first, before its last) where it must turn: from each kept
    cell the next is the farthest one reached in a ``straight`` line (over free cells only), so the
    straight legs between them never cut across a blocked cell."""
    kept, here = [], 0
    while here < len(route) - 1:
        nxt = here + 1
        while nxt + 1 < len(route) and straight(route[here], route[nxt + 1]):
            nxt += 1
        if nxt < len(route) - 1:
            kept.append(route[nxt])
        here = nxt
    return kept


@dataclass
class Field:
    """A room's grid for one way: which cells are blocked (row-major, a cell is ``row * nx + col``:
    plain lists and ints, as a search looks at each cell many times), where the way starts."""

    blocked: list[bool]
    nx: int
    ny: int
    origin: tuple[float, float]
    res: float
    backed: tuple[float, float] | None  # where the robot first backs off to (Avoidance._backed_off)
    start: int | None = None  # the start cell (None: no free cell at all)
    leave: list[tuple[float, float]] = field(default_factory=list)  # out of the walls' clearance first
    _reached: list[bool] | None = None

    def cell(self, p: tuple[float, float]) -> int:
        x0, y0 = self.origin
        row = min(max(int((p[1] - y0) / self.res), 0), self.ny - 1)
        return row * self.nx + min(max(int((p[0] - x0) / self.res), 0), self.nx - 1)

    def centre(self, c: int) -> tuple[float, float]:
        row, col = divmod(c, self.nx)
        return (self.origin[0] + (col + 0.5) * self.res, self.origin[1] + (row + 0.5) * self.res)

    def _neighbours(self, c: int) -> list[tuple[int, float, int, int]]:
        """(cell, step length, row, col) of the free cells around ``c``, in ``NEIGHBOURS``' order."""
        row, col = divmod(c, self.nx)
        found = []
        for dr, dc in NEIGHBOURS:
            r, k = row + dr, col + dc
            if 0 <= r < self.ny and 0 <= k < self.nx and not self.blocked[r * self.nx + k]:
                found.append((r * self.nx + k, STEP[dr, dc], r, k))
        return found

    def reaches(self, p: tuple[float, float]) -> bool:
        """Whether a way from the start can end at ``p``'s cell (the start's free cells, labelled once)."""
        if self.start is None:
            return False
        if self._reached is None:
            from scipy import ndimage  # here, not at the top: importing scipy adds 0.3 s to a service's start

            free = ~np.array(self.blocked, dtype=bool).reshape(self.ny, self.nx)
            free.flat[self.start] = True  # (a start on a robot's disc grown by clearance leaves it)
            labels, _ = ndimage.label(free, structure=EIGHT_WAY)
            self._reached = (labels.ravel() == labels.flat[self.start]).tolist()
        return self._reached[self.cell(p)]

    def shortest(self, a: int, b: int) -> list[int]:
        """A* from ``a`` to ``b`` over free cells (8 neighbours; ties broken by cell, row first),
        the cells from ``a`` to ``b``; [] when ``b`` is not reached."""
        brow, bcol = divmod(b, self.nx)
        came: dict[int, int] = {}
        cost = {a: 0.0}
        heap = [(0.0, a)]
        while heap:
            _, c = heapq.heappop(heap)
            if c == b:
                break
            here = cost[c]
            for n, step, r, k in self._neighbours(c):
                g = here + step
                if g < cost.get(n, math.inf):
                    cost[n], came[n] = g, c
                    heapq.heappush(heap, (g + math.hypot(r - brow, k - bcol), n))
        if b not in came:
            return []
        route = [b]
        while route[-1] != a:
            route.append(came[route[-1]])
        route.reverse()
        return route

    def straight(self, a: int, b: int) -> bool:
        """Whether the straight line between the centres of cells ``a`` and ``b`` crosses free cells only."""
        (ar, ac), (br, bc) = divmod(a, self.nx), divmod(b, self.nx)
        steps = 2 * max(abs(br - ar), abs(bc - ac))
        for i in range(1, steps):
            t = i / steps
            if self.blocked[round(ar + t * (br - ar)) * self.nx + round(ac + t * (bc - ac))]:
                return False
        return True
