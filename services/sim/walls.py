"""How deep a robot's disc reaches into the site's walls: the executor's wall guard (:mod:`.robots`)
and the count of robot-wall contacts (:class:`WallWatch`).

Walls are axis-aligned boxes (``WallSegment.box``: the centre line grown by half the thickness), so
the distance from a disc's centre to each is exact and one numpy expression for all of them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from protocol.site.model import Site

from .overlaps import place

if TYPE_CHECKING:  # for type hints only: the executor (.robots) imports this module
    from .robots import Robot


KNOWN_POINTS = 4096  # depths remembered (a few ticks of every robot's poses and candidate steps)


class WallDepth:
    def __init__(self, site: Site, radius: float) -> None:
        boxes = np.array([w.box for w in site.walls], dtype=np.float64).reshape(-1, 4)
        self._x0, self._y0, self._x1, self._y1 = boxes.T
        self.radius = radius
        # Depths of points asked lately: a robot's pose is asked again and again (by the watch every
        # tick, by the guard as "before" after it was the step's "after"), and the depth of a point
        # never changes. Cleared when full, so it stays small.
        self._known: dict[tuple[float, float], float] = {}

    def depth(self, x: float, y: float) -> float:
        """Metres the disc centred at (x, y) reaches into the nearest wall (<= 0: it touches none)."""
        known = self._known.get((x, y))
        if known is not None:
            return known
        if self._x0.size == 0:
            return -np.inf
        dx = np.maximum(np.maximum(self._x0 - x, x - self._x1), 0.0)
        dy = np.maximum(np.maximum(self._y0 - y, y - self._y1), 0.0)
        depth = float(self.radius - np.sqrt(dx * dx + dy * dy).min())
        if len(self._known) >= KNOWN_POINTS:
            self._known.clear()
        self._known[(x, y)] = depth
        return depth


# A disc reaching less than this (m) into a wall touches it, no more (float rounding at the limit).
TOLERANCE = 1e-3


@dataclass(frozen=True)
class WallContact:
    robot: str
    place: str  # the opening whose gap is within a radius of the robot's centre, else its room
    depth: float  # m the disc reaches into the wall when the contact starts
    pose: tuple[float, float]


class WallWatch:
    """A safety figure checked every tick, like :mod:`.overlaps`: robots whose disc starts to reach
    into a wall (edge-triggered: one contact however many ticks it lasts), and the deepest any disc
    reached. The wall guard (:mod:`.robots`) bounds the depth at ``RobotConfig.wall_tolerance``;
    this counts how often it is used, independently of how the executor keeps to it."""

    def __init__(self, site: Site, radius: float) -> None:
        self.site = site
        self.radius = radius
        self.walls = WallDepth(site, radius)
        self.deepest = 0.0  # m, over the whole run
        self._touching: set[str] = set()

    def check(self, robots: Iterable[Robot]) -> list[WallContact]:
        """The robots whose disc started to reach into a wall since the last check (once per tick)."""
        touching: set[str] = set()
        started: list[WallContact] = []
        for robot in sorted(robots, key=lambda r: r.id):
            depth = self.walls.depth(robot.x, robot.y)
            if depth <= TOLERANCE:
                continue
            self.deepest = max(self.deepest, depth)
            touching.add(robot.id)
            if robot.id not in self._touching:
                where = place(self.site, self.radius, robot.x, robot.y)
                started.append(WallContact(robot.id, where, round(depth, 6), (round(robot.x, 6), round(robot.y, 6))))
        self._touching = touching
        return started
