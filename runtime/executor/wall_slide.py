"""Going along a wall instead of into it: what a robot does when its pursuit would cut a jamb's corner.

Pure pursuit steers for a point ahead on the trajectory, so a robot coming back onto its trajectory
from beside a doorway (after making way, or driving around another robot) heads across the jamb's
corner. The wall guard (:mod:`.executor`) refuses any step that takes the disc more than the
tolerance (a touch) into a wall. Refused, the robot *slides*: it keeps the direction the refused
step wanted, less its part into the wall (the nearest wall point's normal), turns on the spot to face
that way (a differential drive cannot move sideways), and drives along it, until the disc is
``CLEAR`` off every wall or it has slid ``MAX_SLIDE``; then the pursuit steers again. A step straight
at the wall has nothing along it: the guard refuses it and the robot plans its way on the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from runtime.plane import wrap
from runtime.pursuit import ControllerConfig, Step

from .walls import WallDepth

CLEAR = 0.05  # m between the disc and every wall at which a slide ends (a few steps' worth at 0.5 m/s)
MAX_SLIDE = 1.0  # m a robot slides before the pursuit steers again (then it may slide anew)
MIN_ALONG = 0.2  # share of the wanted direction that must lie along the wall for a slide


@dataclass
class _Slide:
    wanted: tuple[float, float]  # unit direction the refused step wanted
    left: float  # m it may still slide


class WallSlide:
    """Per robot: whether it is sliding along a wall, and its next step while it is."""

    def __init__(self, walls: WallDepth, tolerance: float, controller: ControllerConfig) -> None:
        self.walls = walls
        self.tolerance = tolerance
        self.controller = controller
        self._slides: dict[str, _Slide] = {}

    def into_wall(self, x: float, y: float, to_x: float, to_y: float) -> bool:
        """Whether moving the disc from (x, y) to (to_x, to_y) takes it more than the tolerance into
        a wall, deeper than it was (touching, sliding along a wall or getting out of one is allowed)."""
        after = self.walls.depth(to_x, to_y)
        return after > self.tolerance and after > self.walls.depth(x, y) + 1e-9

    def forget(self, robot_id: str) -> None:
        self._slides.pop(robot_id, None)

    def step(self, robot, step: Step, dt: float) -> Step:  # noqa: ANN001 (an executor Robot)
        """``step`` (the pursuit's) as it is, or the slide's step instead: when a slide is under way,
        or ``step`` is one the guard would refuse and has a way along the wall."""
        slide = self._slides.get(robot.id)
        if slide is not None and (slide.left <= 0.0 or self.walls.depth(robot.x, robot.y) <= -CLEAR):
            del self._slides[robot.id]  # clear of the wall (or far enough): the pursuit steers again
            slide = None
        if slide is None:
            dx, dy = step.x - robot.x, step.y - robot.y
            length = math.hypot(dx, dy)
            if length == 0.0 or not self.into_wall(robot.x, robot.y, step.x, step.y):
                return step
            slide = self._slides[robot.id] = _Slide((dx / length, dy / length), MAX_SLIDE)
        heading = self._heading(robot.x, robot.y, slide.wanted)
        if heading is None:
            self.forget(robot.id)
            return step  # straight at the wall: the guard refuses it
        turn = wrap(heading - robot.theta)
        if abs(turn) > self.controller.aligned:
            omega = max(-self.controller.max_turn_rate, min(self.controller.max_turn_rate, turn / dt))
            return Step(robot.x, robot.y, wrap(robot.theta + omega * dt), 0.0, omega)
        distance = min(self.controller.speed * dt, slide.left)
        slide.left -= distance
        to_x, to_y = robot.x + distance * math.cos(heading), robot.y + distance * math.sin(heading)
        return Step(to_x, to_y, heading, distance / dt, turn / dt)

    def _heading(self, x: float, y: float, wanted: tuple[float, float]) -> float | None:
        """The heading of ``wanted`` less its part into the nearest wall, or None when little is left."""
        away = self.walls.away(x, y)
        if away is None:
            return None
        into = wanted[0] * away[0] + wanted[1] * away[1]
        along_x, along_y = (wanted[0] - into * away[0], wanted[1] - into * away[1]) if into < 0.0 else wanted
        if math.hypot(along_x, along_y) < MIN_ALONG:
            return None
        return math.atan2(along_y, along_x)
