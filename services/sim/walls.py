"""Robot-wall contacts, counted every tick like robot-robot ones (:mod:`.overlaps`): a safety figure
of the mission's metrics. How deep a disc reaches into a wall is the executor's
(:class:`runtime.executor.walls.WallDepth`, which its wall guard reads too).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from protocol.site.model import Site
from runtime.executor import Robot
from runtime.executor.walls import TOUCH, WallDepth

from .overlaps import place


@dataclass(frozen=True)
class WallContact:
    robot: str
    place: str  # the opening whose gap is within a radius of the robot's centre, else its room
    depth: float  # m the disc reaches into the wall when the contact starts
    pose: tuple[float, float]


class WallWatch:
    """A safety figure checked every tick, like :mod:`.overlaps`: robots whose disc starts to reach
    into a wall (edge-triggered: one contact however many ticks it lasts), and the deepest any disc
    reached. The executor's wall guard (:mod:`runtime.executor.executor`) refuses any step deeper
    than ``RobotConfig.wall_tolerance`` (by default :data:`TOUCH`, what counts here as a contact);
    this counts contacts independently of how the executor keeps to it."""

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
            if depth <= TOUCH:
                continue
            self.deepest = max(self.deepest, depth)
            touching.add(robot.id)
            if robot.id not in self._touching:
                where = place(self.site, self.radius, robot.x, robot.y)
                started.append(WallContact(robot.id, where, round(depth, 6), (round(robot.x, 6), round(robot.y, 6))))
        self._touching = touching
        return started
