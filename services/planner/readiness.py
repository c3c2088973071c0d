"""Whether the planner knows enough of the robots to make its first plan.

A planner (re)started while a mission is under way knows nothing of it: it plans only once every
robot's pose and status have arrived (the simulator repeats them once a wall second, also while
lockstep time stands still), so its first plan starts from where the robots are and what they carry
and have delivered. With the simulator's clock nothing is planned before that clock ticks (a plan
from the site's start would become the warm start of the first real plan, and the mission would
depend on how fast the simulator started). When nothing has been heard of any robot after
START_GRACE, no mission is running yet and the plan starts from the site's start.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

START_GRACE = 1.5  # wall s to hear a mission under way (statuses come once a second) before planning from the start
STATE_WAIT = 5.0  # wall s to wait for the last robots' poses and statuses before planning without them


@dataclass
class Readiness:
    started_at: float  # monotonic time the service started
    log: logging.Logger
    start_grace: float = START_GRACE
    state_wait: float = STATE_WAIT
    waiting_since: float | None = None  # when planning started to wait for the robots' state
    reported: bool = False  # the warning about planning without some robots was logged

    def ready(
        self,
        now: float,
        *,
        clock_synced: bool,
        missing: list[str],
        heard_any: bool,
        clock_version: int,
        world_version: int,
    ) -> bool:
        """``missing``: robots without pose or status; ``heard_any``: a status of any robot came;
        ``clock_version``: the world version of the site clock (0 before the simulator's);
        ``world_version``: the highest one heard of in messages."""
        if not clock_synced:
            return False  # the simulator's clock is the site's time: nothing to plan before it ticks
        if not missing:
            if self.waiting_since is not None:
                self.log.info("every robot's pose and status in after %.1f s: planning", now - self.waiting_since)
                self.waiting_since = None
            return True
        if not heard_any and not clock_version:
            # Nothing from any robot: a fresh mission plans from the site's start, once a running
            # one has had the time to be heard.
            return now - self.started_at >= self.start_grace
        if self.waiting_since is None:
            self.waiting_since = now
            self.reported = False
            self.log.info(
                "a mission is under way (world v%d): waiting for the pose and status of %s before planning",
                max(world_version, clock_version),
                ", ".join(missing),
            )
        if now - self.waiting_since < self.state_wait:
            return False
        if not self.reported:
            self.reported = True
            self.log.warning(
                "planning without the pose or status of %s (nothing from them in %.0f s)",
                ", ".join(missing),
                self.state_wait,
            )
        return True
