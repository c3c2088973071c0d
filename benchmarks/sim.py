"""Simulator throughput: real-time factor of completed missions in lockstep for 2, 6 and 20 robots (no camera).

For each team size a generated site (``generate_site(N, 3)``: three objects per robot, all for the
storage room behind the human's door) is simulated to the end of its mission, driven by a planner
stand-in that coordinates its robots (benchmarks/lib/coordinated.py: openings reserved per trip,
an unload slot per robot, no solver), so the mission completes and the figure is the simulator's
work on a mission, not on a world wedged until its time limit:

- ``lockstep``: ``arroch sim --mode lockstep`` as a real process, talking over a Zenoh router to the
  stand-in (answering every world version at once), so the figure is the simulator's own cost
  including every round trip the execution contract asks for. The factor is mission sim time /
  wall time as the sim measured it (start to mission_done).
- ``engine_only``: the same mission in process, no network (the engine's ceiling).

Floors (issue 36): >= 1,000x real time in lockstep with 6 robots, >= 300x with 20. A floor is only
judged on a completed mission: a run that ends at the time limit (``"completed": false``) is
refused (``meets_floor`` false, a reason given, exit 1) whatever its factor. Camera frames per
second are benchmarks/sim_camera.py's.

Prints one JSON document (with the machine's load average at start and end). Usage:
``python benchmarks/sim.py [--robots 2 6 20] [--seed 0] [--objects 3]``; exit 1 when a mission did not
complete or a floor is not met.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the stand-in builds on the test suite's scripted planner

from benchmarks.lib.coordinated import CoordinatedPlanner, CoordinatedStandIn  # noqa: E402
from protocol.site import loads_site  # noqa: E402
from runtime.site.generate import generate_site  # noqa: E402
from runtime.transport import free_tcp_port  # noqa: E402
from services.sim.engine import Engine  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402
from tests.sim.helpers import run_mission  # noqa: E402

FLOORS = {6: 1000.0, 20: 300.0}  # robots -> lockstep real-time factor floor


def engine_only(text: str, seed: int) -> dict[str, Any]:
    site = loads_site(text)
    engine = Engine(site, method="arroch", seed=seed)
    planner = CoordinatedPlanner(site)
    started = time.perf_counter()
    run_mission(engine, planner=planner)
    wall = time.perf_counter() - started
    return {
        "sim_time": engine.time,
        "wall_time": round(wall, 3),
        "realtime_factor": round(engine.time / wall, 1),
        "completed": engine.completed,
        "team_completion_time": engine.summary()["team_completion_time"],
        "robots_given_up": planner.gave_up,
    }


def lockstep(text: str, seed: int, router: str, workdir: Path, tag: str) -> dict[str, Any]:
    site_file = workdir / f"{tag}.toml"
    site_file.write_text(text)
    metrics = workdir / f"{tag}.json"
    planner = CoordinatedStandIn(loads_site(text), tag, router)
    planner.open()
    thread = threading.Thread(target=planner.run, daemon=True)
    thread.start()
    sim = Proc(
        arroch(
            "sim",
            *("--site", str(site_file), "--connect", router, "--namespace", tag),
            *("--mode", "lockstep", "--seed", str(seed), "--until-done"),
            *("--metrics-out", str(metrics), "--log-level", "WARNING"),
        ),
        name="sim",
    )
    try:
        code = sim.popen.wait(600)
    finally:
        sim.stop()
        planner.stop()
        thread.join(5)
    if code != 0:
        raise RuntimeError(f"sim exited {code}:\n{sim.output}")
    m = json.loads(metrics.read_text())
    return {
        "sim_time": m["time"],
        "wall_time": round(m["run"]["wall_time"], 3),
        "realtime_factor": round(m["run"]["realtime_factor"], 1),
        "completed": m["completed"],
        "world_versions": m["world_versions"],
        "plans": m["run"]["counters"].get("plans", 0),
        "team_completion_time": m["team_completion_time"],
        "robots_given_up": planner.script.gave_up,
    }


def judge(results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Each floor against its team size's lockstep run; an incomplete mission meets no floor."""
    floors: dict[str, Any] = {}
    for robots, floor in FLOORS.items():
        run = results.get(str(robots))
        if run is None:
            continue
        lock = run["lockstep"]
        entry: dict[str, Any] = {"floor": floor, "realtime_factor": lock["realtime_factor"]}
        if not (lock["completed"] and run["engine_only"]["completed"]):
            entry["met"] = False
            entry["reason"] = (
                f"the {robots}-robot mission did not complete (lockstep completed={lock['completed']}, "
                f"engine_only completed={run['engine_only']['completed']}): its factor times an unfinished world"
            )
        else:
            entry["met"] = lock["realtime_factor"] >= floor
        floors[str(robots)] = entry
    return floors


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[2, 6, 20])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", type=int, default=3, help="objects per robot (the floors are for 3)")
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = Proc(arroch("router", "--listen", endpoint), name="router")
    result: dict[str, Any] = {
        "benchmark": "sim",
        "mode": "lockstep",
        "planner": "coordinated stand-in (benchmarks/lib/coordinated.py)",
        "objects_per_robot": args.objects,
        "seed": args.seed,
        "machine": {"cpus": os.cpu_count(), "load_avg_1min_at_start": round(os.getloadavg()[0], 2)},
        "results": {},
    }
    try:
        router.wait_for("router ready", timeout=20)
        with tempfile.TemporaryDirectory() as tmp:
            for n in args.robots:
                text = generate_site(n, args.objects, seed=args.seed)
                result["results"][str(n)] = {
                    "lockstep": lockstep(text, args.seed, endpoint, Path(tmp), f"bench{n}"),
                    "engine_only": engine_only(text, args.seed),
                }
    finally:
        router.stop()
    result["machine"]["load_avg_1min_at_end"] = round(os.getloadavg()[0], 2)
    result["floors"] = judge(result["results"]) if args.objects == 3 else {}
    # None: no team size with a floor was run
    result["meets_floor"] = all(f["met"] for f in result["floors"].values()) if result["floors"] else None
    incomplete = [n for n, run in result["results"].items() if not run["lockstep"]["completed"]]
    print(json.dumps(result, indent=2))
    if incomplete:
        print(
            f"sim benchmark: missions of {', '.join(incomplete)} robots did not complete: no floor judged",
            file=sys.stderr,
        )
    return 1 if result["meets_floor"] is False or incomplete else 0


if __name__ == "__main__":
    sys.exit(main())
