"""Right of way between driving robots, simulated or real: a robot keeps a safety margin.

The planner sends each robot to its own spot (queue spots at openings, drop slots), but execution
drifts from the plan: a robot runs ahead of its schedule when an action ends early, or falls behind
when it waits at a door. So each driving robot also checks, every step, the robots around it: a
step that would bring its disc within ``margin`` of another robot's disc, and closer than it is
now, is not taken (the robot stops for that tick; moving apart is always allowed).

Two robots that stop for each other would wait forever. Each robot remembers which robot it
stopped for (``blocked_by``); before stopping for robot B, robot A follows that chain from B, and
if it comes back to A (a cycle of robots waiting on one another), the robot with the highest fixed
priority in the cycle (the smallest id) goes on instead of stopping; nor does a robot wait forever
for one that is parked (its action over, waiting for nothing): once it has been stopped for
``patience`` seconds, it goes on past parked robots. Going on never means touching: robots are
solid (:mod:`.avoidance`), so a robot that goes on comes up to the other and drives
around it where there is room. Robots of separate processes (``arroch robot``) follow one another's
``blocked_by`` through their ``RobotTraffic`` (:mod:`.traffic`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

PARKED = ("done", "idle", "failed")


class Body(Protocol):
    """What the rule reads from a robot (:class:`.executor.Robot`)."""

    id: str
    x: float
    y: float
    phase: str  # "drive" while following a trajectory; "done", "idle", "failed": parked


@dataclass
class RightOfWay:
    radius: float
    margin: float = 0.05  # m kept between two discs
    patience: float = 10.0  # s a robot stops for a parked robot before it goes on
    blocked_by: dict[str, str] = field(default_factory=dict)  # robot -> robot it stopped for last step
    _since: dict[str, float] = field(default_factory=dict)  # robot -> when it last stopped for a robot

    def blocker(self, robot: Body, nx: float, ny: float, fleet: Mapping[str, Body], now: float = 0.0) -> str:
        """The robot that ``robot`` must stop for rather than step to (nx, ny), or "" to go on."""
        limit = 2.0 * self.radius + self.margin
        found = ""
        nearest = math.inf
        patient = False
        for other in fleet.values():
            if other.id == robot.id:
                continue
            after = math.hypot(nx - other.x, ny - other.y)
            if after >= limit:
                continue
            patient = True  # another robot is near: the patience clock keeps running (turning in place too)
            if after >= math.hypot(robot.x - other.x, robot.y - other.y) - 1e-9:
                continue
            if self._out_of_patience(robot.id, other, now):
                continue
            if self._cycle_won(robot.id, other.id):
                continue
            if after < nearest:
                found, nearest = other.id, after
        if found:
            self.blocked_by[robot.id] = found
            self._since.setdefault(robot.id, now)
        elif patient:
            self.blocked_by.pop(robot.id, None)
        else:
            self.forget(robot.id)
        return found

    def _out_of_patience(self, me: str, other: Body, now: float) -> bool:
        if other.phase not in PARKED:
            return False
        return now - self._since.get(me, now) > self.patience

    def _cycle_won(self, me: str, other: str) -> bool:
        """True when ``other`` waits (through a chain) on ``me`` and ``me`` has the priority in that cycle."""
        chain = [other]
        seen = {other}
        nxt = self.blocked_by.get(other)
        while nxt is not None and nxt not in seen:
            if nxt == me:
                return me == min([me, *chain])
            chain.append(nxt)
            seen.add(nxt)
            nxt = self.blocked_by.get(nxt)
        return False

    def forget(self, robot: str) -> None:
        self.blocked_by.pop(robot, None)
        self._since.pop(robot, None)
