"""When sim time may advance: the three clock modes (DESIGN §5).

- ``realtime`` and ``rate``: sim time follows the wall clock, ``rate`` sim seconds per wall
  second (1 for realtime). :class:`WallPacer` says how many ticks are due; if the sim falls more
  than ``max_lag`` behind (a slow machine, a stall) it drops the backlog instead of sprinting to
  catch up, so time never jumps and the lag is reported.
- ``lockstep``: sim time advances only while :class:`LockstepGate` is open: the latest TeamPlan
  answers the current ``world_version``, the commands it starts with have arrived, no feedback of
  the human awaits its ack, and the latest plan answers the ``constraints_version`` an accepted
  feedback produced. Time then runs as fast as the machine allows.

Both are pure (the wall time is passed in), so they are tested without a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from protocol.messages import TeamPlan

MODES = ("realtime", "rate", "lockstep")


class WallPacer:
    def __init__(self, rate: float, tick: float, *, max_lag: float = 0.5) -> None:
        if not rate > 0:
            raise ValueError("rate must be > 0")
        self.rate = rate
        self.tick = tick
        self.max_lag = max_lag  # wall seconds of backlog tolerated before it is dropped
        self._anchor_wall: float | None = None
        self._anchor_sim = 0.0
        self.dropped = 0.0  # sim seconds skipped because the sim could not keep up

    def due(self, sim_time: float, wall: float) -> int:
        """Ticks to run now to bring ``sim_time`` up to the wall clock."""
        if self._anchor_wall is None:
            self.resync(sim_time, wall)
        target = self._anchor_sim + (wall - self._anchor_wall) * self.rate  # type: ignore[operator]
        n = math.floor((target - sim_time) / self.tick + 1e-9)
        if n * self.tick > self.max_lag * self.rate:
            self.dropped += n * self.tick
            self.resync(sim_time, wall)
            return 1
        return max(n, 0)

    def resync(self, sim_time: float, wall: float) -> None:
        """Start counting from here (the first call, after a pause or a dropped backlog)."""
        self._anchor_wall = wall
        self._anchor_sim = sim_time


@dataclass
class LockstepGate:
    plan_id: int = -1
    plan_world: int = -1
    plan_constraints: int = 0
    fronts: dict[str, int] = field(default_factory=dict)  # robot -> action_id the plan starts with
    feedback_pending: int = 0  # feedback sent, no answer yet
    constraints_needed: int = 0  # constraints_version the plan must answer (from accepted feedback)

    def on_plan(self, plan: TeamPlan) -> bool:
        """Take a TeamPlan; returns False (and ignores it) when it is older than the one held."""
        if plan.plan_id < self.plan_id:
            return False
        self.plan_id = plan.plan_id
        self.plan_world = plan.world_version
        self.plan_constraints = plan.constraints_version
        self.fronts = {
            rid: steps[0].action_id for rid, steps in plan.robots.items() if steps and steps[0].action_id > 0
        }
        return True

    def feedback_sent(self) -> None:
        self.feedback_pending += 1

    def feedback_answered(self, accepted: bool | None, constraints_version: int) -> None:
        self.feedback_pending = max(self.feedback_pending - 1, 0)
        if accepted:
            self.constraints_needed = max(self.constraints_needed, constraints_version)

    def blocker(self, world_version: int, last_action_ids: dict[str, int]) -> str:
        """Why time may not advance now, or ``""`` when it may."""
        return self.waits_for(world_version, last_action_ids)[1]

    def waits_for(self, world_version: int, last_action_ids: dict[str, int]) -> tuple[str, str]:
        """What time waits for - ``"feedback"``, ``"plan"``, ``"command"`` or ``""`` (the Clock's
        ``awaiting``) - and why, in words."""
        if self.feedback_pending:
            return "feedback", "waiting for the ack of the human's feedback"
        if self.plan_world < world_version:
            return (
                "plan",
                f"waiting for a plan answering world version {world_version} (latest answers {self.plan_world})",
            )
        if self.plan_constraints < self.constraints_needed:
            return "plan", f"waiting for a plan answering constraints version {self.constraints_needed}"
        for rid, action_id in self.fronts.items():
            if rid in last_action_ids and last_action_ids[rid] < action_id:
                return "command", f"waiting for {rid}'s command {action_id} of plan {self.plan_id}"
        return "", ""
