"""benchmarks/sweep.py reruns a sample of a committed sweep and finds its trials.csv rows byte
for byte, or names the trial and column that differ; and says where a trial's time went."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.procs import ROOT

pytestmark = [pytest.mark.slow]


def load_benchmark():
    spec = importlib.util.spec_from_file_location("sweep_benchmark", ROOT / "benchmarks" / "sweep.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def run(*argv: str, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_a_sample_of_a_sweep_gives_its_committed_rows_and_a_changed_row_is_caught(tmp_path: Path):
    committed = tmp_path / "results" / "tiny"
    made = run(
        "-m",
        "services.cli",
        "experiment",
        "robots",
        *("--robots", "2", "--objects", "1", "--trials", "2", "--methods", "arroch"),
        *("--jobs", "2", "--no-report", "--progress", "off", "--out", str(committed)),
    )
    assert made.returncode == 0, made.stderr
    done = run(
        "benchmarks/sweep.py",
        *("--results-dir", str(tmp_path / "results"), "--sweeps", "tiny", "--trials-per-cell", "1"),
        *("--keep", str(tmp_path / "kept")),
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    tiny = doc["sweeps"]["tiny"]
    assert doc["identical"] and tiny["identical"] and tiny["trials"] == 1 and tiny["full_sweep_trials"] == 2
    assert tiny["trials_per_minute"] > 0 and doc["estimate"]["minutes_per_sweep"]["tiny"] > 0
    time = tiny["time"]
    assert time["trials_measured"] == 1 and time["trials_without_sim_measures"] == 0
    seconds = time["seconds_per_trial"]
    assert seconds["mission_sim_steps"]["total"] > 0 and seconds["mission_planning"]["total"] > 0
    parts = ("mission_sim_steps", "mission_sim_publishing", "mission_planning", "mission_lockstep_waiting_and_rest")
    assert sum(seconds[p]["total"] for p in parts) == pytest.approx(seconds["mission"]["total"], abs=0.01)

    # The same sample against a committed row changed in one column: a mismatch naming it, exit 1.
    bench = load_benchmark()
    sample = tmp_path / "kept" / "tiny" / "sample"
    lines = (committed / "trials.csv").read_text().splitlines(keepends=True)
    header = lines[0].rstrip("\n").split(",")
    cells = lines[1].rstrip("\n").split(",")
    cells[header.index("door_openings")] = str(int(cells[header.index("door_openings")]) + 1)
    lines[1] = ",".join(cells) + "\n"
    (committed / "trials.csv").write_text("".join(lines))
    keys = [bench.key_of(dict(zip(header, cells, strict=True)))]
    (mismatch,) = bench.compare(committed, sample, keys)
    assert mismatch["trial"] == keys[0].ident()
    assert [c.split(":")[0] for c in mismatch["columns"]] == ["door_openings"]


def test_a_folder_that_is_not_a_sweep_is_refused_by_name(tmp_path: Path):
    (tmp_path / "empty").mkdir()
    done = run("benchmarks/sweep.py", "--results-dir", str(tmp_path), "--sweeps", "empty", timeout=60)
    assert done.returncode == 2
    assert "sweep.json: no such file" in done.stderr
