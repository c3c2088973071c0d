"""The human model alone, over thousands of seeded trials: its statistics match its parameters.

Bounds are four standard errors of the quantity tested (a binomial proportion or a mean), so a
correct model fails one of them with probability well under 1e-3, and a model that is off by
a few percentage points fails reliably.
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from services.sim.human import METHODS, Declare, HumanConfig, HumanModel, OpenDoor, TaskDone
from services.sim.streams import Streams

DESK = (7.0, 1.0)
DOOR = {"d": (7.0, 4.0)}  # 3 m from her desk: 3 s each way at 1 m/s


def model(method: str, seed: int, **config) -> HumanModel:
    return HumanModel(HumanConfig(**config), method, Streams(seed), DESK, dict(DOOR))


def run(h: HumanModel, *, until: float, dt: float, waiting=None, door_open=False):
    """Step ``h`` to ``until``; ``waiting`` maps robot -> since (robots waiting at door d)."""
    actions, t = [], 0.0
    while t < until - 1e-9:
        for a in h.step(t, dt, {"d": dict(waiting or {})}, {"d": door_open}):
            actions.append((t + dt, a))
        t += dt
    return actions


def within(observed: float, expected: float, n: int) -> bool:
    """A proportion within 4 standard errors of ``expected``."""
    return abs(observed - expected) <= 4.0 * math.sqrt(expected * (1 - expected) / n)


def test_task_time_has_the_configured_mean_and_spread():
    durations = []
    for seed in range(3000):
        h = model("no-feedback", seed, focus_count=0)
        ((t, done),) = [(t, a) for t, a in run(h, until=2000.0, dt=50.0) if isinstance(a, TaskDone)]
        durations.append(done.time)
        assert done.time == pytest.approx(h.task_duration)  # no interruption: exactly her task
    d = np.array(durations)
    assert abs(d.mean() - 600.0) <= 4 * 60.0 / math.sqrt(len(d))
    assert d.std(ddof=1) == pytest.approx(60.0, rel=0.06)


def test_every_door_trip_costs_her_task_time():
    walk = 3.0  # her desk is 3 m from the door
    for seed in range(10):
        h = model("no-feedback", seed, door_probability=0.5, focus_count=0)
        actions = run(h, until=4000.0, dt=0.5, waiting={"r0": 0.0, "r1": 100.0})
        done = [a for _, a in actions if isinstance(a, TaskDone)][0]
        trip = 2 * walk + h.config.open_time
        assert len(h.opened_at) > 10  # the test is not vacuous
        assert h.counters.time_away == pytest.approx(len(h.opened_at) * trip, abs=1e-6)
        # A trip under way when she would have finished delays her by all of it.
        before = sum(1 for t in h.opened_at if t - walk < done.time)
        assert done.time == pytest.approx(h.task_duration + before * trip, abs=1e-6)


def test_every_declaration_costs_her_task_time():
    for seed in range(50):
        h = model("arroch", seed, door_probability=0.0)
        actions = run(h, until=3000.0, dt=0.5)
        done = [a for _, a in actions if isinstance(a, TaskDone)][0]
        assert done.time == pytest.approx(h.task_duration + h.counters.declarations * h.config.declare_time, abs=1e-6)


@pytest.mark.parametrize("p", [0.2, 0.5])
def test_each_decision_about_a_waiting_robot_opens_with_the_door_probability(p):
    decisions = triggers = 0
    for seed in range(150):
        h = model("no-feedback", seed, door_probability=p, focus_count=0, task_mean=3600.0)
        run(h, until=1800.0, dt=5.0, waiting={"r0": 0.0})
        decisions += h.counters.ar_decisions
        triggers += h.counters.ar_triggers
        # One decision per interval at most, and none while she is away.
        assert h.counters.ar_decisions <= 1800.0 / h.config.decision_interval + 1
    assert decisions > 3000
    assert within(triggers / decisions, p, decisions)


@pytest.mark.parametrize("robots", [1, 2, 4])
def test_more_waiting_robots_make_her_more_likely_to_come(robots):
    p, trials, went = 0.3, 3000, 0
    for seed in range(trials):
        h = model("arroch", seed, door_probability=p, focus_count=0)
        run(h, until=0.5, dt=0.5, waiting={f"r{i}": 0.0 for i in range(robots)})
        went += h.counters.door_trips
    assert within(went / trials, 1 - (1 - p) ** robots, trials)


def test_no_comm_goes_to_the_door_with_probability_0_6_every_minute_blind():
    decisions = triggers = 0
    for seed in range(100):
        h = model("no-comm", seed, focus_count=0, task_mean=7200.0)
        actions = run(h, until=3600.0, dt=5.0, waiting={"r0": 0.0})  # a waiting robot changes nothing
        decisions += h.counters.no_comm_decisions
        triggers += h.counters.no_comm_triggers
        assert h.counters.ar_decisions == 0
        opened = [t for t, a in actions if isinstance(a, OpenDoor)]
        # Each opening is one walk (3 s) after a whole minute.
        assert all(abs((t - 3.0) / 60.0 - round((t - 3.0) / 60.0)) < 0.1 for t in opened)
    assert decisions > 4000
    assert within(triggers / decisions, 0.6, decisions)


def test_no_comm_opens_even_when_no_robot_waits():
    h = model("no-comm", 1, focus_count=0, no_comm_probability=1.0)
    actions = run(h, until=300.0, dt=1.0, waiting={})
    assert sum(isinstance(a, OpenDoor) for _, a in actions) >= 4


def test_a2_is_declared_at_about_0_9_of_focus_intervals_in_arroch_only():
    started = declared = 0
    for seed in range(2500):
        h = model("arroch", seed)
        actions = run(h, until=2000.0, dt=30.0)
        started += h.counters.focus_started
        declarations = [(t, a) for t, a in actions if isinstance(a, Declare)]
        declared += len(declarations)
        for t, a in declarations:
            interval = next(f for f in h.focus if f.start <= t and f.start > t - 30.0 - 1e-9)
            assert a.door == "d" and a.minutes == interval.minutes and 2 <= a.minutes <= 4
    assert started > 4000
    assert within(declared / started, 0.9, started)
    for method in ("no-feedback", "no-comm"):
        for seed in range(50):
            h = model(method, seed)
            assert not [a for _, a in run(h, until=2000.0, dt=30.0) if isinstance(a, Declare)]
            assert h.counters.focus_started > 0


CALLED = {
    "arroch": {"door_probability": 1.0},
    "no-feedback": {"door_probability": 1.0},
    "no-comm": {"no_comm_probability": 1.0},
}
ROBOTS_WAITING = {"r0": 0.0, "r1": 0.0, "r2": 0.0}


@pytest.mark.parametrize("method", METHODS)
def test_strict_reading_no_door_is_opened_during_any_focus_interval(method):
    opened_total = focused = 0
    for seed in range(150):
        h = model(method, seed, focus_reading="strict", **CALLED[method])
        actions = run(h, until=1200.0, dt=2.0, waiting=ROBOTS_WAITING)
        assert len(h.opened_at) == sum(isinstance(a, OpenDoor) for _, a in actions)
        for t in h.opened_at:  # the exact instants (actions are reported at the step's end)
            opened_total += 1
            assert not h.in_focus(t), f"opened at {t} during {h.focus}"
        focused += h.counters.focus_started
        assert h.counters.interruptions == 0
    assert opened_total > 500 and focused > 250  # plenty of chances to get it wrong


def test_faithful_reading_arroch_opens_no_door_in_a_declared_interval_but_does_in_an_undeclared_one():
    in_declared = in_undeclared = 0
    for seed in range(300):
        h = model("arroch", seed, **CALLED["arroch"])
        run(h, until=1200.0, dt=2.0, waiting=ROBOTS_WAITING)
        for t in h.opened_at:
            i = h.focus_at(t)
            if i is None:
                continue
            if h.declared[i]:
                in_declared += 1
            else:
                in_undeclared += 1
    assert in_declared == 0
    assert in_undeclared > 0  # about one interval in ten is not declared: the robots still call her away


@pytest.mark.parametrize("method", ["no-feedback", "no-comm"])
def test_faithful_reading_without_a_declaration_she_is_called_away_during_focus(method):
    in_focus = interruptions = 0
    for seed in range(100):
        h = model(method, seed, interruption_cost=15.0, **CALLED[method])
        actions = run(h, until=1500.0, dt=2.0, waiting=ROBOTS_WAITING)
        in_focus += sum(1 for t in h.opened_at if h.in_focus(t))
        interruptions += h.counters.interruptions
        assert h.counters.declarations == 0 and h.counters.turned_back == 0
        assert h.counters.time_lost == pytest.approx(15.0 * h.counters.interruptions)
        done = [a for _, a in actions if isinstance(a, TaskDone)]
        if done:  # every interruption costs her its resumption on top of the trips
            trip = 2 * 3.0 + h.config.open_time
            before = sum(1 for t in h.opened_at if t - 3.0 < done[0].time)
            assert done[0].time == pytest.approx(h.task_duration + before * trip + h.counters.time_lost, abs=1e-6)
    assert in_focus > 100 and interruptions > 100


@pytest.mark.parametrize("reading", ["faithful", "strict"])
def test_the_same_seed_gives_the_same_human_in_every_method(reading):
    """Common random numbers: her task, her focus intervals and the draws about each waiting robot
    do not depend on the method; arroch and no-feedback differ only by the declarations."""
    for seed in range(40):
        humans = {m: model(m, seed, focus_reading=reading) for m in METHODS}
        first = humans["arroch"]
        for h in humans.values():
            assert h.task_duration == first.task_duration
            assert h.focus == first.focus
        # Without focus intervals, seeing the same robots, arroch and no-feedback act identically.
        a, b = (model(m, seed, focus_count=0, focus_reading=reading) for m in ("arroch", "no-feedback"))
        run(a, until=900.0, dt=1.0, waiting={"r0": 0.0, "r1": 50.0})
        run(b, until=900.0, dt=1.0, waiting={"r0": 0.0, "r1": 50.0})
        assert a.opened_at == b.opened_at and a.counters.ar_decisions == b.counters.ar_decisions


def test_a_decision_stream_does_not_shift_when_other_draws_come_first():
    """The k-th decision about robot r at door d is the same verdict whatever was drawn before it:
    r1's first decision, alone or after a decision about r0 in the same step that did not send her."""
    compared = went = 0
    for seed in range(300):
        alone = model("no-feedback", seed, focus_count=0, door_probability=0.5)
        run(alone, until=1.0, dt=1.0, waiting={"r1": 0.0})
        crowded = model("no-feedback", seed, focus_count=0, door_probability=0.5)
        run(crowded, until=1.0, dt=1.0, waiting={"r0": 0.0, "r1": 0.0})
        if crowded.counters.ar_decisions != 2:
            continue  # r0's draw sent her: r1 was not decided about
        compared += 1
        went += alone.counters.ar_triggers
        assert crowded.counters.ar_triggers == alone.counters.ar_triggers
    assert compared > 100 and 0 < went < compared


def test_task_draw_is_one_normal_scaled_so_task_lengths_share_it():
    for seed in range(20):
        short, long = model("arroch", seed, task_mean=300.0), model("arroch", seed, task_mean=900.0)
        assert long.task_duration - short.task_duration == pytest.approx(600.0)


def test_focus_intervals_fit_her_task_and_do_not_overlap():
    starts, lengths = [], []
    for seed in range(2000):
        h = model("arroch", seed)
        # Two, unless both together would fill more than 90 % of her task (then one).
        assert len(h.focus) == 2 or (len(h.focus) == 1 and h.task_duration < 480.0 / 0.9)
        for f in h.focus:
            assert 0.0 <= f.start and f.end <= h.task_duration
            assert round(f.end - f.start, 6) in (120.0, 180.0, 240.0)
            starts.append(f.start / h.task_duration)
            lengths.append(f.minutes)
        assert all(a.end <= b.start for a, b in pairwise(h.focus))
    assert min(starts) < 0.02 and max(starts) > 0.5
    counts = np.bincount(lengths)[2:5] / len(lengths)  # 2, 3 and 4 minutes equally likely
    assert all(within(c, 1 / 3, len(lengths)) for c in counts)


def test_config_file_is_read_and_checked(tmp_path):
    good = tmp_path / "human.toml"
    good.write_text("[human]\ntask_mean = 300.0\nfocus_count = 1\ndoor_probability = 0.25\n")
    cfg = HumanConfig.from_toml(good, door_probability=0.7)
    assert (cfg.task_mean, cfg.focus_count, cfg.door_probability) == (300.0, 1, 0.7)
    bad = tmp_path / "bad.toml"
    bad.write_text("[human]\ntask_meen = 300.0\n")
    with pytest.raises(ValueError, match="task_meen"):
        HumanConfig.from_toml(bad)
    bad.write_text('[human]\nfocus_reading = "lenient"\n')
    with pytest.raises(ValueError, match="focus_reading"):
        HumanConfig.from_toml(bad)
    good.write_text('[human]\nfocus_reading = "strict"\ninterruption_cost = 15\n')
    assert (HumanConfig.from_toml(good).focus_reading, HumanConfig.from_toml(good).interruption_cost) == (
        "strict",
        15.0,
    )
    bad.write_text("[human]\nfocus_count = 1.5\n")
    with pytest.raises(ValueError, match="focus_count: expected an integer, got 1.5"):
        HumanConfig.from_toml(bad)
    with pytest.raises(ValueError, match="door_probability"):
        HumanConfig(door_probability=1.5)
    with pytest.raises(FileNotFoundError):
        HumanConfig.from_toml(tmp_path / "missing.toml")


# ---------------------------------------------------------------------------- anticipation, responsiveness, focus share


def run_planned(h: HumanModel, *, until: float, dt: float, planned: dict[str, float], waiting=None):
    """Step ``h`` with ``planned`` (robot -> planned arrival at door d) shown on her AR view."""
    actions, t = [], 0.0
    while t < until - 1e-9:
        for a in h.step(t, dt, {"d": dict(waiting or {})}, {"d": False}, planned={"d": dict(planned)}):
            actions.append((t + dt, a))
        t += dt
    return actions


@pytest.mark.parametrize("method", ["arroch", "no-feedback"])
def test_with_ar_she_leaves_for_a_planned_arrival_within_her_horizon(method):
    # Sure to go (p = 1): her first trip starts when the robot's arrival at 200 s comes within 30 s, not before,
    # and she is at the door (3 s walk) before the robot.
    for seed in range(20):
        h = model(method, seed, focus_count=0, door_probability=1.0, anticipation=30.0)
        actions = run_planned(h, until=200.0, dt=0.5, planned={"r0": 200.0})
        opened = [t for t, a in actions if isinstance(a, OpenDoor)]
        assert opened and opened[0] == pytest.approx(170.0 + 3.0)
        assert h.counters.anticipated >= 1 and h.counters.ar_decisions == 0


def test_in_no_comm_she_cannot_see_a_plan_and_never_anticipates():
    for seed in range(20):
        h = model("no-comm", seed, focus_count=0, no_comm_probability=0.0, door_probability=1.0, anticipation=60.0)
        actions = run_planned(h, until=400.0, dt=0.5, planned={"r0": 200.0})
        assert not [a for _, a in actions if isinstance(a, OpenDoor)]
        assert h.counters.anticipations == 0


def test_each_anticipation_decision_goes_with_the_door_probability():
    p, decisions, went = 0.3, 0, 0
    for seed in range(3000):
        h = model("no-feedback", seed, focus_count=0, door_probability=p, anticipation=30.0)
        run_planned(h, until=171.0, dt=1.0, planned={"r0": 200.0})  # one decision: at 170 s
        decisions += h.counters.anticipations
        went += h.counters.anticipated
    assert decisions == 3000
    assert within(went / decisions, p, decisions)


def test_anticipation_is_off_by_default_and_moves_no_other_draw():
    # Default (anticipation 0): a plan on her view changes nothing. On, with no arrival within reach: nothing either.
    for seed in range(30):
        base = model("arroch", seed, door_probability=0.5)
        shown = model("arroch", seed, door_probability=0.5)
        reach = model("arroch", seed, door_probability=0.5, anticipation=20.0)
        run(base, until=900.0, dt=1.0, waiting={"r0": 0.0, "r1": 50.0})
        run_planned(shown, until=900.0, dt=1.0, planned={"r2": 5000.0}, waiting={"r0": 0.0, "r1": 50.0})
        run_planned(reach, until=900.0, dt=1.0, planned={"r2": 5000.0}, waiting={"r0": 0.0, "r1": 50.0})
        assert base.opened_at == shown.opened_at == reach.opened_at
        assert base.counters == shown.counters == reach.counters


def test_a_waiting_robot_is_not_anticipated_and_a_declared_focus_stops_anticipation():
    h = model("no-feedback", 3, focus_count=0, door_probability=0.0, anticipation=60.0)
    run_planned(h, until=100.0, dt=1.0, planned={"r0": 50.0}, waiting={"r0": 0.0})
    assert h.counters.anticipations == 0 and h.counters.ar_decisions > 0
    for seed in range(200):
        h = model("arroch", seed, door_probability=1.0, anticipation=60.0)
        if not h.declared or not h.declared[0]:
            continue
        f = h.focus[0]
        run_planned(h, until=f.end - 1.0, dt=1.0, planned={"r0": f.end - 10.0})
        assert not [t for t in h.opened_at if f.start <= t < f.end]


@pytest.mark.parametrize("responsiveness", [0.0, 0.5])
def test_focus_responsiveness_scales_her_chances_during_an_undeclared_focus_only(responsiveness):
    p = 0.4
    tally = {True: [0, 0], False: [0, 0]}  # in focus? -> [decisions, triggers]
    for seed in range(300):
        h = model("no-feedback", seed, door_probability=p, focus_responsiveness=responsiveness)
        for t in np.arange(0.0, 900.0, 10.0):  # one waiting robot each step, seen afresh: one decision when at her desk
            decided, went = h.counters.ar_decisions, h.counters.ar_triggers
            h.step(float(t), 10.0, {"d": {f"r{int(t)}": float(t) + 10.0}}, {"d": False})
            if h.counters.ar_decisions > decided:
                cell = tally[h.in_focus(float(t) + 10.0)]
                cell[0] += 1
                cell[1] += h.counters.ar_triggers - went
    (n_in, k_in), (n_out, k_out) = tally[True], tally[False]
    assert n_in > 1000 and n_out > 1000
    assert within(k_out / n_out, p, n_out)
    assert within(k_in / n_in, responsiveness * p, n_in) if responsiveness else k_in == 0


def test_a_fixed_focus_share_scales_with_her_task_and_is_declared_in_covering_minutes():
    for task in (150.0, 600.0, 900.0):
        for seed in range(50):
            h = model("arroch", seed, task_mean=task, focus_fraction=0.4, focus_count=2)
            total = sum(f.end - f.start for f in h.focus)
            assert total == pytest.approx(0.4 * h.task_duration)
            assert all(a.end <= b.start for a, b in pairwise(h.focus))
            assert all(0.0 <= f.start and f.end <= h.task_duration for f in h.focus)
            assert all(f.minutes == math.ceil((f.end - f.start) / 60.0) for f in h.focus)


def test_planned_arrivals_are_each_robots_first_wait_at_her_door():
    from types import SimpleNamespace as S

    from services.sim.human import planned_arrivals

    plans = {
        "r0": [S(action="approach", args=["d"], start=10.0), S(action="opendoor", args=["d"], start=42.0)],
        "r1": [S(action="opendoor", args=["x"], start=5.0), S(action="opendoor", args=["d"], start=90.0)],
        "r2": [S(action="opendoor", args=["d"], start=70.0), S(action="opendoor", args=["d"], start=300.0)],
    }
    assert planned_arrivals(plans, ["d"]) == {"d": {"r0": 42.0, "r1": 90.0, "r2": 70.0}}
