"""The lockstep handshake's invariants (runtime/lockstep.py), on the rules alone: no Zenoh, no process.

- the simulator's gate never lets time advance while a feedback's ack, a plan answering the world
  and constraints versions, or a front command is outstanding, and says which, in that order;
- a plan older than the one held, and a clock of another world version, are ignored;
- what the simulator's Clock says it waits for is what the planner's rules answer: it plans exactly
  when the gate waits for a plan, and holds while the gate waits for a feedback's ack;
- a whole handshake with plans delivered late and out of order: time advances only at versions a
  plan answered;
- the restrictor's rules: when a feedback takes effect, whether constraints expire on a timer.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from protocol.messages import AWAITING, Clock, PlanStep, TeamPlan
from runtime import lockstep
from runtime.clock import SimClock, WallClock
from runtime.lockstep import (
    CAMERA,
    COMMAND,
    FEEDBACK,
    LOCKSTEP_LEAD,
    NOTHING,
    OPEN,
    PLAN,
    LockstepGate,
    Versions,
    Wait,
    simulator_waits,
)

ROBOTS = ("r0", "r1")
versions = st.integers(0, 6)
action_ids = st.integers(0, 6)


def team_plan(plan_id: int, world: int, constraints: int, fronts: dict[str, int]) -> TeamPlan:
    robots = {
        rid: [PlanStep(action="approach", args=["d0"], start=0.0, end=1.0, action_id=aid)]
        for rid, aid in fronts.items()
    }
    return TeamPlan(plan_id=plan_id, world_version=world, constraints_version=constraints, robots=robots)


plans = st.builds(
    team_plan,
    plan_id=st.integers(0, 8),
    world=versions,
    constraints=versions,
    fronts=st.dictionaries(st.sampled_from(ROBOTS), action_ids),
)
# What may happen to a gate: a plan arrives, a feedback is sent, or its answer comes (accepted,
# refused, or none after every attempt) with the constraints version an accepted one made.
gate_inputs = st.lists(
    st.one_of(
        plans,
        st.just("sent"),
        st.tuples(st.sampled_from((True, False, None)), versions),
    ),
    max_size=12,
)
received = st.dictionaries(st.sampled_from(ROBOTS), action_ids)  # the last command id each robot got


def gate_after(inputs: list) -> LockstepGate:
    gate = LockstepGate()
    for item in inputs:
        if isinstance(item, TeamPlan):
            gate.on_plan(item)
        elif item == "sent":
            gate.feedback_sent()
        else:
            gate.feedback_answered(*item)
    return gate


def sim_clock(gate: LockstepGate, world_version: int, last: dict[str, int]) -> Clock:
    """The Clock the simulator publishes from its gate (services/sim/service.py, _publish_clock)."""
    awaiting, reason = gate.waits_for(world_version, last)
    return Clock(
        time=1.0,
        mode="lockstep",
        world_version=world_version,
        paused=bool(reason),
        awaiting=awaiting,
        constraints_version=gate.constraints_needed,
    )


def held_plan(gate: LockstepGate) -> TeamPlan | None:
    """The plan the gate holds, as the planner that sent it knows it."""
    if gate.plan_id < 0:
        return None
    return TeamPlan(plan_id=gate.plan_id, world_version=gate.plan_world, constraints_version=gate.plan_constraints)


def test_the_awaited_kinds_are_the_clock_messages():
    assert {NOTHING, FEEDBACK, PLAN, COMMAND, CAMERA} == set(AWAITING)


# ---------------------------------------------------------------------------------- the simulator's gate


def reference(inputs: list) -> tuple[TeamPlan | None, int, int]:
    """What the gate must hold after ``inputs``, worked out on its own: the plan with the highest
    id (the latest of equal ids), the feedback not answered, the highest accepted constraints version."""
    plan: TeamPlan | None = None
    pending = needed = 0
    for item in inputs:
        if isinstance(item, TeamPlan):
            plan = item if plan is None or item.plan_id >= plan.plan_id else plan
        elif item == "sent":
            pending += 1
        else:
            accepted, cv = item
            pending = max(pending - 1, 0)  # an answer with nothing outstanding changes no count
            needed = max(needed, cv) if accepted else needed
    return plan, pending, needed


@given(gate_inputs, versions, received)
def test_time_advances_only_when_nothing_is_outstanding(inputs, world_version, last):
    """The gate is open exactly when no feedback awaits its ack, the plan held answers the world
    version and the constraints version accepted feedback made, and every front command arrived;
    else it names the first of these that is missing."""
    gate = gate_after(inputs)
    plan, pending, needed = reference(inputs)
    assert (gate.feedback_pending, gate.constraints_needed) == (pending, needed)
    awaiting, reason = gate.waits_for(world_version, last)
    assert (awaiting == NOTHING) == (reason == "")
    if pending:
        assert awaiting == FEEDBACK
    elif plan is None or plan.world_version < world_version or plan.constraints_version < needed:
        assert awaiting == PLAN
    else:
        fronts = {rid: steps[0].action_id for rid, steps in plan.robots.items() if steps[0].action_id > 0}
        missing = [rid for rid, aid in fronts.items() if rid in last and last[rid] < aid]
        assert awaiting == (COMMAND if missing else NOTHING)


@given(gate_inputs, versions, received)
def test_the_clock_never_advances_while_a_feedback_ack_is_outstanding(inputs, world_version, last):
    gate = gate_after([*inputs, "sent"])
    assert gate.waits_for(world_version, last).awaiting == FEEDBACK


@given(gate_inputs, st.sampled_from((True, False, None)), versions)
def test_only_an_accepted_ack_raises_the_constraints_version_awaited(inputs, accepted, cv):
    gate = gate_after(inputs)
    before = gate.constraints_needed
    gate.feedback_sent()
    gate.feedback_answered(accepted, cv)
    assert gate.constraints_needed == (max(before, cv) if accepted else before)


@given(gate_inputs, plans)
def test_a_plan_older_than_the_one_held_is_ignored(inputs, late):
    gate = gate_after(inputs)
    before = (gate.plan_id, gate.plan_world, gate.plan_constraints, dict(gate.fronts))
    taken = gate.on_plan(late)
    assert taken == (late.plan_id >= before[0])
    if not taken:
        assert (gate.plan_id, gate.plan_world, gate.plan_constraints, gate.fronts) == before
    else:
        assert (gate.plan_id, gate.plan_world, gate.plan_constraints) == (
            late.plan_id,
            late.world_version,
            late.constraints_version,
        )


@given(gate_inputs, versions, received)
def test_a_new_world_version_closes_the_gate_until_a_plan_answers_it(inputs, world_version, last):
    gate = gate_after(inputs)
    newer = max(world_version, gate.plan_world) + 1
    assert gate.waits_for(newer, last).awaiting in (FEEDBACK, PLAN)


def test_the_gate_in_words():
    gate = LockstepGate()
    assert gate.waits_for(1, {}) == (PLAN, "waiting for a plan answering world version 1 (latest answers -1)")
    gate.on_plan(team_plan(1, 1, 0, {"r0": 3}))
    assert gate.waits_for(1, {"r0": 2}) == (COMMAND, "waiting for r0's command 3 of plan 1")
    assert gate.waits_for(1, {}) == OPEN  # a robot that has reported no command yet is not waited for
    gate.feedback_sent()
    assert gate.blocker(1, {"r0": 3}) == "waiting for the ack of the human's feedback"
    gate.feedback_answered(True, 4)
    assert gate.waits_for(1, {"r0": 3}) == (PLAN, "waiting for a plan answering constraints version 4")


@given(st.sampled_from(("", "waiting for x")), st.sampled_from(AWAITING[1:4]), st.text(max_size=3), st.text(max_size=3))
def test_the_simulator_waits_for_its_gate_first_then_the_camera_then_the_drivers(gate_reason, kind, camera, drivers):
    gate = Wait(kind, gate_reason) if gate_reason else OPEN
    wait = simulator_waits(gate, camera, drivers)
    expected = gate.awaiting or (CAMERA if camera else "") or (COMMAND if drivers else "")
    assert wait.awaiting == expected
    assert (wait.reason == "") == (not gate_reason and not camera and not drivers)
    for part in (gate_reason, camera, drivers):
        assert part in wait.reason


@given(versions, versions, versions, versions, versions, versions)
def test_answering_is_a_partial_order(w1, c1, w2, c2, w3, c3):
    a, b, c = Versions(w1, c1), Versions(w2, c2), Versions(w3, c3)
    assert a.answers(a)
    if a.answers(b) and b.answers(c):
        assert a.answers(c)
    if a.answers(b) and b.answers(a):
        assert a == b


# ---------------------------------------------------------------------------------- the planner's rules


@given(gate_inputs, versions, received, st.integers(0, 3))
def test_the_planner_plans_exactly_when_the_gate_waits_for_a_plan(inputs, world_version, last, extra):
    """The clock the simulator publishes from its gate, read by the planner holding at least the
    constraints version it names and having sent the plan the gate holds: a plan is awaited exactly
    when the gate waits for one, and a plan made then opens the gate's plan wait."""
    gate = gate_after(inputs)
    clock = sim_clock(gate, world_version, last)
    held_cv = gate.constraints_needed + extra
    sent = held_plan(gate)
    awaited = lockstep.plan_awaited(clock, world_version, held_cv, sent)
    assert awaited == (clock.awaiting == PLAN)
    if awaited:
        gate.on_plan(team_plan(gate.plan_id + 1, world_version, held_cv, {}))
        assert gate.waits_for(world_version, last).awaiting not in (FEEDBACK, PLAN)
        assert not lockstep.plan_awaited(sim_clock(gate, world_version, last), world_version, held_cv, held_plan(gate))


@given(gate_inputs, versions, received)
def test_the_planner_holds_while_the_simulator_waits_for_a_feedback_ack(inputs, world_version, last):
    gate = gate_after([*inputs, "sent"])
    clock = sim_clock(gate, world_version, last)
    assert not lockstep.version_complete(clock, world_version, gate.constraints_needed + 5)
    assert not lockstep.plan_awaited(clock, world_version, gate.constraints_needed + 5, None)


@given(gate_inputs, versions, received)
def test_a_version_is_not_complete_before_the_constraints_version_its_clock_names(inputs, world_version, last):
    gate = gate_after([*inputs, "sent", (True, 7)])
    clock = sim_clock(gate, world_version, last)
    assert not lockstep.version_complete(clock, world_version, 6)
    assert not lockstep.plan_awaited(clock, world_version, 6, None)


@given(versions, versions, st.booleans())
def test_a_clock_of_another_world_version_is_ignored(clock_version, held_version, paused):
    clock = Clock(
        time=0.0, mode="lockstep", world_version=clock_version, paused=paused, awaiting=PLAN if paused else ""
    )
    if clock_version < held_version:
        assert not lockstep.version_complete(clock, held_version, 0)  # that version's clock is still to come
    if clock_version != held_version:
        assert not lockstep.plan_awaited(clock, held_version, 0, None)


@given(st.sampled_from(("realtime", "rate", "wall")), versions)
def test_outside_lockstep_no_plan_is_awaited(mode, version):
    clock = Clock(time=0.0, mode=mode, world_version=version, paused=True, awaiting=PLAN)
    assert not lockstep.awaits(clock, PLAN)
    assert not lockstep.plan_awaited(clock, version, 0, None)


def test_a_service_is_in_lockstep_once_it_has_heard_a_lockstep_clock():
    clock = SimClock()
    assert not lockstep.in_lockstep(clock)  # not synced yet
    clock.update(Clock(time=0.0, mode="rate", src="sim", seq=1))
    assert not lockstep.in_lockstep(clock)
    clock.update(Clock(time=0.0, mode="lockstep", src="sim", seq=2))
    assert lockstep.in_lockstep(clock)
    assert not lockstep.in_lockstep(WallClock())


# ---------------------------------------------------------------------------------- a whole handshake


class Handshake(RuleBasedStateMachine):
    """The simulator, the planner and the restrictor by the rules, plans delivered late and out of
    order. Time advances only through the gate; every step taken at a world version was answered by
    a plan the planner made for that version with the constraints accepted before it."""

    @initialize()
    def start(self) -> None:
        self.gate = LockstepGate()
        self.world = 1  # the simulator's world version
        self.made = 0  # constraints versions the restrictor made
        self._accepted = 0  # the one the last accepted ack named
        self.planner_cv = 0  # the constraints version the planner holds
        self.plan_id = 0
        self.sent: TeamPlan | None = None  # the planner's last plan
        self.in_flight: list[TeamPlan] = []

    def clock(self) -> Clock:
        return sim_clock(self.gate, self.world, {})

    @precondition(lambda self: self.gate.waits_for(self.world, {}) == OPEN)
    @rule(changes_world=st.booleans(), gives_feedback=st.booleans())
    def step(self, changes_world: bool, gives_feedback: bool) -> None:
        # A step is taken only with a plan in hand that the planner made for this very world version
        # (a plan for a later one cannot exist) and with every constraint accepted so far.
        assert self.gate.plan_world == self.world
        assert self.gate.plan_constraints >= self.gate.constraints_needed == self._accepted
        assert self.gate.feedback_pending == 0
        if changes_world:
            self.world += 1
        if gives_feedback:
            self.gate.feedback_sent()

    @precondition(lambda self: self.gate.feedback_pending > 0)
    @rule(accepted=st.sampled_from((True, False, None)))
    def restrictor_answers(self, accepted: bool | None) -> None:
        if accepted:
            self.made += 1
            self._accepted = self.made
        self.gate.feedback_answered(accepted, self.made)

    @rule(hears_constraints=st.booleans())
    def planner_plans_if_awaited(self, hears_constraints: bool) -> None:
        if hears_constraints:  # the ConstraintSet may come late: it travels on its own key
            self.planner_cv = self.made
        if lockstep.plan_awaited(self.clock(), self.world, self.planner_cv, self.sent):
            self.plan_id += 1
            self.sent = TeamPlan(plan_id=self.plan_id, world_version=self.world, constraints_version=self.planner_cv)
            self.in_flight.append(self.sent)

    @precondition(lambda self: self.in_flight)
    @rule(data=st.data())
    def a_plan_arrives(self, data: st.DataObject) -> None:
        plan = self.in_flight.pop(data.draw(st.integers(0, len(self.in_flight) - 1)))
        self.gate.on_plan(plan)

    @invariant()
    def the_planner_plans_only_for_what_is_in(self) -> None:
        if self.sent is not None:
            assert self.sent.world_version <= self.world and self.sent.constraints_version <= self.made

    @invariant()
    def the_held_plan_is_the_newest_delivered(self) -> None:
        assert self.gate.plan_id <= self.plan_id


TestHandshake = Handshake.TestCase
TestHandshake.settings = settings(deadline=None)  # a run of many rules; the machine may be busy


# ---------------------------------------------------------------------------------- the restrictor's rules


@given(st.floats(0.0, 1e6), st.floats(-1e3, 1e3), st.booleans())
def test_a_feedback_takes_effect_at_its_stamp_only_in_lockstep_and_never_before_now(now, offset, in_lockstep):
    stamp = now + offset
    at = lockstep.feedback_time(now, stamp, lockstep=in_lockstep)
    if not in_lockstep:
        assert at == now
    else:
        assert at == (stamp if now <= stamp <= now + LOCKSTEP_LEAD else now)
        assert now <= at <= now + LOCKSTEP_LEAD


def test_constraints_expire_on_a_timer_only_outside_lockstep():
    assert lockstep.expires_on_timer(lockstep=False)
    assert not lockstep.expires_on_timer(lockstep=True)
