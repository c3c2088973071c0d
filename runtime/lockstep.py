"""The lockstep handshake: when site time may advance, and what each side waits for.

In lockstep (``arroch sim --mode lockstep``, every sweep's trial) the simulator advances site time
only while nobody it depends on still has to answer, so a trial gives the same outcome on a busy
machine as on an idle one. Three processes take part. Every rule here is stated in the handshake's
own counters - world versions, constraints versions, plan ids and action ids - never in wall time:
wall time only decides *when* a lost message is sent again or a run is given up, never what happens.

**States.** The simulator's world is at a ``world_version``, which counts the states the planner
must answer (the mission start, every action done or failed, every opening or closing of a door the
human operates). Its gate (:class:`LockstepGate`) holds the latest TeamPlan (plan id, the
:class:`Versions` it answers, the action id each robot's plan starts with), the feedback queries
still unanswered, and the constraints version the plan must answer (the highest one an accepted ack
named).

**The simulator** steps only while :meth:`LockstepGate.waits_for` is empty. It waits, in this order
(the order is the Clock's ``awaiting``), for

1. ``feedback``: the ack of every feedback of the human it sent (a query on ``feedback``, repeated
   until answered; after the simulator's abort time without an ack the run ends as failed rather
   than go on without it); a refused feedback asks for no constraints;
2. ``plan``: a TeamPlan answering the current world version and that constraints version
   (:meth:`Versions.answers`); a TeamPlan with a lower plan id than the one held is ignored;
3. ``command``: each robot's command for the action its plan starts with (the last id the robot
   got is lower); the planner publishes a plan's commands before the plan;

and, besides the gate (:func:`simulator_waits`), for the overlay of a held camera frame
(``camera``) and for real robots' drivers answering the last odometry (``command``). A tick that
changes the world version ends the stepping; the simulator then publishes that instant's poses, every
status and door state, the events, and last the Clock (``paused``, ``awaiting``, the constraints
version it waits for). While time stands still the Clock goes out again twice a wall second.

**The planner** (:func:`version_complete`, :func:`plan_awaited`) plans for a world version only once
it is complete: that version's Clock has come (it follows the version's statuses and events), the
simulator does not wait for a feedback's ack (the ack brings a new ConstraintSet and a clock awaiting
a plan that answers it), and the constraints version the Clock names is held. It plans at once when
the paused simulator awaits a plan the one it sent does not answer. News the simulator waits for no
plan about (a robot acknowledging its command, a robot starting to wait at a door) is held for the
next world version: a plan made on it would reach the simulator at a moment of the machine's
choosing. Every world version is answered by a TeamPlan, even an unchanged one.

**The restrictor** answers every feedback with one ack (a retry with the same ``seq`` gets the same
one); an accepted ack names the constraints version it made, and that ConstraintSet is published
before the query is answered. In lockstep a feedback takes effect at its own stamp
(:func:`feedback_time`), and constraints expire only when feedback is handled, never on a timer
(:func:`expires_on_timer`): a ConstraintSet published between two world versions would reach the
planner at a moment of the machine's choosing.

Pure logic: no I/O, no clock of its own; the simulator's gate, the planner's follower and the
restrictor call it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from protocol.messages import Clock, TeamPlan

from .clock import SimClock

LOCKSTEP = "lockstep"  # the Clock's mode

# What a paused lockstep simulator waits for (Clock.awaiting; protocol.messages.AWAITING).
NOTHING = ""
FEEDBACK = "feedback"
PLAN = "plan"
COMMAND = "command"
CAMERA = "camera"

LOCKSTEP_LEAD = 120.0  # site s a feedback's stamp may be ahead of the restrictor's clock and still count


class Wait(NamedTuple):
    """What time waits for (a Clock ``awaiting``, :data:`NOTHING` when it may advance) and why, in words."""

    awaiting: str
    reason: str


OPEN = Wait(NOTHING, "")


@dataclass(frozen=True)
class Versions:
    """A point of the handshake: a world version and a constraints version."""

    world: int
    constraints: int

    def answers(self, awaited: Versions) -> bool:
        """Whether a plan made at these versions answers a simulator waiting at ``awaited``."""
        return self.world >= awaited.world and self.constraints >= awaited.constraints

    @classmethod
    def of(cls, message: TeamPlan | Clock) -> Versions:
        return cls(message.world_version, message.constraints_version)


# ---------------------------------------------------------------------------------- the simulator


@dataclass
class LockstepGate:
    """The simulator's gate: what it holds of the plan and the feedback, and what time waits for."""

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
        """A feedback's answer: ``accepted`` None when no ack came (outside lockstep the sender gives up)."""
        self.feedback_pending = max(self.feedback_pending - 1, 0)
        if accepted:
            self.constraints_needed = max(self.constraints_needed, constraints_version)

    def blocker(self, world_version: int, last_action_ids: dict[str, int]) -> str:
        """Why time may not advance now, or ``""`` when it may."""
        return self.waits_for(world_version, last_action_ids).reason

    def waits_for(self, world_version: int, last_action_ids: dict[str, int]) -> Wait:
        """What time waits for at ``world_version``, given the last command id each robot got."""
        if self.feedback_pending:
            return Wait(FEEDBACK, "waiting for the ack of the human's feedback")
        held = Versions(self.plan_world, self.plan_constraints)
        awaited = Versions(world_version, self.constraints_needed)
        if not held.answers(awaited):
            if held.world < awaited.world:
                return Wait(
                    PLAN, f"waiting for a plan answering world version {awaited.world} (latest answers {held.world})"
                )
            return Wait(PLAN, f"waiting for a plan answering constraints version {awaited.constraints}")
        for rid, action_id in self.fronts.items():
            if rid in last_action_ids and last_action_ids[rid] < action_id:
                return Wait(COMMAND, f"waiting for {rid}'s command {action_id} of plan {self.plan_id}")
        return OPEN


def simulator_waits(gate: Wait, camera: str, drivers: str) -> Wait:
    """What the simulator waits for: the gate's reason first, then a held camera frame (``camera``:
    why, or ""), then real robots' drivers (``drivers``: why, or ""); the reasons all in words."""
    awaiting = gate.awaiting or (CAMERA if camera else NOTHING) or (COMMAND if drivers else NOTHING)
    return Wait(awaiting, "; ".join(reason for reason in (gate.reason, camera, drivers) if reason))


# ---------------------------------------------------------------------------------- the planner


def awaits(clock: Clock | None, what: str) -> bool:
    """Whether ``clock`` is a lockstep simulator's, paused waiting for ``what``."""
    return clock is not None and clock.mode == LOCKSTEP and clock.paused and clock.awaiting == what


def version_complete(clock: Clock | None, world_version: int, constraints_version: int) -> bool:
    """Whether everything the plan for ``world_version`` must answer is in, ``clock`` being the
    simulator's latest and ``constraints_version`` the one held: that version's clock, no feedback
    ack pending, and the constraints version the clock names."""
    if clock is None or clock.world_version < world_version:
        return False
    if clock.paused and clock.awaiting == FEEDBACK:
        return False
    return constraints_version >= clock.constraints_version


def plan_awaited(clock: Clock | None, world_version: int, constraints_version: int, sent: TeamPlan | None) -> bool:
    """Whether the simulator waits at ``world_version`` for a plan newer than ``sent`` and the news it
    waits on is in: that world version and the constraints version its accepted feedback made."""
    if clock is None or not awaits(clock, PLAN) or clock.world_version != world_version:
        return False
    if constraints_version < clock.constraints_version:
        return False
    return not answered(sent, clock)  # when answered, what is pending waits for the next version


def answered(sent: TeamPlan | None, clock: Clock) -> bool:
    """Whether the plan ``sent`` answers what ``clock`` waits at (a plan the simulator may have lost)."""
    return sent is not None and Versions.of(sent).answers(Versions.of(clock))


def in_lockstep(clock: object) -> bool:
    """Whether a service's site clock is a lockstep simulator's."""
    return isinstance(clock, SimClock) and clock.synced and clock.mode == LOCKSTEP


# ---------------------------------------------------------------------------------- the restrictor


def feedback_time(now: float, stamp: float, *, lockstep: bool) -> float:
    """The site time a feedback stamped ``stamp`` takes effect at, ``now`` on the restrictor's clock.

    In lockstep the restrictor's clock lags the simulator's by however many clock messages are still
    on their way, so there the feedback's own stamp (the simulator's time when the human gave it)
    counts, when it is not before ``now`` nor more than LOCKSTEP_LEAD after it."""
    if not lockstep:
        return now
    return stamp if now <= stamp <= now + LOCKSTEP_LEAD else now


def expires_on_timer(*, lockstep: bool) -> bool:
    """Whether constraints expire as the site clock passes their window's end; in lockstep they
    expire only when feedback is handled (a set published between two world versions would reach
    the planner at a moment of the machine's choosing)."""
    return not lockstep
