"""The report on fixed CSVs: paired statistics against values computed by hand, pairing by trial
index, its tables and files."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from services.experiments.design import METHODS, SweepSpec
from services.experiments.report import build_report
from services.experiments.results import ReportError, load_results
from tests.experiments.helpers import T_975, row, t_two_sided, t_upper_tail, write_trials

# Two robots, ARROCH against no-comm over five paired trials (the same as test_stats, by hand):
#   team: d = -20 -15 0 -30 -10, mean -15, sd sqrt(125), se 5, t = -3 (4 df); Wilcoxon: R+ = 0, R- = 10, p = 2/16.
#   doors: d = -1 -1 0 -2 -1 (nonzero -1 -1 -2 -1: of the 16 sign patterns only all-minus and all-plus reach |S| = 5),
#   permutation p = 2/16.
A = [600.0, 610.0, 620.0, 630.0, 640.0]
B = [620.0, 625.0, 620.0, 660.0, 650.0]
DOORS_A = [3, 4, 5, 3, 4]
DOORS_B = [4, 5, 5, 5, 5]


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture
def fixed(tmp_path: Path) -> Path:
    rows = [row("arroch", 2, i, team=v, doors=d) for i, (v, d) in enumerate(zip(A, DOORS_A, strict=True))]
    rows += [row("no-comm", 2, i, team=v, doors=d) for i, (v, d) in enumerate(zip(B, DOORS_B, strict=True))]
    # Trial 5 completed for ARROCH only: its pair is dropped from the paired tests (not from ARROCH's mean).
    rows.append(row("arroch", 2, 5, team=700.0, doors=9))
    rows.append(
        row("no-comm", 2, 5, team=None, doors=None, status="timeout", reason="no end of mission within 900 s wall")
    )
    write_trials(tmp_path, rows)
    return tmp_path


def test_pairs_by_trial_index_drop_a_failed_trial(fixed: Path) -> None:
    results = load_results(fixed)
    pairs = results.pairs("team_completion_time", 2, "arroch", "no-comm")
    assert [p.trial for p in pairs] == [0, 1, 2, 3, 4]
    assert [(p.a, p.b) for p in pairs] == list(zip(A, B, strict=True))
    assert len(results.values("arroch", 2, "team_completion_time")) == 6


def test_pairs_follow_the_trial_index_not_the_row_order(tmp_path: Path) -> None:
    rows = [row("no-comm", 3, i, team=500.0 + i, doors=1) for i in (2, 0, 1)]
    rows += [row("arroch", 3, i, team=400.0 + i, doors=1) for i in (0, 1, 3)]  # trial 2 missing, trial 3 alone
    write_trials(tmp_path, rows)
    pairs = load_results(tmp_path).pairs("team_completion_time", 3, "arroch", "no-comm")
    assert [(p.trial, p.a, p.b) for p in pairs] == [(0, 400.0, 500.0), (1, 401.0, 501.0)]


def test_summary_and_tests_match_hand_computed_values(fixed: Path) -> None:
    build_report(fixed)
    summary = {r["method"]: r for r in _csv(fixed / "summary.csv")}
    nocomm = summary["no-comm"]
    assert float(nocomm["team_completion_time_mean"]) == pytest.approx(635.0)
    # b: mean 635, deviations -15 -10 -15 25 15: squares 225+100+225+625+225 = 1400, variance 350.
    half = T_975[4] * math.sqrt(350 / 5)
    assert float(nocomm["team_completion_time_ci_low"]) == pytest.approx(635.0 - half, abs=1e-3)
    assert float(nocomm["team_completion_time_ci_high"]) == pytest.approx(635.0 + half, abs=1e-3)
    # The timed-out trial is counted but kept out of the statistics; the human was slowest in every completed one.
    assert (nocomm["trials"], nocomm["timeout"], nocomm["team_completion_time_n"]) == ("6", "1", "5")
    assert (nocomm["human_slowest"], nocomm["human_slowest_share"]) == ("5", "1.000")
    assert float(summary["arroch"]["team_completion_time_mean"]) == pytest.approx(sum(A + [700.0]) / 6)

    tests = {(r["metric"], r["baseline"]): r for r in _csv(fixed / "tests.csv")}
    team = tests[("team_completion_time", "no-comm")]
    assert (team["robots"], team["n_pairs"], team["n_nonzero"]) == ("2", "5", "4")
    assert float(team["mean_arroch"]) == pytest.approx(620.0)  # the pairs' mean, trial 5 left out
    assert float(team["mean_diff"]) == pytest.approx(-15.0)
    assert float(team["t_ci_low"]) == pytest.approx(-15 - T_975[4] * 5, abs=1e-3)
    assert float(team["sd_diff"]) == pytest.approx(math.sqrt(125), abs=1e-3)
    assert float(team["paired_t"]) == pytest.approx(-3.0)
    assert float(team["paired_t_p"]) == pytest.approx(t_two_sided(-3.0, 4), abs=1e-5)
    assert (float(team["wilcoxon_w"]), float(team["wilcoxon_p"])) == (0.0, 0.125)
    assert team["perm_p"] == "" and team["primary_test"] == "wilcoxon"
    assert float(team["primary_p"]) == 0.125
    assert float(team["d_z"]) == pytest.approx(-15 / math.sqrt(125), abs=1e-5)
    assert float(team["tost_margin"]) == 30.0
    assert float(team["tost_p"]) == pytest.approx(t_upper_tail(3.0, 4), abs=1e-5)
    # The sum of times moves with the team time here (human + 2 robots 100 s earlier): d = 3 x the team's.
    total = tests[("sum_of_times", "no-comm")]
    assert float(total["mean_diff"]) == pytest.approx(-45.0)
    assert float(total["d_z"]) == pytest.approx(float(team["d_z"]), abs=1e-5)

    doors = tests[("door_openings", "no-comm")]
    assert doors["primary_test"] == "permutation"
    assert float(doors["mean_diff"]) == pytest.approx(-1.0)
    assert float(doors["perm_p"]) == pytest.approx(2 / 16)
    assert float(doors["primary_p"]) == float(doors["perm_p"])
    # One level, one baseline: Holm leaves a single p as it is. Doors: p = 0.125 and d outside ±0.5: not significant.
    # Team time: not significantly lower (0.125), but within ±30 s (TOST p = P(T > 3) = 0.02): equivalent.
    assert float(doors["primary_p_holm"]) == float(doors["primary_p"])
    assert doors["verdict"] == "not significant"
    assert float(team["tost_p_holm"]) == float(team["tost_p"]) < 0.05
    assert team["verdict"] == "equivalent within ±30 s"


def test_report_files(fixed: Path) -> None:
    (fixed / "discussion.md").write_text("Written by a person.\n", encoding="utf-8")
    spec = SweepSpec(kind="robots", methods=("arroch", "no-comm"), robots=(2,), objects=3, ps=(0.5,), trials=6, seed=7)
    (fixed / "sweep.json").write_text(json.dumps(spec.to_json()), encoding="utf-8")
    params = {
        "source": "fixed",
        "human": {
            "focus_reading": "faithful",
            "interruption_cost": 15.0,
            "declare_time": 1.0,
            "task_mean": 600.0,
            "focus_count": 2,
        },
        "varied_per_trial": {"door_probability": [0.5]},
        "mode": "lockstep",
    }
    (fixed / "params.json").write_text(json.dumps(params), encoding="utf-8")
    written = {p.name for p in build_report(fixed)}
    figures = {"door_openings_vs_robots.png", "team_completion_time_vs_robots.png", "sum_of_times_vs_robots.png"}
    assert {"summary.csv", "summary.md", "tests.csv", "REPORT.md"} | figures <= written
    for name in figures:
        assert (fixed / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (fixed / "REPORT.md").read_text(encoding="utf-8")
    assert "1 timeout" in report and "Written by a person." in report
    assert "| focus_reading | faithful |" in report and "| interruption_cost | 15 |" in report
    assert "| base seed | 7 |" in report and "| interruption costs (s) | 0 |" in report
    assert "## Design" in report and "Holm" in report and "±30 s" in report and "±0.5" in report
    assert "### Lowest sum of times: **not confirmed**" in report
    assert "sum of times (s)" in report and "5/5 (100 %)" in report


def test_report_refuses_a_folder_without_results(tmp_path: Path) -> None:
    with pytest.raises(ReportError, match="no trials.csv"):
        build_report(tmp_path)


def test_methods_follow_the_paper_order(fixed: Path) -> None:
    assert load_results(fixed).methods == [m for m in METHODS if m in ("arroch", "no-comm")]


def test_the_contacts_section_reports_walls_and_failed_actions_beside_robot_contacts(tmp_path: Path) -> None:
    figures = [  # (robot contacts, wall contacts, deepest into a wall (m), failed actions) per trial
        ("0", "4", "0.012", "0"),
        ("2", "6", "0.050", "3"),
        ("0", "9", "0.031", "12"),
    ]
    rows = [
        row("arroch", 6, i, team=700.0, doors=3, robot_overlaps=o, wall_contacts=w, wall_depth_max=d, actions_failed=f)
        for i, (o, w, d, f) in enumerate(figures)
    ]
    write_trials(tmp_path, rows)
    build_report(tmp_path)
    report = (tmp_path / "REPORT.md").read_text(encoding="utf-8")
    section = report[report.index("## Contacts and failed actions") :]
    assert "| 6 | arroch | 2 / 3 | 0 | 2 | 6 | 50 | 3 / 12 |" in section, section
    assert "refuses steps past its tolerance" in section  # no params.json: no figure made up
    # the guard's tolerance and the give-up time are quoted from the simulator's params
    motion = {"wall_tolerance": 0.04, "give_up": 9.0, "ask_after": 3.0}
    (tmp_path / "params.json").write_text(json.dumps({"robot_motion": motion}), encoding="utf-8")
    build_report(tmp_path)
    report = (tmp_path / "REPORT.md").read_text(encoding="utf-8")
    assert "refuses steps past 40 mm" in report and "a robot kept back 9 s with no way around" in report
    assert "robot_motion: ask_after = 3, give_up = 9, wall_tolerance = 0.04" in report
