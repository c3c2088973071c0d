"""The sensitivity analysis: its points share their draws (common random numbers), its designs, and its analysis
finding the factor that decides a constructed outcome."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from services.experiments.design import SweepSpec
from services.experiments.record import trial_fields, trial_row
from services.experiments.results import load_results
from services.experiments.sensitivity import (
    SCREEN,
    Design,
    analyse,
    morris_design,
    sobol_design,
    stage_spec,
    what_matters,
)
from services.experiments.sensitivity_report import strict_json
from services.experiments.store import CsvStore
from services.experiments.trial import TrialOutcome

ARGS = argparse.Namespace(robots=2, objects=3, p=0.5, replicates=2, seed=0, time_limit=None)


def test_every_point_meets_the_same_buildings_and_human_draws_per_replicate() -> None:
    design = morris_design(list(SCREEN), trajectories=2, levels=4, seed=0)
    spec = stage_spec(ARGS, design, None, {})
    keys = spec.keys()
    assert len(keys) == 3 * len(design.x) * 2 and len({k.point for k in keys}) == len(design.x) == 2 * 12
    for replicate in range(2):
        mine = [k for k in keys if k.trial == replicate]
        assert len({spec.site_seed(k) for k in mine}) == 1  # every point, every method: one building ...
        assert len({spec.sim_seed(k) for k in mine}) == 1  # ... and one human's draws
    first, second = (next(k for k in keys if k.trial == r) for r in (0, 1))
    assert spec.sim_seed(first) != spec.sim_seed(second) and spec.site_seed(first) != spec.site_seed(second)
    # A population is the opposite: each person meets draws of her own.
    people = SweepSpec(
        kind="population",
        methods=("arroch", "no-comm"),
        robots=(2,),
        objects=3,
        ps=(0.5,),
        trials=1,
        seed=0,
        points=({"declare_time": 1.0}, {"declare_time": 4.0}),
    )
    a, b = (k for k in people.keys() if k.method == "arroch")
    assert people.sim_seed(a) != people.sim_seed(b) and people.site_seed(a) != people.site_seed(b)


def test_designs_round_integer_factors_and_hold_the_unchosen_at_their_nominal_values() -> None:
    design = morris_design(list(SCREEN), trajectories=2, levels=4, seed=0)
    points = design.points()
    assert {p["capacity"] for p in points} <= {1, 2, 3} and all(isinstance(p["focus_count"], int) for p in points)
    assert all(0.2 <= p["door_share"] <= 1.0 for p in points)
    assert morris_design(list(SCREEN), 2, 4, 0) == design  # the same seed gives the same sample
    sobol = sobol_design(list(SCREEN), ["capacity", "door_share"], n=4, seed=0)
    assert len(sobol.x) == 4 * (2 + 2)  # Saltelli without second order: N (k + 2)
    assert all(
        p["task_mean"] == 600.0 and p["anticipation"] == 0.0 and p["focus_responsiveness"] == 1.0
        for p in sobol.points()
    )


def _outcome(spec: SweepSpec, key, team: float, human: float) -> TrialOutcome:  # noqa: ANN001
    metrics = {
        "completed": True,
        "time": team,
        "team_completion_time": team,
        "agent_completion_times": {"r0": team - 50.0, "r1": team - 60.0, "human": human},
        "human_door_openings": 2,
        "human": {},
        "feedback": {},
        "robots": {},
        "plan_changes": {"constraint_replans": 0, "plans_changed": 0, "deliveries_reordered": 0, "door_wait_time": 0.0},
    }
    return TrialOutcome(key, "ok", "", metrics)


def test_morris_finds_the_factor_that_decides_the_sign(tmp_path: Path) -> None:
    # Constructed outcome: ARROCH − No-feedback = 40 s × (door_share − 0.6) + 5 s × (capacity − 2), plus one draw's
    # noise in every method (common random numbers cancel it). door_share decides the sign; capacity only shifts it.
    ranges = [r for r in SCREEN if r.name in ("door_share", "capacity", "declare_time")]
    design = morris_design(ranges, trajectories=6, levels=4, seed=1)
    args = argparse.Namespace(**{**vars(ARGS), "replicates": 1})
    spec = stage_spec(args, design, None, {})
    rng = np.random.default_rng(0)
    draw = {r: float(rng.normal(600.0, 60.0)) for r in range(spec.trials)}
    rows = []
    for key in spec.keys():
        point = spec.point(key)
        base = draw[key.trial]
        shift = 40.0 * (point["door_share"] - 0.6) + 5.0 * (point["capacity"] - 2) if key.method == "arroch" else 0.0
        team = base + shift + (30.0 if key.method == "no-comm" else 0.0)
        rows.append(trial_row(spec, _outcome(spec, key, team, team)))
    (tmp_path / "sweep.json").write_text(json.dumps(spec.to_json()), encoding="utf-8")
    CsvStore(tmp_path / "trials.csv", trial_fields(spec)).rewrite(rows)
    analyses = analyse(design, load_results(tmp_path), seed=0)
    team_nofb = next(a for a in analyses if (a.metric, a.baseline) == ("team_completion_time", "no-feedback"))
    effects = {e.name: e for e in team_nofb.effects}
    assert effects["door_share"].mu_star > effects["capacity"].mu_star > effects["declare_time"].mu_star
    assert effects["declare_time"].mu_star == pytest.approx(0.0, abs=1e-9)
    assert effects["door_share"].mu > 0 and effects["door_share"].low_half < 0 < effects["door_share"].high_half
    assert team_nofb.missing == 0 and 0 < team_nofb.lower_share < 1
    assert what_matters(analyses, 2) == ["door_share", "capacity"]
    design.save(tmp_path)
    assert Design.load(tmp_path) == design


def test_a_point_without_a_complete_pair_takes_the_mean_and_is_counted(tmp_path: Path) -> None:
    ranges = [r for r in SCREEN if r.name in ("door_share", "capacity")]
    design = morris_design(ranges, trajectories=2, levels=4, seed=2)
    spec = stage_spec(argparse.Namespace(**{**vars(ARGS), "replicates": 1}), design, None, {})
    rows = []
    for key in spec.keys():
        outcome = _outcome(spec, key, 600.0 + (10.0 * key.point if key.method == "arroch" else 0.0), 600.0)
        if key.point == 1 and key.method == "no-comm":
            outcome = TrialOutcome(key, "timeout", "no end")
        rows.append(trial_row(spec, outcome))
    (tmp_path / "sweep.json").write_text(json.dumps(spec.to_json()), encoding="utf-8")
    CsvStore(tmp_path / "trials.csv", trial_fields(spec)).rewrite(rows)
    analyses = {(a.metric, a.baseline): a for a in analyse(design, load_results(tmp_path), seed=0)}
    assert analyses[("team_completion_time", "no-comm")].missing == 1
    assert analyses[("team_completion_time", "no-feedback")].missing == 0
    assert not math.isnan(analyses[("team_completion_time", "no-comm")].mean)


def test_the_analysis_is_written_as_standard_json_with_null_for_what_could_not_be_computed() -> None:
    text = strict_json({"mu": 1.5, "s1": math.nan, "effects": [{"st": math.inf}, (2.0, -math.inf)], "n": 3})

    def refuse(constant: str) -> None:
        raise ValueError(f"not standard JSON: {constant}")

    expected = {"mu": 1.5, "s1": None, "effects": [{"st": None}, [2.0, None]], "n": 3}
    assert json.loads(text, parse_constant=refuse) == expected
