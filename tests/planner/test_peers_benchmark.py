"""benchmarks/peers.py: the delivery problem encoded for unified-planning, solved by a real engine,
every plan checked by unified-planning's validator and the project's own, and no makespan ratio for
a plan that fails either (a short run: the figures themselves are for `make bench`)."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys

import pytest

from tests.procs import ROOT

pytest.importorskip(
    "unified_planning", reason="unified-planning is not installed (the `peers` extra: pip install -e '.[peers]')"
)

# up-lpg 0.1.3 imports pkg_resources, which setuptools < 81 still has (and warns about)
pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore:pkg_resources is deprecated")]


def load_benchmark():
    spec = importlib.util.spec_from_file_location("peers", ROOT / "benchmarks" / "peers.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("peers", module)  # its dataclasses look their module up while being made
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def two_robots():
    """A generated site with 2 robots and 1 object each, its planner and its world."""
    from protocol.site import loads_site
    from runtime.site.generate import generate_site
    from services.planner.planner import TaskPlanner
    from services.planner.world import initial_world

    bench = load_benchmark()
    site = loads_site(generate_site(2, 1, seed=0))
    inst = bench.Instance("generated", 2, 2, None, site)
    return bench, inst, TaskPlanner(site), initial_world(site)


def test_an_engine_plan_passes_both_validators_and_a_spoiled_one_fails_both(two_robots):
    from unified_planning.plans import TimeTriggeredPlan
    from unified_planning.shortcuts import PlanValidator

    from benchmarks.lib.up_delivery import encode
    from services.planner.validator import Windows, validate

    bench, inst, planner, world = two_robots
    enc = encode(inst.site, planner.builder, world, None, "unshared")
    out = bench.run_apart(lambda: bench.solve_with(enc.problem, "lpg", 60.0), 60.0)
    assert out["status"].startswith("solved"), out
    plan = bench.rebuild_plan(enc.problem, out["plan"])
    with PlanValidator(problem_kind=enc.problem.kind) as validator:
        assert validator.validate(enc.problem, plan).status.name == "VALID"
    robots, openings = enc.steps(plan)
    assert sorted(robots) == ["r0", "r1"] and openings  # every delivery goes through the storage door
    assert validate(inst.site, world, robots, openings, Windows()) == []
    assert {s.action for steps in robots.values() for s in steps} == {
        "approach",
        "opendoor",
        "gothrough",
        "load",
        "unload",
    }

    # Every pass through the human's door a second earlier: its robot is not beside the door yet.
    spoiled = TimeTriggeredPlan(
        [(s - (1 if a.action.name == "pass_door" else 0), a, d) for s, a, d in plan.timed_actions]
    )
    with PlanValidator(problem_kind=enc.problem.kind) as validator:
        assert validator.validate(enc.problem, spoiled).status.name == "INVALID"
    robots, openings = enc.steps(spoiled)
    assert any(
        "starts before the previous step ends" in e for e in validate(inst.site, world, robots, openings, Windows())
    )
    assert bench.ratio({"valid": False, "up_valid": False, "makespan": 90}, {"valid": True, "makespan": 60}) is None
    assert bench.ratio({"valid": True, "up_valid": False, "makespan": 90}, {"valid": True, "makespan": 60}) is None
    assert bench.ratio({"valid": True, "up_valid": True, "makespan": 90}, {"valid": True, "makespan": 60}) == 1.5


@pytest.mark.skipif(shutil.which("java") is None, reason="ENHSP runs on Java, which is not installed")
def test_the_clock_encoding_reads_back_into_a_valid_timed_plan():
    """ENHSP takes no durative actions: its plan of the clock encoding is a sequence, timed by
    replaying the robots' clocks, and both validators accept it."""
    from protocol.site import loads_site
    from runtime.site.generate import generate_site
    from services.planner.planner import TaskPlanner
    from services.planner.world import initial_world

    bench = load_benchmark()
    site = loads_site(generate_site(1, 1, seed=0))
    inst = bench.Instance("calibration", 1, 1, ("d_storage", 0, 30), site)
    planner, world = TaskPlanner(site), initial_world(site)
    row = bench.run_peer(inst, planner, world, "enhsp", "clock", 60.0)
    assert row["status"] == "solved_satisficing" and row["up_valid"] and row["valid"], row
    assert row["door_openings"] >= 1
    # the human opens no door before 30 s, so the robot cannot be through before then
    iidp = bench.run_asp(inst, planner, world, "iidp", 60.0)
    assert iidp["valid"] and row["makespan"] >= 30 and iidp["makespan"] >= 30


def test_harder_problems_are_not_run_after_a_failure_and_the_office_keeps_its_first_robots():
    bench = load_benchmark()
    office = bench.office(2)
    assert sorted(office.robots) == ["r0", "r1"] and {o.robot for o in office.objects.values()} == {"r0", "r1"}
    assert len(office.objects) == 6 and "d_storage" in office.doors
    small = bench.Instance("office", 2, 6, None, office)
    window = ("d_storage", 60, 180)
    assert bench.Instance("office", 3, 9, None, office).harder_than(small)
    assert bench.Instance("office", 2, 6, window, office).harder_than(small)
    assert not small.harder_than(bench.Instance("office", 2, 6, window, office))  # fewer constraints
    assert not bench.Instance("office", 3, 3, None, office).harder_than(small)  # fewer objects each
    assert not bench.Instance("generated", 3, 9, None, office).harder_than(small)  # another building


def test_durations_are_the_planners_own(two_robots):
    """One robot's approach, load and unload last what the planner's legs say they do."""
    from benchmarks.lib.up_delivery import encode

    bench, inst, planner, world = two_robots
    enc = encode(inst.site, planner.builder, world, ("d_storage", 10, 50), "temporal")
    problem = planner.builder.problem(world, "r0", 0)
    leg = next(leg for leg in problem.legs if leg.origin == "start")  # start -> load its object
    first = leg.crossings[0]
    wait = f"wait_{first.opening}_{first.src}"
    assert enc.durations[("drive", "start_r0", wait)] == first.approach
    far = f"far_{first.opening}_{first.dst}"
    assert enc.durations[("through", wait, far)] == first.through
    if len(leg.crossings) == 1:
        assert enc.durations[("work", far, f"obj_{problem.stops[leg.stop].obj}")] == leg.tail
    # the window is a pair of timed initial literals on the storage door's availability
    timed = {float(t.delay): [str(e) for e in effects] for t, effects in enc.problem.timed_effects.items()}
    assert sorted(timed) == [10.0, 50.0]
    assert "available(d_storage) := false" in timed[10.0][0] and "available(d_storage) := true" in timed[50.0][0]


def test_the_benchmark_prints_and_writes_its_json_and_plot(tmp_path):
    out, png = tmp_path / "peers.json", tmp_path / "peers.png"
    result = subprocess.run(
        [
            sys.executable,
            "benchmarks/peers.py",
            "--robots",
            "2",
            "--objects",
            "1",
            "--office",
            "0",
            "--calibration",
            "",
            "--engines",
            "lpg/unshared",
            "--time-limit",
            "60",
            "--out",
            str(out),
            "--plot",
            str(png),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert json.loads(out.read_text()) == report and png.stat().st_size > 10_000
    assert len(report["machine"]["load_average_at_start"]) == 3
    plain, windowed = report["results"]
    assert plain["window"] is None and windowed["window"] == ["d_storage", 60, 180]
    assert plain["iidp"]["valid"] and plain["joint"]["status"] != "not run"  # 2 robots: the joint program runs
    lpg = plain["peers"]["lpg/unshared"]
    assert lpg["status"] == "solved_satisficing" and lpg["valid"] and lpg["up_valid"]
    assert lpg["ratio_to_iidp"] == round(lpg["makespan"] / plain["iidp"]["makespan"], 4)
    # LPG takes no timed initial literals: with the window it is not run, and says why
    assert windowed["peers"]["lpg/unshared"]["status"] == "unsupported"
    assert "TIMED_EFFECTS" in windowed["peers"]["lpg/unshared"]["missing_features"]
    assert report["table"][0]["lpg/unshared"].startswith("x")
