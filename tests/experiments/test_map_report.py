"""The map sweep's report from a fixed CSV: its heatmaps, its tests per cell and its reading in numbers."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from services.experiments.design import METHODS, SweepSpec
from services.experiments.report import build_report
from services.experiments.results import load_results
from tests.experiments.helpers import row, write_trials

TASKS = (300.0, 600.0)
COSTS = (0.0, 60.0)
TRIALS = 10  # exact Wilcoxon p of ten same-signed distinct differences: 2/1024; Holm over 4 cells x 2 baselines: 0.016


@pytest.fixture(scope="module")
def map_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Without an interruption cost ARROCH and No-feedback give the same times (the same draws); with one ARROCH saves
    20-29 s against No-feedback; No-comm is 50 s slower everywhere. Door openings are equal everywhere."""
    folder = tmp_path_factory.mktemp("map")
    spec = SweepSpec(
        kind="map", methods=METHODS, robots=(3,), objects=3, ps=(0.5,), trials=TRIALS, seed=0, tasks=TASKS, costs=COSTS
    )
    (folder / "sweep.json").write_text(json.dumps(spec.to_json()), encoding="utf-8")
    rows = []
    for task in TASKS:
        for cost in COSTS:
            for i in range(TRIALS):
                base = task + 5.0 * i
                saved = 20.0 + i if cost else 0.0
                for method, team in (("arroch", base - saved), ("no-feedback", base), ("no-comm", base + 50.0 + i)):
                    rows.append(row(method, 3, i, task=task, cost=cost, team=team, doors=5))
    write_trials(folder, rows)
    build_report(folder)
    return folder


def test_levels_are_the_cells_in_the_sweep_order(map_folder: Path) -> None:
    results = load_results(map_folder)
    assert results.kind == "map"
    assert results.levels == [(300.0, 0.0), (300.0, 60.0), (600.0, 0.0), (600.0, 60.0)]
    assert results.level_label((600.0, 60.0)) == "task 600 s, cost 60 s"


def test_map_figures_are_pngs(map_folder: Path) -> None:
    for metric in ("team_completion_time", "sum_of_times", "door_openings"):
        assert (map_folder / f"map_{metric}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(map_folder.glob("*_vs_*.png"))  # no bar figures for the map


def test_tests_per_cell(map_folder: Path) -> None:
    with open(map_folder / "tests.csv", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    team = {
        (r["task_mean"], r["interruption_cost"], r["baseline"]): r
        for r in rows
        if r["metric"] == "team_completion_time"
    }
    assert len(team) == 8
    costly = team[("600", "60", "no-feedback")]
    assert float(costly["mean_diff"]) == pytest.approx(-24.5)  # -(20 + 21 + ... + 29) / 10
    assert float(costly["wilcoxon_p"]) == pytest.approx(2 / 1024, rel=1e-5)  # six significant digits in the CSV
    assert float(costly["primary_p_holm"]) == pytest.approx(8 * 2 / 1024, rel=1e-5)
    assert costly["verdict"] == "lower (significant), within ±30 s (TOST)"  # -24.5 s: significant, inside ±30 s
    assert costly["interval_kind"] == "Hodges–Lehmann, Wilcoxon interval"
    assert float(costly["estimate"]) == pytest.approx(-24.5)  # the Walsh averages of -20..-29: symmetric
    free = team[("600", "0", "no-feedback")]
    assert (free["mean_diff"], free["paired_t"], free["d_z"], free["wilcoxon_p"]) == ("0.000", "", "", "1")
    assert free["verdict"] == "equivalent within ±30 s"


def test_report_reads_the_map_in_numbers(map_folder: Path) -> None:
    report = (map_folder / "REPORT.md").read_text(encoding="utf-8")
    assert "## Map: where feedback pays" in report
    assert "![map_sum_of_times](map_sum_of_times.png)" in report
    assert (
        "**Team completion time, ARROCH − No-feedback** (Δ in s): significantly lower in 2 of 4 cells "
        "(task 300 s / cost 60 s: -24.5 ["
    ) in report
    assert "by interruption cost 0/60 s: 0/2, 2/2; significantly higher in 0; equivalent within ±30 s in 2" in report
    assert "**Team completion time, ARROCH − No-comm** (Δ in s): significantly lower in 4 of 4 cells" in report
    assert "**Door openings, ARROCH − No-feedback** (Δ in openings): significantly lower in 0 of 4 cells" in report
    assert "| 600 | 60 | 10/10 | -24.5 [" in report
    assert "### Lowest team completion time: **partly**" in report  # 6 of 8 lower, 2 equivalent, none higher
    assert "| task_mean | interruption_cost | method |" in report  # the summary's level columns
