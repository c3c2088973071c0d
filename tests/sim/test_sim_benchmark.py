"""benchmarks/sim.py times completed missions only: its coordinating stand-in completes a mission the
plain stand-in leaves wedged, and a run that did not complete meets no floor."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest

from benchmarks.lib.coordinated import CoordinatedPlanner, unload_slots
from protocol.site import loads_site
from runtime.site.generate import generate_site
from services.sim.engine import Engine
from tests.procs import ROOT
from tests.sim.helpers import run_mission


def load_benchmark():
    spec = importlib.util.spec_from_file_location("sim_benchmark", ROOT / "benchmarks" / "sim.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_the_coordinated_stand_in_completes_a_shared_door_mission():
    """Three robots, every object behind the human's one door: reservations keep them from
    wedging in it, and no robot gives up."""
    site = loads_site(generate_site(3, 1, seed=0))
    engine = Engine(site, method="arroch", seed=0)
    planner = CoordinatedPlanner(site)
    events = run_mission(engine, planner=planner)
    assert engine.completed and planner.gave_up == []
    assert not planner.holder  # every reserved opening released
    assert not [e for e in events if e.kind == "robot_overlap"]


def test_unload_slots_are_a_robots_width_apart_and_inside_the_room():
    site = loads_site(generate_site(6, 1, seed=0))
    radius = site.params.robot_radius
    slots = unload_slots(site, "storage", radius)
    assert len(slots) >= 6
    for i, p in enumerate(slots):
        assert site.rooms["storage"].contains(*p, margin=radius)
        assert all(((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2) ** 0.5 >= 2 * radius for q in slots[i + 1 :])


def test_an_incomplete_mission_meets_no_floor_whatever_its_factor():
    bench = load_benchmark()
    done = {"completed": True, "realtime_factor": 5000.0}
    wedged = {"completed": False, "realtime_factor": 5000.0}
    floors = bench.judge(
        {
            "6": {"lockstep": done, "engine_only": done},
            "20": {"lockstep": wedged, "engine_only": done},
        }
    )
    assert floors["6"]["met"] is True and floors["6"]["floor"] == 1000.0
    assert floors["20"]["met"] is False and "did not complete" in floors["20"]["reason"]


@pytest.mark.slow
def test_the_benchmark_runs_a_small_team_to_the_end_in_lockstep():
    done = subprocess.run(
        [sys.executable, "benchmarks/sim.py", "--robots", "2", "--objects", "1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    run = doc["results"]["2"]
    assert run["lockstep"]["completed"] and run["engine_only"]["completed"]
    # the same mission in process and over Zenoh: the same outcome
    assert run["lockstep"]["team_completion_time"] == run["engine_only"]["team_completion_time"]
    assert doc["meets_floor"] is None and doc["floors"] == {}  # no floor at 2 robots
    assert doc["machine"]["load_avg_1min_at_start"] >= 0
