"""Sweeps against the real services: every trial runs the planner, restrictor and sim as processes
over Zenoh (``arroch experiment`` in a subprocess, as a user runs it).

Tiny sweeps (2 robots, 1 object, a shortened human task so a mission lasts a couple of minutes of
sim time) keep this module within a few minutes of wall time on two cores.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from services.experiments.routers import RUN_ENV
from services.experiments.runner import RunOptions, SweepError
from services.experiments.trial import TrialConfig
from tests.procs import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow]

# Not the paper's model (a quick mission for tests only): a 90 s task, one one-minute focus interval.
HUMAN = """[human]
task_mean = 90.0
task_std = 5.0
focus_count = 1
focus_min_minutes = 1
focus_max_minutes = 1
"""
TINY = ["--robots", "2", "--objects", "1", "--trials", "2", "--seed", "7"]


def sweep_processes(pid: int) -> list[int]:
    """Processes started by the sweep whose pid is ``pid`` (tagged in their environment)."""
    tag = f"{RUN_ENV}={pid}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as handle:
                if tag in handle.read().split(b"\0"):
                    found.append(int(entry))
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return found


def describe(pids: list[int]) -> list[str]:
    """Command lines of ``pids``, for a failure message."""
    out = []
    for pid in pids:
        try:
            out.append(Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip())
        except OSError:
            out.append(f"{pid} (gone)")
    return out


def wait_gone(pid: int, timeout: float = 15.0) -> list[int]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        left = sweep_processes(pid)
        if not left:
            return []
        time.sleep(0.2)
    return sweep_processes(pid)


def start(args: list[str], human: Path) -> subprocess.Popen[str]:
    argv = [
        sys.executable,
        "-m",
        "services.cli",
        "experiment",
        *args,
        "--human-config",
        str(human),
        "--progress",
        "line",
        "--no-report",
    ]
    return subprocess.Popen(
        argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )


def finish(proc: subprocess.Popen[str], timeout: float) -> tuple[int, str]:
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        raise AssertionError(f"the sweep did not end within {timeout} s:\n{out}") from None
    return proc.returncode, out


def rows(folder: Path, name: str = "trials.csv") -> list[dict[str, str]]:
    with open(folder / name, encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def human(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("human") / "human.toml"
    path.write_text(HUMAN, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory, human: Path) -> Path:
    """One complete tiny sweep (both methods that differ most: feedback and blind trips)."""
    out = tmp_path_factory.mktemp("reference")
    proc = start(["robots", *TINY, "--methods", "arroch,no-comm", "--out", str(out), "--trial-timeout", "60"], human)
    code, output = finish(proc, 300)
    assert wait_gone(proc.pid) == [], "processes of the sweep outlived it"
    statuses = [r["status"] for r in rows(out)] if (out / "trials.csv").exists() else []
    assert code == 0 and statuses == ["ok"] * 4, (
        f"the tiny sweep did not complete every mission (exit {code}, statuses {statuses}):\n{output[-3000:]}"
    )
    return out


def test_a_trial_is_bounded_recorded_and_leaves_nothing(tmp_path: Path, human: Path) -> None:
    """One real trial with a short wall-clock budget: whatever the mission does, the trial ends by its
    timeout, is recorded with its reason, and no process or folder of it survives."""
    out = tmp_path / "one"
    mine = "arroch-exp-arroch-n2-o1-p0.5-w90-c0-t00-*"  # this trial's folder (other sweeps may run meanwhile)
    before = set(Path("/tmp").glob(mine))
    proc = start(
        [
            "robots",
            "--robots",
            "2",
            "--objects",
            "1",
            "--trials",
            "1",
            "--methods",
            "arroch",
            "--out",
            str(out),
            "--trial-timeout",
            "15",
            "--jobs",
            "1",
        ],
        human,
    )
    code, output = finish(proc, 90)
    assert wait_gone(proc.pid) == [], f"processes of the sweep outlived it:\n{output}"
    assert set(Path("/tmp").glob(mine)) - before == set(), "a trial folder was left behind"
    [row] = rows(out)
    [timing] = rows(out, "timing.csv")
    assert row["status"] in ("ok", "timeout"), output
    assert float(timing["wall_time"]) < 15 + 8  # the budget plus stopping the processes
    assert float(timing["services_up"]) > 0
    if row["status"] == "timeout":
        assert code == 1 and row["reason"].startswith("no end of mission within 15 s wall")
        log = (out / "logs" / "arroch-n2-o1-p0.5-w90-c0-t00.log").read_text()
        assert "status: timeout" in log
        assert "most recent call first" in log  # the services' stacks, printed as the trial timed out
    else:
        assert code == 0 and float(row["team_completion_time"]) >= float(row["human_completion_time"]) > 0
    [session] = json.loads((out / "runs.json").read_text())
    assert session["trials_run"] == 1 and session["versions"]["clingo"].startswith("5.")


def test_sigint_stops_a_running_sweep_cleanly(tmp_path: Path, human: Path) -> None:
    out = tmp_path / "stopped"
    proc = start(
        ["robots", *TINY, "--methods", "arroch", "--out", str(out), "--trial-timeout", "120", "--jobs", "2"], human
    )
    deadline = time.monotonic() + 30
    while len(sweep_processes(proc.pid)) < 4 and time.monotonic() < deadline:  # routers and services are up
        time.sleep(0.2)
    assert len(sweep_processes(proc.pid)) >= 4, "the sweep did not start its processes"
    proc.send_signal(signal.SIGINT)
    started = time.monotonic()
    code, output = finish(proc, 30)
    assert code == 130, output
    assert time.monotonic() - started < 15
    assert wait_gone(proc.pid) == [], output
    assert "--resume" in output
    recorded = rows(out) if (out / "trials.csv").exists() else []
    assert all(r["status"] == "ok" for r in recorded)  # a stopped trial is not recorded as anything


@contextlib.contextmanager
def cpu_burners(count: int = 2) -> Iterator[None]:
    """``count`` processes spinning on the CPU: a loaded machine (the 2 cores are shared with them)."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()


def test_same_seed_gives_the_same_csv_beside_cpu_burning_processes(
    reference: Path, tmp_path: Path, human: Path
) -> None:
    """Lockstep waits for answers in site time, never on the wall clock: a loaded machine runs the
    same missions, byte for byte (the reference ran without the burners)."""
    out = tmp_path / "again"
    with cpu_burners():
        proc = start(
            ["robots", *TINY, "--methods", "arroch,no-comm", "--out", str(out), "--trial-timeout", "120"], human
        )
        code, output = finish(proc, 400)
    assert code == 0, output
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()
    # And the figures are real: the human's task and the robots' deliveries both took sim time.
    for r in rows(out):
        assert float(r["human_completion_time"]) > 60 and float(r["slowest_robot_time"]) > 0
        assert float(r["team_completion_time"]) == max(
            float(r["human_completion_time"]), float(r["slowest_robot_time"])
        )
    assert {r["method"]: r["feedback_sent"] for r in rows(out) if r["trial"] == "0"}["no-comm"] == "0"
    # Paired: both methods of one trial index met the same site and the same human.
    for i in ("0", "1"):
        same = {(r["site_seed"], r["seed"], r["human_task_time"]) for r in rows(out) if r["trial"] == i}
        assert len(same) == 1, same


def test_a_dask_cluster_gives_the_same_csv(reference: Path, tmp_path: Path, human: Path) -> None:
    """--cluster: each trial runs on a worker of a (here local, two-worker) Dask cluster with its own
    router and services; the results are the local pool's, byte for byte."""
    import distributed  # the test extra installs it (pyproject.toml)

    out = tmp_path / "cluster"
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
    ) as cluster:
        proc = start(
            [
                "robots",
                *TINY,
                "--methods",
                "arroch,no-comm",
                "--out",
                str(out),
                "--trial-timeout",
                "120",
                "--cluster",
                cluster.scheduler_address,
            ],
            human,
        )
        code, output = finish(proc, 400)
    assert code == 0, output
    assert "cluster tcp://127.0.0.1:" in output and "2 worker(s)" in output
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()
    assert '"cluster": "tcp://127.0.0.1:' in (out / "runs.json").read_text()


def test_an_unreachable_cluster_is_refused_by_name(tmp_path: Path, human: Path) -> None:
    nowhere = ["--cluster", "tcp://127.0.0.1:9", "--cluster-timeout", "2"]  # (2 s, not the default 20: a test)
    proc = start(["robots", *TINY, "--out", str(tmp_path / "nowhere"), *nowhere], human)
    code, output = finish(proc, 120)
    assert code == 2 and "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in output


def test_killed_sweep_resumes_to_the_same_csv(reference: Path, tmp_path: Path, human: Path) -> None:
    out = tmp_path / "killed"
    args = ["robots", *TINY, "--methods", "arroch,no-comm", "--out", str(out), "--trial-timeout", "60", "--jobs", "1"]
    folders = "arroch-exp-*-n2-o1-p0.5-w90-c0-t0*-*"  # the trial folders of this sweep
    before = set(Path("/tmp").glob(folders))
    proc = start(args, human)
    deadline = time.monotonic() + 200
    while time.monotonic() < deadline and proc.poll() is None:
        if (out / "trials.csv").exists() and len(rows(out)) >= 1:
            break
        time.sleep(0.2)
    assert proc.poll() is None, "the sweep ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)  # a crash: no clean-up code of the sweep runs
    proc.communicate()
    left = wait_gone(proc.pid)
    assert left == [], f"the services of a killed sweep must die with it: {describe(left)}"
    for folder in set(Path("/tmp").glob(folders)) - before:
        shutil.rmtree(folder, ignore_errors=True)  # the running trial's folder: a crash leaves it behind
    done = len(rows(out))
    assert 1 <= done < 4
    proc = start([*args, "--resume"], human)
    code, output = finish(proc, 300)
    assert code == 0, output
    assert f"resume: {done} of 4 trials already done" in output
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()


def test_resume_refuses_another_sweep(reference: Path, tmp_path: Path, human: Path) -> None:
    proc = start(["robots", *TINY, "--methods", "arroch", "--out", str(reference), "--resume"], human)
    code, output = finish(proc, 30)
    assert code == 2 and "holds another sweep (methods:" in output
    proc = start(["robots", *TINY, "--methods", "arroch,no-comm", "--out", str(reference)], human)
    code, output = finish(proc, 30)
    assert code == 2 and "already holds a sweep: add --resume" in output


def test_rerun_runs_the_named_trials_again_and_refuses_unknown_ones(
    reference: Path, tmp_path: Path, human: Path
) -> None:
    out = tmp_path / "rerun"
    shutil.copytree(reference, out)
    args = ["robots", *TINY, "--methods", "arroch,no-comm", "--out", str(out), "--trial-timeout", "60", "--resume"]
    proc = start([*args, "--rerun", "arroch-n2-o1-p0.5-w90-c9-t00"], human)
    code, output = finish(proc, 30)
    assert code == 2 and "--rerun: this sweep has no trial arroch-n2-o1-p0.5-w90-c9-t00" in output
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()  # nothing touched
    proc = start([*args, "--rerun", "no-comm-n2-o1-p0.5-w90-c0-t01"], human)
    code, output = finish(proc, 200)
    assert code == 0, output
    assert "resume: 3 of 4 trials already done" in output
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()  # the same code: the same row
    timed = [r for r in rows(out, "timing.csv") if r["method"] == "no-comm" and r["trial"] == "1"]
    before = [r for r in rows(reference, "timing.csv") if r["method"] == "no-comm" and r["trial"] == "1"]
    assert len(timed) == 1 and timed != before  # run again: a new wall-clock record, once


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"jobs": 0}, "--jobs must be >= 1"),
        ({"router": "everywhere"}, "--router must be one of"),
        ({"trial": TrialConfig(timeout=0.0)}, "--trial-timeout must be > 0"),
        ({"cluster_timeout": float("nan")}, "--cluster-timeout must be > 0"),
        ({"cluster_timeout": -1.0}, "--cluster-timeout must be > 0"),
        ({"rerun": ("arroch-n2-o1-p0.5-w90-c0-t00",)}, "--rerun needs --resume"),
    ],
)
def test_bad_run_options_are_refused_by_name(tmp_path: Path, changes: dict[str, Any], message: str) -> None:
    with pytest.raises(SweepError, match=re.escape(message)):
        RunOptions(out=tmp_path, **changes).check()
    RunOptions(out=tmp_path).check()  # the defaults are fine
