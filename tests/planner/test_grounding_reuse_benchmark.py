"""benchmarks/grounding_reuse.py records the planner's one-robot programs with their problem and
context parts apart (adding up to the planner's own program, or it refuses), grounds both, and
measures kept programs holding the context as externals against the planner's fresh ones."""

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
    whole, bounds = row["kept_whole_context_external"], row["kept_bounds_external"]
    for kept in (whole, bounds):
        assert kept["programs"] == row["programs"]
        assert kept["seconds_fresh"] > 0 and kept["seconds_kept"] > kept["seconds_kept_grounding"] > 0
        assert kept["optima_compared"] > 0 and kept["optima_that_differ"] == 0  # the same optima
        assert kept["ground_atoms_kept_median"] > 0
    # one kept program per problem; holding only the bounds, one per problem and rest of the context
    assert whole["groundings_kept"] == row["problems"] <= bounds["groundings_kept"] <= row["programs"]


def test_a_context_is_read_as_the_atoms_its_spans_state():
    bench = load_benchmark()
    atoms = bench.context_atoms("horizon(r0,90). blocked(r0,x,3..5,2).\n")
    assert sorted(str(a) for a in atoms) == [
        "blocked(r0,x,3,2)",
        "blocked(r0,x,4,2)",
        "blocked(r0,x,5,2)",
        "horizon(r0,90)",
    ]
    assert bench.levels((0, 3, 0, 280)) == bench.levels((3, 280)) == (3, 280)
