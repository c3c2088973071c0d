"""A population of simulated people: priors read from a calibration or stated, persons drawn from them, and the
mixed-effects model recovering a known effect."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from services.experiments.mixed import Observation, fit_mixed
from services.experiments.population import load_population

CALIBRATED = """
[human]
door_probability = 0.42
declare_time = 2.5
task_mean = 480.0

[calibration.door_probability]
estimate = 0.42
interval = [0.30, 0.54]
n = 48

[calibration.declare_time]
estimate = 2.5
interval = [1.5, 3.5]
n = 22

[calibration.puzzle_pieces_per_minute]
estimate = 3.0
interval = [2.0, 4.0]
n = 11

[population.interruption_cost]
distribution = "uniform"
low = 0.0
high = 60.0
"""


def test_a_calibrations_interval_is_read_as_the_spread_of_a_normal_prior(tmp_path: Path) -> None:
    path = tmp_path / "human.toml"
    path.write_text(CALIBRATED, encoding="utf-8")
    population = load_population(path)
    priors = {p.factor: p for p in population.priors}
    assert set(priors) == {"door_probability", "declare_time", "interruption_cost"}
    assert priors["door_probability"].distribution == "normal"
    assert priors["door_probability"].params == pytest.approx({"mean": 0.42, "sd": 0.24 / 3.919928})
    assert "n = 48" in priors["door_probability"].source
    assert population.unused == ["puzzle_pieces_per_minute"]  # named, not silently dropped
    assert population.fixed == {"door_probability": 0.42, "task_mean": 480.0}  # trial-key values go to each person
    assert population.human == {"declare_time": 2.5}
    people = population.persons(2000, seed=0)
    p = np.array([person["door_probability"] for person in people])
    assert p.mean() == pytest.approx(0.42, abs=4 * 0.0612 / math.sqrt(2000))
    assert p.std() == pytest.approx(0.0612, rel=0.1)
    assert all(0.0 <= v <= 1.0 for v in p)
    cost = np.array([person["interruption_cost"] for person in people])  # the stated prior wins
    assert 0.0 <= cost.min() and cost.max() <= 60.0 and cost.mean() == pytest.approx(30.0, abs=2.0)
    assert all(person["task_mean"] == 480.0 for person in people)


def test_each_persons_draw_is_keyed_so_adding_a_factor_moves_no_other(tmp_path: Path) -> None:
    one = tmp_path / "one.toml"
    one.write_text('[population.declare_time]\ndistribution = "normal"\nmean = 3.0\nsd = 1.0\n', encoding="utf-8")
    two = tmp_path / "two.toml"
    two.write_text(
        one.read_text() + '[population.anticipation]\ndistribution = "uniform"\nlow = 0.0\nhigh = 30.0\n',
        encoding="utf-8",
    )
    a = load_population(one).persons(20, seed=5)
    b = load_population(two).persons(20, seed=5)
    assert [p["declare_time"] for p in a] == [p["declare_time"] for p in b]
    assert len({p["declare_time"] for p in a}) == 20 and all(p["declare_time"] >= 0.0 for p in a)


@pytest.mark.parametrize(
    "text, message",
    [
        ('[population.teleport]\ndistribution = "fixed"\nvalue = 1.0\n', "unknown factor"),
        ('[population.declare_time]\ndistribution = "cauchy"\n', "distribution must be one of"),
        ("[calibration.declare_time]\nestimate = 9.0\ninterval = [1.0, 2.0]\n", "outside its interval"),
        ("[human]\ndeclare_time = 2.0\n", r"no \[population.<factor>\] prior"),
    ],
)
def test_a_bad_population_file_is_refused_by_name(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=message):
        load_population(path)


def test_the_mixed_model_recovers_a_known_method_effect_and_person_spread() -> None:
    # 20 persons x 3 missions x 3 methods: y = 600 + u_person + effect(method) + noise, u ~ N(0, 40), noise ~ N(0, 15).
    # ARROCH − No-feedback = -25 s, ARROCH − No-comm = +10 s.
    rng = np.random.default_rng(7)
    effect = {"arroch": 0.0, "no-feedback": 25.0, "no-comm": -10.0}
    observations = []
    for person in range(20):
        u = float(rng.normal(0.0, 40.0))
        for _ in range(3):
            for method, shift in effect.items():
                observations.append(Observation(person, method, 600.0 + u + shift + float(rng.normal(0.0, 15.0))))
    fit = fit_mixed("team_completion_time", observations)
    assert fit.converged and (fit.persons, fit.observations) == (20, 180)
    found = {e.baseline: e for e in fit.effects}
    for baseline, truth in (("no-feedback", -25.0), ("no-comm", 10.0)):
        e = found[baseline]
        assert e.low < truth < e.high and e.p < 0.001  # the interval covers the truth and excludes 0
        assert e.estimate == pytest.approx(truth, abs=8.0)
    assert 20.0 < fit.person_sd < 65.0 and 11.0 < fit.residual_sd < 19.0
    # No effect at all: the interval covers 0.
    null = fit_mixed("x", [Observation(o.person, o.method, o.value - effect[o.method]) for o in observations])
    assert all(e.low < 0.0 < e.high for e in null.effects)


def test_the_mixed_model_says_when_it_cannot_be_fitted() -> None:
    fit = fit_mixed("x", [Observation(0, "arroch", 1.0), Observation(0, "no-comm", 2.0)])
    assert not fit.effects and "two persons" in fit.note
