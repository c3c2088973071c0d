"""``arroch demo``: the main job on the packaged default site, all on localhost.

It checks and draws the site, then runs one whole mission under the supervisor
(``arroch up --until-done``): a Zenoh router, the planner, the restrictor and the simulator with
its simulated human, in lockstep so the mission takes seconds of wall time instead of the ~12
minutes it lasts on the site clock. The supervisor prints progress and the final metrics and
leaves a run folder (metrics.json, events.jsonl, the merged log); the site picture goes there too.
Everything it starts is stopped before it returns.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from protocol.site import default_site_path


def _arroch(*args: str) -> list[str]:
    return [sys.executable, "-m", "services.cli", *args]


def _step(text: str) -> None:
    print(f"==> {text}", flush=True)


def run_demo(args: argparse.Namespace) -> int:
    site_file = args.site or str(default_site_path())
    run_root = Path(args.run_dir)
    _step(f"checking the site {site_file}")
    if subprocess.run(_arroch("site", "check", site_file)).returncode != 0:
        return 1
    run_root.mkdir(parents=True, exist_ok=True)
    before = set(run_root.iterdir())

    _step(f"running one mission ({args.method}, seed {args.seed}, {args.mode}) with router, planner, restrictor and sim")
    mission = subprocess.run(_arroch(
        "up", "--site", site_file, "--services", "planner,restrictor,sim", "--method", args.method,
        "--mode", args.mode, "--seed", str(args.seed), "--until-done", "--timeout", str(args.timeout),
        "--run-dir", str(run_root), "--progress", "line", "--log-level", "WARNING",
    ))
    new_runs = sorted(set(run_root.iterdir()) - before)
    run_dir = new_runs[-1] if new_runs else run_root
    subprocess.run(_arroch("site", "show", site_file, "--png", str(run_dir / "site.png")), check=False, stdout=subprocess.DEVNULL)
    if mission.returncode != 0:
        print(f"the mission did not complete (exit {mission.returncode}); see {run_dir}", file=sys.stderr)
        return mission.returncode
    _step(f"done; metrics, event log and site picture in {run_dir}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("demo", help="run one mission on the default site (localhost) and print its metrics", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--site", help="site file (default: the packaged office site)")
    parser.add_argument("--method", default="arroch", choices=("arroch", "no-feedback", "no-comm"), help="method (default arroch)")
    parser.add_argument("--mode", default="lockstep", choices=("lockstep", "realtime", "rate"), help="sim clock mode (default lockstep)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the simulated human (default 1)")
    parser.add_argument("--timeout", type=float, default=600.0, help="give up after this many wall seconds (default 600)")
    parser.add_argument("--run-dir", default="runs", help="folder of run folders (default runs/)")
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_demo)
