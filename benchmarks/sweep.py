"""Experiment throughput, and a check that the code still gives the committed results.

For each sweep named (``--sweeps``, folders of ``--results-dir``, by default the three paper sweeps
robots, laziness and map) the first ``--trials-per-cell`` K trials of every cell (condition x
method) of the committed sweep are run again as that sweep's runner runs them (the same spec but
``trials = K``: the same seeds, sites and human draws, ``--jobs`` at a time, real planner,
restrictor and sim processes over Zenoh). Then:

- **identity**: every row the run produced in ``trials.csv`` must equal, byte for byte, the
  committed row of the same trial. trials.csv holds no wall-clock column (those are in timing.csv;
  services/experiments/record.py), so the whole line is compared; the header too. Any difference,
  or a trial that did not run, is a mismatch: the JSON lists them (the differing columns named)
  and the exit code is 1. This is the check that a change of the code changes no outcome.
- **throughput**: trials per minute over the sample's wall time, on ``--jobs`` workers, and the
  three paper sweeps' total time estimated from it (their trial counts from the committed specs),
  against the 30-minute target.
- **where a trial's wall time goes**, from the runner's own timing.csv and from the sim itself
  (benchmarks/lib/sim_probe.py times each engine step and each tick inside the sim process, written
  to a side file, never to trials.csv): start-up of the services, the mission (simulation steps,
  publishing, planning = the planner's solve times, and the rest: lockstep round trips and waiting,
  the planner's work outside solving, machine contention; the four ``mission_*`` parts add up to
  ``mission``), and shutdown.

Prints one JSON document; progress goes to stderr. Usage:
``python benchmarks/sweep.py [--sweeps robots,laziness,map] [--trials-per-cell 3] [--jobs 2]``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import logging
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib import sim_probe  # noqa: E402
from services.experiments.design import SweepSpec, TrialKey  # noqa: E402
from services.experiments.record import key_of  # noqa: E402
from services.experiments.runner import SPEC_FILE, TIMING_FILE, TRIALS_FILE, RunOptions, Sweep  # noqa: E402
from services.experiments.trial import TrialConfig  # noqa: E402

PAPER_SWEEPS = ("robots", "laziness", "map")
TARGET_MINUTES = 30.0  # issue 36: the three paper sweeps together on this machine
MISMATCHES_SHOWN = 20  # per sweep, in the JSON (the count is always complete)


class BenchError(RuntimeError):
    """A results folder this benchmark cannot use (the message names the file)."""


def read_rows(path: Path) -> tuple[bytes, dict[TrialKey, bytes]]:
    """A trials.csv's header line and each row's exact line, by trial."""
    try:
        lines = path.read_bytes().split(b"\n")
    except FileNotFoundError:
        raise BenchError(f"{path}: no such file") from None
    if lines and lines[-1] == b"":
        lines.pop()
    if not lines:
        raise BenchError(f"{path}: empty (no header)")
    header = next(csv.reader([lines[0].decode("utf-8")]))
    rows: dict[TrialKey, bytes] = {}
    for number, line in enumerate(lines[1:], start=2):
        cells = next(csv.reader([line.decode("utf-8")]))
        if len(cells) != len(header):
            raise BenchError(f"{path}:{number}: {len(cells)} cells for {len(header)} columns")
        try:
            rows[key_of(dict(zip(header, cells, strict=True)))] = line
        except (KeyError, ValueError) as exc:
            raise BenchError(f"{path}:{number}: not a trial row ({exc})") from None
    return lines[0], rows


def load_spec(folder: Path) -> SweepSpec:
    path = folder / SPEC_FILE
    try:
        return SweepSpec.from_json(json.loads(path.read_text(encoding="utf-8")))
    except FileNotFoundError:
        raise BenchError(f"{path}: no such file (not a sweep folder)") from None
    except (json.JSONDecodeError, ValueError) as exc:
        raise BenchError(f"{path}: {exc}") from None


def differing_columns(header: bytes, ours: bytes, theirs: bytes) -> list[str]:
    names = next(csv.reader([header.decode("utf-8")]))
    a = next(csv.reader([ours.decode("utf-8")]))
    b = next(csv.reader([theirs.decode("utf-8")]))
    if len(a) != len(b):
        return ["(column count)"]
    return [f"{name}: {x!r} != committed {y!r}" for name, x, y in zip(names, a, b, strict=True) if x != y]


def compare(folder: Path, out: Path, keys: list[TrialKey]) -> list[dict[str, Any]]:
    """Mismatches between the committed trials.csv and the sample's, for the sample's trials."""
    committed_header, committed = read_rows(folder / TRIALS_FILE)
    if not (out / TRIALS_FILE).exists():
        return [{"trial": "*", "problem": f"the sample wrote no {TRIALS_FILE}"}]
    header, produced = read_rows(out / TRIALS_FILE)
    if header != committed_header:
        return [
            {"trial": "*", "problem": f"header differs: {header.decode()} != committed {committed_header.decode()}"}
        ]
    problems: list[dict[str, Any]] = []
    for key in keys:
        ours, theirs = produced.get(key), committed.get(key)
        if theirs is None:
            problems.append({"trial": key.ident(), "problem": f"not in the committed {folder / TRIALS_FILE}"})
        elif ours is None:
            problems.append({"trial": key.ident(), "problem": "the sample did not record it"})
        elif ours != theirs:
            problems.append({"trial": key.ident(), "columns": differing_columns(header, ours, theirs)})
    return problems


def summary(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    return {
        "mean": round(statistics.fmean(values), 3),
        "median": round(statistics.median(values), 3),
        "max": round(max(values), 3),
        "total": round(sum(values), 3),
    }


def breakdown(out: Path, probes: Path) -> dict[str, Any]:
    """Where the sample's trials spent their wall time (module docstring), per trial and in total."""
    with (out / TIMING_FILE).open(encoding="utf-8", newline="") as f:
        timing = list(csv.DictReader(f))
    parts: dict[str, list[float]] = {
        name: []
        for name in (
            "wall",
            "services_up",
            "sim_startup",
            "mission",
            "mission_sim_steps",
            "mission_sim_publishing",
            "mission_planning",
            "mission_lockstep_waiting_and_rest",
            "shutdown",
        )
    }
    plans: list[float] = []
    factors: list[float] = []
    unprobed = 0
    for row in timing:
        if row["status"] not in ("ok", "unfinished"):
            continue
        measured = sim_probe.read(probes, key_of(row).ident())
        if measured is None:
            unprobed += 1
            continue
        mission = float(row["mission_wall_time"] or 0.0)
        planning = float(row["planner_solve_time"] or 0.0)
        steps = float(measured["engine_step_s"])
        publishing = float(measured["tick_s"]) - steps
        parts["wall"].append(float(row["wall_time"]))
        parts["services_up"].append(float(row["services_up"] or 0.0))
        parts["sim_startup"].append(float(row["sim_startup"] or 0.0))
        parts["mission"].append(mission)
        parts["mission_sim_steps"].append(steps)
        parts["mission_sim_publishing"].append(publishing)
        parts["mission_planning"].append(planning)
        parts["mission_lockstep_waiting_and_rest"].append(max(0.0, mission - steps - publishing - planning))
        parts["shutdown"].append(float(row["shutdown"] or 0.0))
        plans.append(float(row["plans"] or 0))
        factors.append(float(row["realtime_factor"] or 0.0))
    total_wall = sum(parts["wall"]) or 1.0
    return {
        "trials_measured": len(parts["wall"]),
        "trials_without_sim_measures": unprobed,
        "seconds_per_trial": {name: summary(values) for name, values in parts.items()},
        "share_of_trial_wall": {
            name: round(sum(values) / total_wall, 3) for name, values in parts.items() if name != "wall"
        },
        "plans_per_trial": summary(plans),
        "mission_realtime_factor": summary(factors),
    }


def run_sample(name: str, folder: Path, k: int, jobs: int, timeout: float, keep: Path | None) -> dict[str, Any]:
    full = load_spec(folder)
    spec = dataclasses.replace(full, trials=min(k, full.trials))
    if keep is None:
        with tempfile.TemporaryDirectory(prefix=f"bench-sweep-{name}-") as tmp:
            return _sample(name, folder, full, spec, jobs, timeout, Path(tmp), kept=False)
    return _sample(name, folder, full, spec, jobs, timeout, keep / name, kept=True)


def _sample(
    name: str, folder: Path, full: SweepSpec, spec: SweepSpec, jobs: int, timeout: float, work: Path, *, kept: bool
) -> dict[str, Any]:
    keys = spec.keys()
    out, probes = work / "sample", work / "sim_probes"
    probes.mkdir(parents=True, exist_ok=True)
    print(f"[sweep bench] {name}: {len(keys)} trials ({spec.trials} per cell) on {jobs} jobs", file=sys.stderr)
    options = RunOptions(out=out, jobs=jobs, trial=TrialConfig(timeout=timeout), progress="off", report=False)
    started = time.monotonic()
    with sim_probe.probing_sims(probes):
        code = Sweep(spec, options).run()
    wall = time.monotonic() - started
    mismatches = compare(folder, out, keys)
    print(f"[sweep bench] {name}: {wall:.1f} s, {len(mismatches)} mismatch(es)", file=sys.stderr)
    return {
        "folder": str(folder),
        "cells": len(spec.conditions()),
        "trials_per_cell": spec.trials,
        "trials": len(keys),
        "full_sweep_trials": full.trial_count(),
        "runner_exit_code": code,
        "wall_time": round(wall, 3),
        "trials_per_minute": round(len(keys) / wall * 60.0, 2),
        "identical": not mismatches,
        "mismatches": len(mismatches),
        "mismatch_examples": mismatches[:MISMATCHES_SHOWN],
        "time": breakdown(out, probes),
        "kept_in": str(work) if kept else None,
    }


def estimate(results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The named sweeps' full run time at the throughput measured on each, and the whole at the pooled rate."""
    per_sweep = {
        name: round(r["full_sweep_trials"] / r["trials_per_minute"], 1) for name, r in results.items() if r["trials"]
    }
    trials = sum(r["trials"] for r in results.values())
    wall = sum(r["wall_time"] for r in results.values())
    total = round(sum(per_sweep.values()), 1)
    return {
        "minutes_per_sweep": per_sweep,
        "total_minutes": total,
        "pooled_trials_per_minute": round(trials / wall * 60.0, 2) if wall else None,
        "target_minutes": TARGET_MINUTES,
        "over_target_factor": round(total / TARGET_MINUTES, 2),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweeps", default=",".join(PAPER_SWEEPS), help="sweep folders, comma-separated")
    parser.add_argument("--trials-per-cell", type=int, default=3, metavar="K")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--results-dir", type=Path, default=ROOT / "experiments" / "results")
    parser.add_argument("--trial-timeout", type=float, default=300.0, help="wall s for one trial")
    parser.add_argument("--keep", type=Path, default=None, help="keep each sample's folder under this directory")
    args = parser.parse_args()
    if args.trials_per_cell < 1 or args.jobs < 1:
        parser.error("--trials-per-cell and --jobs must be >= 1")
    names = [n.strip() for n in args.sweeps.split(",") if n.strip()]
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    doc: dict[str, Any] = {
        "benchmark": "sweep",
        "jobs": args.jobs,
        "trials_per_cell": args.trials_per_cell,
        "machine": {"cpus": os.cpu_count(), "load_avg_1min_at_start": round(os.getloadavg()[0], 2)},
        "sweeps": {},
    }
    try:
        for name in names:
            folder = args.results_dir / name
            doc["sweeps"][name] = run_sample(
                name, folder, args.trials_per_cell, args.jobs, args.trial_timeout, args.keep
            )
    except BenchError as exc:
        print(f"sweep benchmark: {exc}", file=sys.stderr)
        return 2
    doc["machine"]["load_avg_1min_at_end"] = round(os.getloadavg()[0], 2)
    doc["estimate"] = estimate(doc["sweeps"])
    doc["identical"] = all(r["identical"] for r in doc["sweeps"].values())
    print(json.dumps(doc, indent=2))
    if not doc["identical"]:
        bad = [name for name, r in doc["sweeps"].items() if not r["identical"]]
        print(f"sweep benchmark: trials.csv rows differ from the committed ones in {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
