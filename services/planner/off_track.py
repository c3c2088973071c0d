"""Robots far off the trajectory sent to them: they get a fresh command with the next plan.

Outside lockstep a robot is checked on each pose, at most once per OFF_TRACK_COOLDOWN; in lockstep
all robots are checked when a plan is made, from the poses of that instant (poses between two world
versions fall at wall-clock moments, which depend on the machine's load).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

OFF_TRACK_COOLDOWN = 2.0  # s between two off-track replans for one robot


@dataclass
class OffTrackWatch:
    cooldown: float = OFF_TRACK_COOLDOWN
    force: set[str] = field(default_factory=set)  # robots to command anew with the next plan
    noticed_at: dict[str, float] = field(default_factory=dict)

    def notice(self, robot: str, off: bool, now: float) -> bool:
        """Whether ``robot``, off its trajectory or not (``off``), is newly to be commanded anew."""
        if not off or now - self.noticed_at.get(robot, -math.inf) < self.cooldown:
            return False
        self.noticed_at[robot] = now
        self.force.add(robot)
        return True

    def sweep(self, robots: Iterable[str], is_off: Callable[[str], bool]) -> int:
        """Lockstep: mark every robot of ``robots`` that ``is_off``; how many were newly marked."""
        added = 0
        for robot in robots:
            if robot not in self.force and is_off(robot):
                self.force.add(robot)
                added += 1
        return added

    def take(self) -> set[str]:
        """The robots to command anew, and a fresh start."""
        out, self.force = self.force, set()
        return out
