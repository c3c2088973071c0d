"""benchmarks/planner.py and benchmarks/planner_ab.py run end to end on a small team and print the
JSON they promise (the figures themselves are for the benchmarks' own runs)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.procs import ROOT

pytestmark = [pytest.mark.slow]


def run(*argv: str) -> dict:
    done = subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_planner_benchmark_reports_its_floors_and_the_load():
    doc = run("benchmarks/planner.py", "--robots", "2", "--seeds", "1", "--replans", "1", "--joint-limit", "0")
    assert doc["settings"]["threads"] == 2
    assert doc["machine"]["load_avg_1min_at_start"] >= 0 and doc["machine"]["load_avg_1min_at_end"] >= 0
    (row,) = doc["results"]
    assert row["robots"] == 2 and row["invalid_plans"] == 0
    assert (
        row["first_plan_seconds"]["n"] == 1 and row["replan_seconds"]["n"] == 2
    )  # one after progress, one after a constraint
    assert doc["floors"] == {}  # no target at 2 robots


def test_the_before_after_benchmark_finds_a_tree_gives_its_own_plans():
    """Compared with itself (the before tree is this one, loaded under another name), every plan is
    the same and the per-plan ratios are there for every variant."""
    doc = run(
        "benchmarks/planner_ab.py",
        *("--before", str(ROOT), "--robots", "2", "--seeds", "1", "--replans", "1"),
        *("--time-limit", "600", "--solve-limit", "60", "--variant", "threads=1"),
    )
    size = doc["sizes"]["2"]
    assert size["same_plans_as_before"] == {"after": True, "after_threads=1": True}
    for name in ("before", "after", "after_threads=1"):
        figures = size["figures"][name]
        assert figures["first_plan_wall"]["n"] == 1 and figures["replan_wall"]["n"] == 2
        assert figures["replan_cpu"]["median"] > 0
    for name in ("after", "after_threads=1"):
        assert set(size["median_ratio_to_before"][name]) == {
            "first_plan_wall",
            "first_plan_cpu",
            "replan_wall",
            "replan_cpu",
        }
    assert doc["machine"]["load_avg_1min_at_start"] >= 0


def test_the_end_to_end_benchmark_splits_a_press_by_hop_and_by_way_in():
    """benchmarks/e2e_latency.py: each hop summarised over all presses and per way in (the AR client's
    sender, the tablet's page); the page → AR client hop is how much longer the page's presses take to
    reach the restrictor."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("e2e_latency", ROOT / "benchmarks" / "e2e_latency.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)

    def press(via: str, to_restrictor: float) -> dict:
        hops = {"to_restrictor": to_restrictor, "planner_waiting": 0.01, "planner_solving": 0.1, "plan_out": 0.001}
        return {"via": via, "hops": hops}

    direct_only = bench.hop_figures([press("direct", 0.02), {"via": "direct", "ack": None}])
    assert set(direct_only) == set(bench.HOPS) and direct_only["to_restrictor"]["n"] == 1
    both = bench.hop_figures([press("direct", 0.02), press("page", 0.05), press("page", 0.07)])
    assert both["planner_solving"]["p50"] == 100.0 and both["to_restrictor"]["n"] == 3
    assert both["page"]["to_restrictor"]["n"] == 2 and both["direct"]["to_restrictor"]["p50"] == 20.0
    assert both["page_to_ar_client_ms"] == 40.0  # page median 60 ms against direct 20 ms
