"""A safety invariant checked every tick: no robot's footprint enters the doorway of a closed door.

The executor keeps robots off doors that are not passable (they stop short and wait, and a hard
guard refuses any step toward a shut gap; see :mod:`runtime.executor.executor`). This watch checks the
outcome independently of how it is achieved: after each tick, a robot whose disc overlaps a door's
gap (the segment between its jambs, where the closed leaf stands) while that door is not passable
(closed, opening, or closing) is *in a closed doorway*. Each entry counts once, however many ticks
the robot stays there, so a fault that drives one robot through one closed door is one crossing.

Doors close only once their doorway is clear, and robots wait until a door is fully open, so a
correct run never reports one; a planner that loses its state, a dropped command or a stale
trajectory must not make one happen either (the fault tests count them).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from runtime.executor import Robot
from runtime.plane import segment_distance

from .doors import Doors

# Overlap below this (m) is touching, not entering: a robot stopped exactly at the guard distance
# must not count, and neither must float rounding on a robot grazing a jamb.
TOLERANCE = 1e-3
BOX_SLACK = 1e-9  # m added to the box test, so float rounding can never skip a robot the exact test counts


@dataclass(frozen=True)
class Crossing:
    robot: str
    door: str
    depth: float  # m the disc reaches into the closed gap (radius - distance to the gap)
    fraction: float  # how far the leaf was open (0 closed .. 1 open, still not passable)
    pose: tuple[float, float, float]


class ClosedDoorWatch:
    """Reports each robot entering a doorway whose door is not passable (edge-triggered)."""

    def __init__(self, doors: Doors, radius: float) -> None:
        self.doors = doors
        self.radius = radius
        self._inside: set[tuple[str, str]] = set()  # (robot, door) in a closed doorway after the last check

    def check(self, robots: Iterable[Robot]) -> list[Crossing]:
        """The robots that entered a closed doorway since the last check (call once per tick)."""
        robots = list(robots)
        inside: set[tuple[str, str]] = set()
        entered: list[Crossing] = []
        for door in self.doors.doors.values():
            if door.passable:
                continue
            a, b = door.gap
            # The gap is axis-aligned with a <= b: a robot farther than a radius from its bounding
            # box along either axis cannot reach it (the exact distance below would say the same).
            reach = self.radius + BOX_SLACK
            x0, y0, x1, y1 = a[0] - reach, a[1] - reach, b[0] + reach, b[1] + reach
            for robot in robots:
                if not (x0 < robot.x < x1 and y0 < robot.y < y1):
                    continue
                depth = self.radius - segment_distance((robot.x, robot.y), a, b)
                if depth <= TOLERANCE:
                    continue
                key = (robot.id, door.id)
                inside.add(key)
                if key not in self._inside:
                    entered.append(
                        Crossing(
                            robot.id,
                            door.id,
                            round(depth, 6),
                            round(door.fraction, 6),
                            (round(robot.x, 6), round(robot.y, 6), round(robot.theta, 6)),
                        )
                    )
        self._inside = inside
        return entered
