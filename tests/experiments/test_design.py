"""Sweeps, trials and seeds: the same spec always means the same trials."""

from __future__ import annotations

import hashlib

import pytest

from services.experiments.design import SweepSpec, TrialKey, derive_seed


def spec(**changes: object) -> SweepSpec:
    values: dict[str, object] = dict(kind="robots", methods=("arroch", "no-feedback", "no-comm"), robots=(2, 3), objects=3,
                                     ps=(0.5,), trials=3, seed=0)
    values.update(changes)
    return SweepSpec(**values)  # type: ignore[arg-type]


def test_derive_seed_is_sha256_of_the_parts() -> None:
    expected = int.from_bytes(hashlib.sha256(b"0|sim|arroch|3|3|0.5|7").digest()[:4], "big") & 0x7FFFFFFF
    assert derive_seed(0, "sim", "arroch", 3, 3, "0.5", 7) == expected


def test_seeds_per_trial() -> None:
    s = spec(kind="laziness", robots=(3,), ps=(0.1, 0.5))
    a = TrialKey("arroch", 3, 3, 0.1, 0)
    # One building per (team size, repetition), whatever the method and probability ...
    assert s.site_seed(a) == s.site_seed(TrialKey("no-comm", 3, 3, 0.5, 0))
    assert s.site_seed(a) != s.site_seed(TrialKey("arroch", 3, 3, 0.1, 1))
    # ... while the human's draws differ with every field of the key and with the base seed.
    sims = {s.sim_seed(TrialKey(m, 3, 3, p, i)) for m in ("arroch", "no-comm") for p in (0.1, 0.5) for i in range(3)}
    assert len(sims) == 12
    assert spec(seed=1).sim_seed(a) != s.sim_seed(a)


def test_schedule_runs_every_trial_once_repetition_by_repetition() -> None:
    s = spec()
    schedule = s.schedule()
    assert sorted(schedule) == sorted(s.keys()) and len(set(schedule)) == s.trial_count() == 18
    assert [k.trial for k in schedule] == sorted(k.trial for k in schedule)
    # The CSV's order: condition by condition, the swept variable first.
    assert [(k.method, k.robots) for k in s.keys()[:4]] == [("arroch", 2)] * 3 + [("no-feedback", 2)]


@pytest.mark.parametrize("changes, message", [
    ({"methods": ("arroch", "teleport")}, "methods must be among"),
    ({"robots": (0, 2)}, "robots must be distinct integers >= 1"),
    ({"ps": (1.5,)}, "door-opening probabilities"),
    ({"trials": 0}, "trials must be >= 1"),
    ({"kind": "speed"}, "sweep kind"),
])
def test_bad_specs_are_refused_by_name(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        spec(**changes)


def test_spec_round_trip_and_differences() -> None:
    s = spec(human_config="[human]\ntask_mean = 100.0\n")
    assert SweepSpec.from_json(s.to_json()) == s
    assert spec(trials=4).differences(s) == ["trials: 3 vs 4", "human_config: '[human]\\ntask_mean = 100.0\\n' vs None"]
