"""Sweeps, trials and seeds: the same spec always means the same trials."""

from __future__ import annotations

import hashlib

import pytest

from services.experiments.design import SweepSpec, TrialKey, derive_seed


def spec(**changes: object) -> SweepSpec:
    values: dict[str, object] = dict(
        kind="robots",
        methods=("arroch", "no-feedback", "no-comm"),
        robots=(2, 3),
        objects=3,
        ps=(0.5,),
        trials=3,
        seed=0,
    )
    values.update(changes)
    return SweepSpec(**values)  # type: ignore[arg-type]


def test_derive_seed_is_sha256_of_the_parts() -> None:
    expected = int.from_bytes(hashlib.sha256(b"0|sim|arroch|3|3|0.5|7").digest()[:4], "big") & 0x7FFFFFFF
    assert derive_seed(0, "sim", "arroch", 3, 3, "0.5", 7) == expected


def key(method: str, p: float, trial: int, *, robots: int = 3, task: float = 600.0, cost: float = 0.0) -> TrialKey:
    return TrialKey(method, robots, 3, p, task, cost, trial)


def test_seeds_per_trial_are_paired_across_methods_and_human_parameters() -> None:
    s = spec(kind="laziness", robots=(3,), ps=(0.1, 0.5))
    a = key("arroch", 0.1, 0)
    # One building and one human per (team size, repetition), whatever the method, the probability,
    # her task length and the interruption cost: the conditions are compared on the same draws ...
    for other in (key("no-comm", 0.5, 0), key("no-feedback", 0.1, 0, task=300.0, cost=60.0)):
        assert s.site_seed(a) == s.site_seed(other) and s.sim_seed(a) == s.sim_seed(other)
    # ... and differ from one repetition (and team size, and base seed) to the next.
    sims = {s.sim_seed(key("arroch", 0.1, i, robots=n)) for i in range(3) for n in (2, 3)}
    assert len(sims) == 6
    assert s.site_seed(a) != s.site_seed(key("arroch", 0.1, 1))
    assert spec(seed=1).sim_seed(a) != s.sim_seed(a)


def test_defaults_are_the_simulators() -> None:
    from services.experiments.design import DEFAULT_COST, DEFAULT_P, DEFAULT_TASK, FOCUS_READINGS
    from services.sim.human import FOCUS_READINGS as SIM_READINGS
    from services.sim.human import HumanConfig

    sim = HumanConfig()
    assert (DEFAULT_TASK, DEFAULT_COST, DEFAULT_P) == (sim.task_mean, sim.interruption_cost, sim.door_probability)
    assert FOCUS_READINGS == SIM_READINGS


def test_a_map_sweep_crosses_task_lengths_and_costs() -> None:
    s = spec(kind="map", robots=(3,), tasks=(150.0, 600.0), costs=(0.0, 15.0, 60.0), trials=2)
    assert s.trial_count() == 3 * 2 * 3 * 2 == len(set(s.keys()))
    assert {(k.task, k.cost) for k in s.keys()} == {(t, c) for t in (150.0, 600.0) for c in (0.0, 15.0, 60.0)}
    assert len({s.sim_seed(k) for k in s.keys()}) == 2  # one human per repetition


def test_schedule_runs_every_trial_once_repetition_by_repetition() -> None:
    s = spec()
    schedule = s.schedule()
    assert sorted(schedule) == sorted(s.keys()) and len(set(schedule)) == s.trial_count() == 18
    assert [k.trial for k in schedule] == sorted(k.trial for k in schedule)
    # The CSV's order: condition by condition, the swept variable first.
    assert [(k.method, k.robots) for k in s.keys()[:4]] == [("arroch", 2)] * 3 + [("no-feedback", 2)]


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"methods": ("arroch", "teleport")}, "methods must be among"),
        ({"robots": (0, 2)}, "robots must be distinct integers >= 1"),
        ({"ps": (1.5,)}, "door-opening probabilities"),
        ({"trials": 0}, "trials must be >= 1"),
        ({"kind": "speed"}, "sweep kind"),
        ({"tasks": (0.0,)}, "task lengths"),
        ({"costs": (-1.0,)}, "interruption costs"),
        ({"focus_reading": "lenient"}, "focus reading"),
    ],
)
def test_bad_specs_are_refused_by_name(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        spec(**changes)


def test_spec_round_trip_and_differences() -> None:
    s = spec(human_config="[human]\ntask_mean = 100.0\n")
    assert SweepSpec.from_json(s.to_json()) == s
    assert spec(trials=4).differences(s) == ["trials: 3 vs 4", "human_config: '[human]\\ntask_mean = 100.0\\n' vs None"]


def test_the_earlier_sweeps_json_is_unchanged_by_the_point_sweeps_fields() -> None:
    data = spec().to_json()
    assert not {"human", "points", "domain"} & set(data)  # the same sweep.json as before these fields existed
    assert SweepSpec.from_json(data) == spec()
    assert all(k.point == -1 and "-x" not in k.ident() for k in spec().keys())


def test_a_detour_sweep_crosses_its_points_with_the_methods_on_shared_draws() -> None:
    points = ({"capacity": 1, "door_share": 0.5}, {"capacity": 3, "door_share": 0.5})
    s = spec(kind="detour", robots=(2,), points=points, domain="detour", trials=2)
    assert s.trial_count() == 3 * 2 * 2 == len(set(s.keys()))
    assert s.factor_names() == ("capacity", "door_share")
    by_point = {k.point for k in s.keys()}
    assert by_point == {0, 1} and s.point(s.keys()[-1]) == points[1]
    same = [k for k in s.keys() if k.trial == 1]
    assert len({s.sim_seed(k) for k in same}) == 1 and len({s.site_seed(k) for k in same}) == 1
    assert SweepSpec.from_json(s.to_json()) == s
    assert spec(kind="detour", robots=(2,), points=points, domain="detour").differences(s) == ["trials: 2 vs 3"]


def test_a_points_key_factors_become_its_trials_key() -> None:
    s = spec(kind="sensitivity", robots=(2,), points=({"task_mean": 150.0, "interruption_cost": 60.0, "capacity": 2},))
    (first, *_) = s.keys()
    assert (first.task, first.cost, first.p) == (150.0, 60.0, 0.5)
    assert s.factor_names() == ("capacity",)  # the key has columns for the others


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"kind": "detour"}, "needs points"),
        ({"points": ({"capacity": 2},)}, "takes no points"),
        ({"kind": "detour", "robots": (2,), "points": ({"teleport": 1.0},)}, "unknown factor"),
        ({"kind": "detour", "robots": (2,), "points": ({"capacity": 1.5},)}, "whole number"),
        ({"kind": "detour", "robots": (2,), "points": ({"door_share": 1.5},)}, "outside"),
        ({"kind": "detour", "robots": (2,), "points": ({"door_share": 1 / 3},)}, "six significant digits"),
        ({"kind": "detour", "points": ({"capacity": 2},)}, "one team size"),
        ({"domain": "moon"}, "domain"),
    ],
)
def test_bad_point_sweeps_are_refused_by_name(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        spec(**changes)
