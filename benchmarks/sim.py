"""Simulator throughput: real-time factor in lockstep for 2, 6 and 20 robots (no camera).

For each team size a generated site (``generate_site(N, 3)``: three objects per robot, all for the
storage room behind the human's door) is simulated to the end of its mission:

- ``lockstep``: ``arroch sim --mode lockstep`` as a real process, talking over a Zenoh router to a
  planner stand-in (tests/sim/standin.py: answers every world version at once, no solver), so the
  figure is the simulator's own cost including every round trip the execution contract asks for.
  The factor is mission sim time / wall time as the sim measured it (start to mission_done).
- ``engine_only``: the same mission in process, no network (the engine's ceiling).

Floor (issue 5): >= 50x real time in lockstep with 6 robots. Camera frames per second are
benchmarks/sim_camera.py's.

Prints one JSON document. Usage: ``python benchmarks/sim.py [--robots 2 6 20] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the planner stand-in lives with the tests

from protocol.site import generate_site, loads_site  # noqa: E402
from protocol.transport import free_tcp_port  # noqa: E402
from services.sim.engine import Engine  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402
from tests.sim.helpers import run_mission  # noqa: E402
from tests.sim.standin import StandInPlanner  # noqa: E402

FLOOR_6 = 50.0


def engine_only(text: str, seed: int) -> dict:
    site = loads_site(text)
    engine = Engine(site, method="arroch", seed=seed)
    started = time.perf_counter()
    run_mission(engine)
    wall = time.perf_counter() - started
    return {
        "sim_time": engine.time,
        "wall_time": round(wall, 3),
        "realtime_factor": round(engine.time / wall, 1),
        "completed": engine.completed,
    }


def lockstep(text: str, seed: int, router: str, workdir: Path, tag: str) -> dict:
    site_file = workdir / f"{tag}.toml"
    site_file.write_text(text)
    metrics = workdir / f"{tag}.json"
    site = loads_site(text)
    planner = StandInPlanner(site, tag, router)
    planner.open()
    thread = threading.Thread(target=planner.run, daemon=True)
    thread.start()
    sim = Proc(
        arroch(
            "sim",
            "--site",
            str(site_file),
            "--connect",
            router,
            "--namespace",
            tag,
            "--mode",
            "lockstep",
            "--seed",
            str(seed),
            "--until-done",
            "--metrics-out",
            str(metrics),
            "--log-level",
            "WARNING",
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
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[2, 6, 20])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = Proc(arroch("router", "--listen", endpoint), name="router")
    result: dict = {"benchmark": "sim", "mode": "lockstep", "objects_per_robot": 3, "seed": args.seed, "results": {}}
    try:
        router.wait_for("router ready", timeout=20)
        with tempfile.TemporaryDirectory() as tmp:
            for n in args.robots:
                text = generate_site(n, 3, seed=args.seed)
                result["results"][str(n)] = {
                    "lockstep": lockstep(text, args.seed, endpoint, Path(tmp), f"bench{n}"),
                    "engine_only": engine_only(text, args.seed),
                }
    finally:
        router.stop()
    six = result["results"].get("6")
    if six:
        result["floor_6_robots"] = FLOOR_6
        result["meets_floor"] = six["lockstep"]["realtime_factor"] >= FLOOR_6
    print(json.dumps(result, indent=2))
    return 0 if result.get("meets_floor", True) else 1


if __name__ == "__main__":
    sys.exit(main())
