"""``arroch plan``: the one-shot CLI and its JSON shape, and ``arroch planner --help``."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.planner.conftest import SITES
from tests.procs import ROOT, arroch


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(arroch(*args), cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_plan_json_shape_and_content():
    out = run("plan", "--site", str(SITES / "pair.toml"), "--json")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert set(data) == {"method", "makespan", "door_openings", "solve_time", "iterations", "robots"}
    assert data["method"] == "iidp" and data["door_openings"] == 1
    assert set(data["robots"]) == {"r0", "r1"}
    for steps in data["robots"].values():
        assert [s["action"] for s in steps] == ["load", "approach", "opendoor", "gothrough", "unload"]
        for s in steps:
            assert set(s) == {"action", "args", "start", "end"} and s["start"] <= s["end"]
    assert data["makespan"] == max(steps[-1]["end"] for steps in data["robots"].values())


def test_plan_with_unavailable_door_and_constraints_file(tmp_path):
    lp = tmp_path / "late.lp"
    lp.write_text("% no robot through the storage door before 80\n:- goes_through(R, d_storage, T), T < 80.\n")
    out = run(
        "plan",
        "--site",
        str(SITES / "pair.toml"),
        "--unavailable",
        "d_storage:0:60",
        "--constraints",
        str(lp),
        "--json",
        "--method",
        "joint",
    )
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["method"] == "joint"
    for steps in data["robots"].values():
        for s in steps:
            if s["action"] == "gothrough" and s["args"] == ["d_storage"]:
                assert s["start"] >= 80


def test_plan_reports_conflicting_constraints(tmp_path):
    lp = tmp_path / "keep_out.lp"  # both robots start in the corridor
    lp.write_text("room_forbidden(corridor, 0, 600).\n:- robot_in(R, corridor, S, E), S < 600, E > 0.\n")
    out = run("plan", "--site", str(SITES / "pair.toml"), "--constraints", str(lp), "--json")
    assert out.returncode == 1 and out.stdout == ""
    assert "conflicting constraints: file_keep_out" in out.stderr
    bad = run("plan", "--site", str(SITES / "pair.toml"), "--unavailable", "d_storage:5:3")
    assert bad.returncode == 2 and "T1 must be greater" in bad.stderr


def test_bad_arguments_exit_2():
    assert run("plan", "--unavailable", "nodoor").returncode == 2
    assert run("plan", "--site", "/nonexistent.toml").returncode == 2
    assert run("plan", "--time-limit", "0").returncode == 2
    bad = run("plan", "--solve-limit", "-1")
    assert bad.returncode == 2 and "--solve-limit must be positive" in bad.stderr


def test_planner_help():
    out = run("planner", "--help")
    assert out.returncode == 0 and "--site" in out.stdout and "--method" in out.stdout
    out = subprocess.run(
        [sys.executable, "-m", "services.planner", "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0 and "planner" in out.stdout
