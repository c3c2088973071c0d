"""The planner's side of the simulator's lockstep handshake (counterpart of the sim's ``LockstepGate``).

In lockstep the simulator publishes everything of a world version (statuses, events, door states)
and then its Clock, which says whether it is paused and what for (``awaiting``). A plan made before
that clock came would start from whatever part of the version had arrived, which depends on the
machine's load; planning only at these fixed points makes a lockstep mission the same on a busy
machine as on an idle one. While the simulator waits for the ack of the human's feedback, the planner
does nothing: the ack brings a ConstraintSet and a clock awaiting a plan that answers it.

A TeamPlan lost on its way would leave the simulator waiting forever, so while it stays paused at a
version the current plan answers, the plan is due to be published again every REPEAT_AFTER seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.messages import Clock, TeamPlan

REPEAT_AFTER = 2.0  # wall s the simulator may stay paused at a version the plan answers before the plan is sent again


@dataclass(frozen=True)
class Repeat:
    """The current plan is due to be published again."""

    world_version: int
    paused_for: float  # wall s the simulator has been paused
    first: bool  # the first repeat in this pause


@dataclass
class LockstepFollower:
    repeat_after: float = REPEAT_AFTER
    clock: Clock | None = None  # the simulator's latest clock message
    # (world version, sim time) the simulator is paused at, and since when (wall); None while it runs
    paused: tuple[tuple[int, float], float] | None = None
    repeated_at: float = 0.0

    def on_clock(self, msg: Clock, now: float) -> None:
        self.clock = msg
        if not msg.paused:
            self.paused = None
            return
        where = (msg.world_version, msg.time)
        if self.paused is None or self.paused[0] != where:
            self.paused = (where, now)

    def version_complete(self, world_version: int, constraints_version: int) -> bool:
        """Whether everything the plan for ``world_version`` must answer is in: that version's clock
        (it comes after the version's statuses and events), no feedback ack pending, and the
        constraints version the clock names (``constraints_version`` is the one held here)."""
        clock = self.clock
        if clock is None or clock.world_version < world_version:
            return False
        if clock.paused and clock.awaiting == "feedback":
            return False
        return constraints_version >= clock.constraints_version

    def awaiting(self, what: str, world_version: int) -> Clock | None:
        """The simulator's clock when it is paused in lockstep at ``world_version`` waiting for
        ``what`` (Clock.awaiting); else None."""
        clock = self.clock
        if clock is None or clock.mode != "lockstep" or not clock.paused or clock.awaiting != what:
            return None
        return clock if clock.world_version == world_version else None

    def plan_awaited(self, world_version: int, constraints_version: int, sent: TeamPlan | None) -> bool:
        """Whether the simulator waits for a plan newer than ``sent`` and the news it waits on is in:
        its world version and the constraints version its accepted feedback made."""
        clock = self.awaiting("plan", world_version)
        if clock is None or constraints_version < clock.constraints_version:
            return False
        answered = (
            sent is not None
            and sent.world_version >= clock.world_version
            and sent.constraints_version >= clock.constraints_version
        )
        return not answered  # when answered, what is pending waits for the next version

    def repeat_due(self, sent: TeamPlan | None, now: float) -> Repeat | None:
        """Whether ``sent`` should be published again (the simulator may never have got it); a
        returned Repeat is counted as done."""
        if self.paused is None or sent is None:
            return None
        (version, _), since = self.paused
        if sent.world_version < version or now - max(since, self.repeated_at) < self.repeat_after:
            return None
        first = self.repeated_at < since
        self.repeated_at = now
        return Repeat(version, now - since, first)
