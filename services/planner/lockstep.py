"""The planner's side of the lockstep handshake (:mod:`runtime.lockstep`, the rules; the
simulator holds its ``LockstepGate``), with the wall-time recovery from lost messages.

In lockstep the simulator publishes everything of a world version (statuses, events, door states)
and then its Clock, which says whether it is paused and what for (``awaiting``). A plan made before
that clock came would start from whatever part of the version had arrived, which depends on the
machine's load; planning only at these fixed points makes a lockstep mission the same on a busy
machine as on an idle one. While the simulator waits for the ack of the human's feedback, the planner
does nothing: the ack brings a ConstraintSet and a clock awaiting a plan that answers it.

A TeamPlan lost on its way would leave the simulator waiting forever, so while it stays paused at a
version the current plan answers, the plan is due to be published again every REPEAT_AFTER seconds.
The other way round - the simulator paused for a plan the planner does not make - is a stall
(:meth:`LockstepFollower.stall`): a ConstraintSet that never arrived (the planner asks the restrictor
for it again), or news with no trigger left to answer it (the version is planned for anyway). Wall
time only decides *when* that is done, never what is planned: the answer is the one the lost
message would have given.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from protocol.messages import Clock, TeamPlan
from runtime import lockstep

REPEAT_AFTER = 2.0  # wall s the simulator may stay paused at a version the plan answers before the plan is sent again
STALL_REPORT = 10.0  # wall s of a stall before the planner says what it holds (the sim warns then too)


@dataclass(frozen=True)
class Repeat:
    """The current plan is due to be published again."""

    world_version: int
    paused_for: float  # wall s the simulator has been paused
    first: bool  # the first repeat in this pause


@dataclass(frozen=True)
class Stall:
    """The simulator has been paused for ``paused_for`` wall seconds waiting for a plan newer than
    the one sent, and what to do about it."""

    world_version: int
    constraints_version: int  # the one the simulator's clock names
    paused_for: float
    fetch_constraints: bool  # that constraints version is not held here: ask the restrictor for it
    report: bool  # the first look at this stall past STALL_REPORT

    def describe(self, world_version: int, constraints_version: int, pending: Iterable[object], missing: object) -> str:
        """The stall in words, beside what the planner holds: what is missing shows in the difference."""
        return (
            f"simulator paused {self.paused_for:.0f} s for a plan answering world v{self.world_version}, "
            f"constraints v{self.constraints_version}; held here: world v{world_version}, constraints "
            f"v{constraints_version}, pending news {sorted(map(str, pending))}, missing {missing}"
        )


@dataclass
class LockstepFollower:
    repeat_after: float = REPEAT_AFTER
    clock: Clock | None = None  # the simulator's latest clock message
    # (world version, sim time) the simulator is paused at, and since when (wall); None while it runs
    paused: tuple[tuple[int, float], float] | None = None
    repeated_at: float = 0.0
    stall_seen_at: float = 0.0  # wall time of the last recovery step
    stall_reported: float = 0.0  # when the pause that was reported began

    def on_clock(self, msg: Clock, now: float) -> None:
        self.clock = msg
        if not msg.paused:
            self.paused = None
            return
        where = (msg.world_version, msg.time)
        if self.paused is None or self.paused[0] != where:
            self.paused = (where, now)

    def version_complete(self, world_version: int, constraints_version: int) -> bool:
        """Whether everything the plan for ``world_version`` must answer is in
        (:func:`runtime.lockstep.version_complete`; ``constraints_version`` is the one held here)."""
        return lockstep.version_complete(self.clock, world_version, constraints_version)

    def plan_awaited(self, world_version: int, constraints_version: int, sent: TeamPlan | None) -> bool:
        """Whether the simulator waits for a plan newer than ``sent`` and the news it waits on is in
        (:func:`runtime.lockstep.plan_awaited`)."""
        return lockstep.plan_awaited(self.clock, world_version, constraints_version, sent)

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

    def stall(self, sent: TeamPlan | None, constraints_version: int, now: float) -> Stall | None:
        """A recovery step (at most one every REPEAT_AFTER s) when the simulator has been paused for
        REPEAT_AFTER s or more waiting for a plan newer than ``sent``; None otherwise."""
        clock = self.clock
        if self.paused is None or clock is None or not lockstep.awaits(clock, lockstep.PLAN):
            return None
        (version, _), since = self.paused
        if lockstep.answered(sent, clock):
            return None  # answered: a lost plan is repeat_due's business
        if now - since < self.repeat_after or now - self.stall_seen_at < self.repeat_after:
            return None
        self.stall_seen_at = now
        report = now - since >= STALL_REPORT and self.stall_reported != since
        if report:
            self.stall_reported = since
        return Stall(
            version, clock.constraints_version, now - since, constraints_version < clock.constraints_version, report
        )
