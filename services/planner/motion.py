"""Motion planner P^m: shortest collision-free paths on the site's occupancy grid, and timed trajectories.

The grid is the site's, with every door open (plans go through doors) and obstacles inflated by
the robot radius plus a clearance: the controller's tracking error and the grid's discretisation
(runtime/clearance.py), so a robot following a path whose cells are free never touches a wall.
Every motion a plan needs stays inside one room (approach, load, unload) or crosses one opening
(gothrough); rooms are rectangles, so a straight segment between two
free points is usually free. The planner checks that segment against the grid first and falls back
to A* (8-connected, octile heuristic, confined to the rooms the two points lie in) with line-of-sight
shortening only when it is blocked, e.g. from a start pose pressed against a wall.

Results are cached per pair of points (rounded to a millimetre): the plan's key points (robot
starts, points beside openings, objects, drop points) repeat across legs, robots and replans.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from protocol.site import Site
from runtime.clearance import wall_clearance

Point = tuple[float, float]

GRID_RESOLUTION = 0.05  # m per cell: an 0.8 m door inflated by 2 x 0.316 m keeps at least 3 free cells
# m added to the robot radius: pure pursuit's tracking error (0.02) and this grid's discretisation
# (0.046), runtime/clearance.py
CLEARANCE = wall_clearance(GRID_RESOLUTION)
SAMPLE_SPACING = 0.5  # m between trajectory rows along a straight piece
SNAP_LIMIT = 1.5  # m: how far a key point may move to reach free space


class NoPath(Exception):
    """No collision-free path joins the two points."""


@dataclass(frozen=True)
class Path:
    points: tuple[Point, ...]  # from start to goal, at least one point
    length: float


class MotionPlanner:
    """Paths and trajectories on one site. Not thread-safe (its caches are plain dicts)."""

    def __init__(self, site: Site, *, resolution: float = GRID_RESOLUTION, clearance: float | None = None) -> None:
        if clearance is None:
            clearance = wall_clearance(resolution)
        self.site = site
        self.speed = site.params.robot_speed
        self.grid = site.occupancy_grid(
            resolution=resolution, open_doors=tuple(site.door_leaves), inflate=site.params.robot_radius + clearance
        )
        self._occ = self.grid.occupied
        self._res = self.grid.resolution
        self._paths: dict[tuple[Point, Point], Path] = {}
        self._snapped: dict[Point, Point] = {}
        self._rows: list[list[bool]] | None = None  # the grid as plain lists (A* windows are cut from it)
        self.stats = {"paths": 0, "cache_hits": 0, "astar": 0}

    # ------------------------------------------------------------------ free space

    def is_free(self, p: Point) -> bool:
        return self.grid.is_free(p[0], p[1])

    def snap(self, p: Point, room: str | None = None) -> Point:
        """``p`` if free, else the nearest free cell centre (inside ``room`` when given)."""
        key = (round(p[0], 3), round(p[1], 3))
        hit = self._snapped.get(key)
        if hit is not None:
            return hit
        if self.is_free(p):
            out = p
        else:
            out = self._nearest_free(p, room)
        self._snapped[key] = out
        return out

    def _nearest_free(self, p: Point, room: str | None) -> Point:
        row, col = self.grid.world_to_cell(*p)
        n = int(math.ceil(SNAP_LIMIT / self._res))
        ny, nx = self._occ.shape
        r0, r1 = max(row - n, 0), min(row + n + 1, ny)
        c0, c1 = max(col - n, 0), min(col + n + 1, nx)
        window = ~self._occ[r0:r1, c0:c1]
        rows, cols = np.nonzero(window)
        if rows.size == 0:
            raise NoPath(f"no free space within {SNAP_LIMIT} m of ({p[0]:.2f}, {p[1]:.2f})")
        xs = self.grid.origin[0] + (cols + c0 + 0.5) * self._res
        ys = self.grid.origin[1] + (rows + r0 + 0.5) * self._res
        d2 = (xs - p[0]) ** 2 + (ys - p[1]) ** 2
        if room is not None:
            x0, y0, x1, y1 = self.site.rooms[room].rect
            inside = (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)
            if inside.any():
                d2 = np.where(inside, d2, np.inf)
        i = int(np.argmin(d2))
        return (float(xs[i]), float(ys[i]))

    def segment_free(self, a: Point, b: Point) -> bool:
        """True when every grid cell the segment a-b passes is free (sampled at a quarter cell)."""
        length = math.dist(a, b)
        n = max(int(math.ceil(length / (self._res * 0.25))), 1)
        t = np.linspace(0.0, 1.0, n + 1)
        xs = a[0] + (b[0] - a[0]) * t
        ys = a[1] + (b[1] - a[1]) * t
        cols = np.floor((xs - self.grid.origin[0]) / self._res).astype(np.int64)
        rows = np.floor((ys - self.grid.origin[1]) / self._res).astype(np.int64)
        ny, nx = self._occ.shape
        if rows.min() < 0 or cols.min() < 0 or rows.max() >= ny or cols.max() >= nx:
            return False
        return not bool(self._occ[rows, cols].any())

    # ------------------------------------------------------------------ paths

    def path(self, a: Point, b: Point, rooms: Iterable[str] = ()) -> Path:
        """Shortest collision-free path from ``a`` to ``b`` (cached). ``rooms`` bounds the A* search."""
        key = ((round(a[0], 3), round(a[1], 3)), (round(b[0], 3), round(b[1], 3)))
        hit = self._paths.get(key)
        if hit is not None:
            self.stats["cache_hits"] += 1
            return hit
        self.stats["paths"] += 1
        if math.dist(a, b) < 1e-6:
            result = Path((a,), 0.0)
        elif self.segment_free(a, b):
            result = Path((a, b), math.dist(a, b))
        else:
            self.stats["astar"] += 1
            result = self._astar(a, b, tuple(rooms))
        self._paths[key] = result
        return result

    def distance(self, a: Point, b: Point, rooms: Iterable[str] = ()) -> float:
        return self.path(a, b, rooms).length

    def _bounds(self, a: Point, b: Point, rooms: Sequence[str]) -> tuple[int, int, int, int]:
        """Grid window (r0, r1, c0, c1) the A* may use: the given rooms' rectangles plus a margin."""
        if rooms:
            rects = [self.site.rooms[r].rect for r in rooms if r in self.site.rooms]
        else:
            rects = []
        if not rects:
            rects = [self.site.bounds]
        margin = 0.5
        x0 = min(min(r[0] for r in rects), a[0], b[0]) - margin
        y0 = min(min(r[1] for r in rects), a[1], b[1]) - margin
        x1 = max(max(r[2] for r in rects), a[0], b[0]) + margin
        y1 = max(max(r[3] for r in rects), a[1], b[1]) + margin
        ny, nx = self._occ.shape
        r0, c0 = self.grid.world_to_cell(x0, y0)
        r1, c1 = self.grid.world_to_cell(x1, y1)
        return max(r0, 0), min(r1 + 1, ny), max(c0, 0), min(c1 + 1, nx)

    def _astar(self, a: Point, b: Point, rooms: Sequence[str]) -> Path:
        start = self.grid.world_to_cell(*a)
        goal = self.grid.world_to_cell(*b)
        for cell, label in ((start, "start"), (goal, "goal")):
            if not self.grid.in_bounds(*cell) or self._occ[cell]:
                # A point in an inflated margin (a robot pushed against a wall): leave it through
                # the nearest free cell.
                snapped = self._nearest_free(a if label == "start" else b, None)
                if label == "start":
                    start = self.grid.world_to_cell(*snapped)
                else:
                    goal = self.grid.world_to_cell(*snapped)
        r0, r1, c0, c1 = self._bounds(a, b, rooms)
        if not (r0 <= start[0] < r1 and c0 <= start[1] < c1 and r0 <= goal[0] < r1 and c0 <= goal[1] < c1):
            r0, r1, c0, c1 = 0, self._occ.shape[0], 0, self._occ.shape[1]
        cells = self._search(start, goal, (r0, r1, c0, c1))
        if cells is None and (r0, r1, c0, c1) != (0, self._occ.shape[0], 0, self._occ.shape[1]):
            cells = self._search(start, goal, (0, self._occ.shape[0], 0, self._occ.shape[1]))
        if cells is None:
            raise NoPath(f"no path from ({a[0]:.2f}, {a[1]:.2f}) to ({b[0]:.2f}, {b[1]:.2f})")
        pts = [a] + [self.grid.cell_to_world(r, c) for r, c in cells[1:-1]] + [b]
        pts = self._shorten(pts)
        return Path(tuple(pts), sum(math.dist(p, q) for p, q in pairwise(pts)))

    def _search(
        self, start: tuple[int, int], goal: tuple[int, int], window: tuple[int, int, int, int]
    ) -> list[tuple[int, int]] | None:
        r0, r1, c0, c1 = window
        h, w = r1 - r0, c1 - c0
        sr, sc = start[0] - r0, start[1] - c0
        gr, gc = goal[0] - r0, goal[1] - c0
        occ = self._window(r0, r1, c0, c1, ((sr, sc), (gr, gc)))
        diag = math.sqrt(2.0)
        steps = (
            (1, 0, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, diag),
            (1, -1, diag),
            (-1, 1, diag),
            (-1, -1, diag),
        )

        def heuristic(r: int, c: int) -> float:
            dr, dc = abs(r - gr), abs(c - gc)
            return (dr + dc) + (diag - 2.0) * min(dr, dc)

        best = {(sr, sc): 0.0}
        parent: dict[tuple[int, int], tuple[int, int]] = {}
        heap = [(heuristic(sr, sc), 0.0, sr, sc)]
        while heap:
            _f, g, r, c = heapq.heappop(heap)
            if (r, c) == (gr, gc):
                out = [(r + r0, c + c0)]
                while (r, c) in parent:
                    r, c = parent[(r, c)]
                    out.append((r + r0, c + c0))
                return out[::-1]
            if g > best.get((r, c), math.inf):
                continue
            for dr, dc, cost in steps:
                nr, nc = r + dr, c + dc
                if not (0 <= nr < h and 0 <= nc < w) or occ[nr][nc]:
                    continue
                if dr and dc and (occ[r + dr][c] or occ[r][c + dc]):
                    continue  # no corner cutting
                ng = g + cost
                if ng < best.get((nr, nc), math.inf):
                    best[(nr, nc)] = ng
                    parent[(nr, nc)] = (r, c)
                    heapq.heappush(heap, (ng + heuristic(nr, nc), ng, nr, nc))
        return None

    def _window(self, r0: int, r1: int, c0: int, c1: int, free: tuple[tuple[int, int], ...]) -> list[list[bool]]:
        """The occupancy of a grid window as plain lists (they index much faster than numpy per cell),
        with the ``free`` cells (window coordinates) cleared. Rows are cut from the whole grid's lists,
        made once: converting each window afresh cost as much as the search in it."""
        if self._rows is None:
            self._rows = self._occ.tolist()
        occ = [row[c0:c1] for row in self._rows[r0:r1]]
        for r, c in free:
            occ[r][c] = False
        return occ

    def _shorten(self, pts: list[Point]) -> list[Point]:
        """Greedy line-of-sight shortening of a grid path (keeps the end points)."""
        out = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self.segment_free(pts[i], pts[j]):
                j -= 1
            out.append(pts[j])
            i = j
        return out

    # ------------------------------------------------------------------ trajectories

    def seconds(self, length: float) -> float:
        return length / self.speed

    def trajectory(self, points: Sequence[Point], t0: float, *, theta0: float | None = None) -> list[list[float]]:
        """Rows ``[t, x, y, theta]`` along ``points`` at ``robot_speed`` from time ``t0``.

        Rows are at most ``SAMPLE_SPACING`` apart; theta is the heading of the piece being driven
        (the last piece's heading at the end). A single point gives one row (stay there)."""
        if len(points) == 1 or all(math.dist(points[0], p) < 1e-9 for p in points[1:]):
            x, y = points[0]
            return [[t0, x, y, theta0 if theta0 is not None else 0.0]]
        rows: list[list[float]] = []
        t = t0
        heading = theta0
        for a, b in pairwise(points):
            length = math.dist(a, b)
            if length < 1e-9:
                continue
            heading = math.atan2(b[1] - a[1], b[0] - a[0])
            n = max(int(math.ceil(length / SAMPLE_SPACING)), 1)
            for k in range(n):
                f = k / n
                rows.append([t + f * length / self.speed, a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), heading])
            t += length / self.speed
        rows.append([t, points[-1][0], points[-1][1], heading if heading is not None else 0.0])
        return rows


def polyline_distance(p: Point, rows: Sequence[Sequence[float]]) -> float:
    """Distance from ``p`` to the polyline through trajectory rows ``[t, x, y, theta]``."""
    if not rows:
        return math.inf
    if len(rows) == 1:
        return math.dist(p, (rows[0][1], rows[0][2]))
    best = math.inf
    px, py = p
    for a, b in pairwise(rows):
        ax, ay, bx, by = a[1], a[2], b[1], b[2]
        dx, dy = bx - ax, by - ay
        seg2 = dx * dx + dy * dy
        f = 0.0 if seg2 == 0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / seg2))
        best = min(best, math.hypot(px - (ax + f * dx), py - (ay + f * dy)))
    return best
