"""benchmarks/grounding_reuse.py records the planner's one-robot programs with their problem and
context parts apart (adding up to the planner's own program, or it refuses) and grounds both."""

from __future__ import annotations

import importlib.util

from services.planner import single
from tests.procs import ROOT


def load_benchmark():
    spec = importlib.util.spec_from_file_location("grounding_reuse", ROOT / "benchmarks" / "grounding_reuse.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_it_records_every_program_by_problem_and_grounds_both_parts():
    bench = load_benchmark()
    original = single.SingleRobotSolver._member
    programs = bench.record_programs(robots=2, seed=0, replans=1)
    assert single.SingleRobotSolver._member is original  # put back
    assert programs and any(p[3] != p[4] for p in programs)  # a context that is not the neutral one
    row = bench.measure(robots=2, seed=0, replans=1)
    assert row["programs"] == len(programs) >= row["problems"] >= 2  # both robots, some solved again
    assert row["programs_per_problem_max"] >= row["programs_per_problem_median"] >= 1
    assert row["seconds_as_planned"] > 0 and row["seconds_problem_alone"] > 0
    assert 0 <= row["saved_share_bound"] < 1
    assert row["ground_atoms_as_planned_median"] > 0 and row["ground_atoms_problem_alone_median"] > 0
