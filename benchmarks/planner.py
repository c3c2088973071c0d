"""Planner figures: replanning wall time, plan quality, IIDP against the joint optimum.

For each team size (robots x 3 objects, on sites from ``runtime.site.generate.generate_site``) and seed:

- the first plan, IIDP from scratch (every robot alone, then rounds): wall time, makespan, human
  door openings, IIDP rounds;
- replans as the service makes them while the mission runs: the world the current plan leads to at
  ``--replans`` evenly spaced times (``services.planner.replay``), each planned with IIDP starting
  from the plan being executed, plus one replan at each of those times after the human declares the
  storage door unavailable for two minutes (a new ConstraintSet); wall time and CPU time of each
  (CPU time moves less with the machine's load), and the clingo programs each solved;
- for 2-3 robots, the joint program (all robots in one ASP program) with ``--joint-limit`` seconds:
  makespan, openings, whether optimality was proven, and IIDP/joint ratios.

- dispatching each of those plans (every robot's front action turned into a trajectory, as after a
  planner restart: the worst case) with collision-free team motion (``services.planner.teammotion``,
  the planner's opt-in ``--collision-free``) and without, in the same run: wall time of each, and
  the replan time plus the collision-free dispatch;

Prints one JSON document: per team size, medians and p95 of the replan times, the first plans'
figures, and whether the targets hold (FLOORS, issue 36: 6 robots median replan <= 0.05 s and p95
<= 0.15 s; 20 robots first plan <= 2 s and median replan <= 0.2 s; 50 robots first plan <= 5 s and
median replan <= 0.5 s; IIDP makespan <= 1.05 x joint where the joint program finished). A size
without a target (100 robots, any other) is measured and reported the same way. The machine's load
average at the start and end is in the JSON: on a shared machine, compare trees in one run with
``benchmarks/planner_ab.py`` instead.

    .venv/bin/python benchmarks/planner.py                 # the full set (takes several minutes)
    .venv/bin/python benchmarks/planner.py --robots 2,6 --seeds 1
    .venv/bin/python benchmarks/planner.py --robots 6,20,50 --seeds 1 --replans 3 --joint-limit 0
    .venv/bin/python benchmarks/planner.py --robots 100 --seeds 1 --replans 2 --joint-limit 0
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from protocol.site import loads_site  # noqa: E402
from runtime.site.generate import generate_site  # noqa: E402
from services.planner.constraints import ConstraintProgram, unavailable  # noqa: E402
from services.planner.dispatcher import Dispatcher  # noqa: E402
from services.planner.planner import PlannerSettings, TaskPlanner  # noqa: E402
from services.planner.replay import world_at  # noqa: E402
from services.planner.solver import WORK, ClingoWork  # noqa: E402
from services.planner.teammotion import TeamMotion  # noqa: E402
from services.planner.validator import Windows, validate_result  # noqa: E402
from services.planner.world import initial_world  # noqa: E402


def dispatch_seconds(planner: TaskPlanner, world, result, collision_free: bool) -> float:
    """Wall time to dispatch ``result`` from scratch (every robot gets a command)."""
    dispatcher = Dispatcher(planner.builder, planner.motion)
    if collision_free:
        dispatcher.team = TeamMotion(planner.motion)
    t0 = time.perf_counter()
    dispatcher.dispatch(result, world, 1)
    return time.perf_counter() - t0


# robots -> {figure: bound in s}; figures are the medians/p95 of run_size's summaries
FLOORS = {
    6: {"replan_median": 0.05, "replan_p95": 0.15},
    20: {"first_plan_median": 2.0, "replan_median": 0.2},
    50: {"first_plan_median": 5.0, "replan_median": 0.5},
}
RATIO_FLOOR = 1.05


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    k = min(int(round(q * (len(ordered) - 1))), len(ordered) - 1)
    return ordered[k]


def summary(values: list[float]) -> dict:
    return (
        {
            "n": len(values),
            "median": round(statistics.median(values), 4),
            "p95": round(pct(values, 0.95), 4),
            "max": round(max(values), 4),
        }
        if values
        else {"n": 0}
    )


def timed(plan, *args, **kwargs):
    """Run ``plan(*args, **kwargs)``: its result, wall and CPU seconds, and the clingo work it did."""
    before = dataclasses.replace(WORK)
    t0, c0 = time.perf_counter(), time.process_time()
    result = plan(*args, **kwargs)
    return result, time.perf_counter() - t0, time.process_time() - c0, WORK.since(before)


def clingo_split(runs: list[tuple[float, ClingoWork]]) -> dict:
    """Where the plans' wall time went, as medians over the plans (``runs``: wall seconds and clingo
    work of each): programs grounded, and the shares of making the programs (Control, encoding,
    parsing the facts' text), grounding them and solving. A plan from scratch makes its two
    tie-breaking runs side by side (``--threads 2``): both threads' work over one wall time, so its
    shares can add up to more than 1."""
    if not runs:
        return {}

    def share(part: str) -> float:
        return round(statistics.median(getattr(w, part) / max(t, 1e-9) for t, w in runs), 3)

    return {
        "programs_median": statistics.median(w.programs for _, w in runs),
        "build_share_median": share("build_seconds"),
        "ground_share_median": share("ground_seconds"),
        "solve_share_median": share("solve_seconds"),
    }


def run_size(
    robots: int,
    seeds: int,
    replans: int,
    joint_limit: float,
    time_limit: float,
    first_limit: float,
    validate: bool,
    threads: int = 2,
) -> dict:
    cold_times, makespans, openings, rounds = [], [], [], []
    replan_times, constraint_times, cpu_times, solves = [], [], [], []
    first_work, replan_work = [], []
    invalid = 0
    joint_rows = []
    dispatch = {True: [], False: []}  # collision-free -> dispatch wall times
    with_dispatch = []  # replan + collision-free dispatch
    for seed in range(seeds):
        site = loads_site(generate_site(robots, 3, seed=seed))
        settings = PlannerSettings(time_limit=time_limit, joint_time_limit=joint_limit, threads=threads)
        planner = TaskPlanner(site, settings)
        world = initial_world(site)
        first, took, _, work = timed(planner.plan, world, time_limit=first_limit)
        cold_times.append(took)
        first_work.append((took, work))
        makespans.append(first.makespan)
        openings.append(first.door_openings)
        rounds.append(first.iterations)
        if validate and validate_result(site, world, first):
            invalid += 1
        current, current_world = first, world
        for k in range(1, replans + 1):
            t = first.makespan * k / (replans + 1)
            w = world_at(planner.builder, current_world, current, t)
            nxt, took, cpu, work = timed(planner.plan, w, warm=current)
            replan_times.append(took)
            cpu_times.append(cpu)
            replan_work.append((took, work))
            solves.append(nxt.solves)
            if validate and validate_result(site, w, nxt):
                invalid += 1
            for on in (False, True):
                dispatch[on].append(dispatch_seconds(planner, w, nxt, on))
            with_dispatch.append(replan_times[-1] + dispatch[True][-1])
            # the human says: "I can't open the storage door for two minutes" (restrictor's form)
            start = int(t)
            item = unavailable("d_storage", start, start + 120, "bench")
            program = ConstraintProgram.build([item])
            constrained, took, cpu, work = timed(planner.plan, w, program, warm=nxt)
            constraint_times.append(took)
            cpu_times.append(cpu)
            replan_work.append((took, work))
            solves.append(constrained.solves)
            if validate and validate_result(site, w, constrained, Windows.of(program.facts())):
                invalid += 1
            current, current_world = nxt, w
        if robots <= 3 and joint_limit > 0:
            t0 = time.perf_counter()
            joint = planner.plan(world, method="joint")
            took = time.perf_counter() - t0
            if validate and validate_result(site, world, joint):
                invalid += 1
            joint_rows.append(
                {
                    "seed": seed,
                    "iidp_makespan": first.makespan,
                    "iidp_openings": first.door_openings,
                    "joint_makespan": joint.makespan,
                    "joint_openings": joint.door_openings,
                    "joint_optimal": joint.optimal,
                    "joint_seconds": round(took, 2),
                    "ratio_makespan": round(first.makespan / joint.makespan, 4) if joint.makespan else None,
                    "ratio_openings": round(first.door_openings / joint.door_openings, 4)
                    if joint.door_openings
                    else None,
                }
            )
    all_replans = replan_times + constraint_times
    row = {
        "robots": robots,
        "objects": 3 * robots,
        "seeds": seeds,
        "first_plan_seconds": summary(cold_times),
        "replan_seconds": summary(all_replans),
        "replan_seconds_after_progress": summary(replan_times),
        "replan_seconds_after_new_constraint": summary(constraint_times),
        "replan_cpu_seconds": summary(cpu_times),
        "dispatch_seconds_collision_free": summary(dispatch[True]),
        "dispatch_seconds_plain": summary(dispatch[False]),
        "replan_plus_collision_free_dispatch_seconds": summary(with_dispatch),
        "replan_solves": {"median": statistics.median(solves), "total": sum(solves)} if solves else {},
        "first_plan_clingo": clingo_split(first_work),
        "replan_clingo": clingo_split(replan_work),
        "makespan": {"median": statistics.median(makespans), "values": makespans},
        "door_openings": {"median": statistics.median(openings), "values": openings},
        "iidp_rounds": {"median": statistics.median(rounds), "values": rounds},
        "invalid_plans": invalid,  # plans (first, replans, joint) the validator refuses
    }
    if joint_rows:
        row["joint"] = joint_rows
        finished = [r for r in joint_rows if r["joint_optimal"]]
        row["joint_finished_within_limit"] = len(finished)
        row["ratio_makespan_median"] = statistics.median(r["ratio_makespan"] for r in joint_rows if r["ratio_makespan"])
        if finished:
            row["ratio_makespan_max_where_joint_finished"] = max(r["ratio_makespan"] for r in finished)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="2,3,4,6,10,20", help="team sizes, comma-separated")
    parser.add_argument("--seeds", type=int, default=3, help="generated sites per team size")
    parser.add_argument("--replans", type=int, default=5, help="mid-mission replanning points per site")
    parser.add_argument("--joint-limit", type=float, default=60.0, help="s for the joint program (2-3 robots; 0: skip)")
    parser.add_argument("--time-limit", type=float, default=5.0, help="s for one IIDP plan (the service's default)")
    parser.add_argument("--first-plan-limit", type=float, default=60.0, help="s for the first plan from scratch")
    parser.add_argument("--no-validate", action="store_true", help="skip validating every plan")
    parser.add_argument(
        "--threads", type=int, default=2, help="2: a plan from scratch makes its two runs side by side (default)"
    )
    args = parser.parse_args(argv)
    load_at_start = round(os.getloadavg()[0], 2)
    sizes = [int(x) for x in args.robots.split(",") if x]
    results = []
    for n in sizes:
        t0 = time.perf_counter()
        results.append(
            run_size(
                n,
                args.seeds,
                args.replans,
                args.joint_limit,
                args.time_limit,
                args.first_plan_limit,
                not args.no_validate,
                args.threads,
            )
        )
        print(f"{n} robots done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    floors = {}
    for row in results:
        figures = {
            "replan_median": row["replan_seconds"].get("median"),
            "replan_p95": row["replan_seconds"].get("p95"),
            "first_plan_median": row["first_plan_seconds"].get("median"),
        }
        for figure, bound in FLOORS.get(row["robots"], {}).items():
            value = figures[figure]
            floors[f"{figure}_{row['robots']}_robots<= {bound} s"] = value is not None and value <= bound
        if "ratio_makespan_max_where_joint_finished" in row:
            floors[f"iidp/joint_makespan_{row['robots']}_robots<= {RATIO_FLOOR}"] = (
                row["ratio_makespan_max_where_joint_finished"] <= RATIO_FLOOR
            )
    doc = {
        "benchmark": "planner",
        "command": " ".join(
            [Path(sys.executable).name, "benchmarks/planner.py", *(argv if argv is not None else sys.argv[1:])]
        ),
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "load_avg_1min_at_start": load_at_start,
            "load_avg_1min_at_end": round(os.getloadavg()[0], 2),
        },
        "settings": {
            "objects_per_robot": 3,
            "replan_time_limit": args.time_limit,
            "joint_limit": args.joint_limit,
            "threads": args.threads,
        },
        "results": results,
        "floors": floors,
    }
    print(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
