"""How much of the planner's grounding a multi-shot solver could keep between solves: measured
before building one (issue 18, item 2: "keep clingo's grounded program between solves ...
wherever it pays").

The planner grounds every clingo program from scratch (``services/planner/solver.py``). Within one
plan IIDP solves each robot many times: the same problem (the robot's stops and legs) against a
context that changes from solve to solve (other robots' openings, busy doorways, the team's end,
the horizon). A multi-shot solver would ground what does not change once per problem and only the
context per solve. This measures how much that could save, on a first plan and its replans:

- every one-robot program the planner grounds is recorded with its problem part and its context
  part apart (``SingleRobotSolver._member``, wrapped);
- each is made and grounded again (fastest of ``REPEATS``), alone: as the planner grounds it, and
  with a neutral context (nothing given, busy or blocked, no horizon, the same waits): the problem
  part alone;
- reported: how many programs per problem, the seconds making and grounding both (a ``Control``,
  the encoding, the facts, grounding: what a kept program would not redo) and their ground atoms,
  and ``saved_share_bound``: the share of the as-planned seconds that grounding each problem's part
  once per problem (and each program's context, as planned minus alone, on top) instead of the
  whole program once per solve would save. That is an upper
  bound, reached only if the context can enter a grounded program without being grounded into it
  (the encoding lets the context settle the grounding: the horizon bounds the time chain,
  ``blocked``/``near``/``closed`` prune times; see ``docs/architecture.md``, "The context").

    .venv/bin/python benchmarks/grounding_reuse.py --robots 6 --seeds 1 --replans 2
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from protocol.site import generate_site, loads_site  # noqa: E402
from services.planner import single  # noqa: E402
from services.planner.facts import Context, closed_facts, context_facts, door_facts, throughs  # noqa: E402
from services.planner.planner import PlannerSettings, TaskPlanner  # noqa: E402
from services.planner.replay import world_at  # noqa: E402
from services.planner.solver import _grounded  # noqa: E402
from services.planner.world import initial_world  # noqa: E402

# problem key, site facts, problem part, context part, neutral context, encoding parts, constraints
Recorded = tuple[tuple, str, str, str, str, list[str], object]
REPEATS = 3  # each program is made and grounded this many times, the fastest kept (the machine is shared)


def record_programs(robots: int, seed: int, replans: int) -> list[Recorded]:
    """The one-robot programs a first plan and ``replans`` replans ground, problem and context apart."""
    recorded: list[Recorded] = []

    def member(solver: single.SingleRobotSolver, prob, ctx: Context) -> str:
        r = prob.robot
        mine = solver.robot_facts(prob) + f"grp({r},{r}).\n"
        context = context_facts(ctx, r) + door_facts(ctx, r, throughs([prob]), solver.hold)
        context += closed_facts(prob, ctx, solver.hold)
        neutral = context_facts(Context(syncwait=ctx.syncwait, clearwait=ctx.clearwait), r)
        program = original(solver, prob, ctx)
        if mine + context != program:  # the split must add up to the planner's own program
            raise RuntimeError(f"{r}: the problem and context parts differ from SingleRobotSolver._member's program")
        key = (r, tuple(leg.id for leg in prob.legs))
        recorded.append((key, solver.site_facts, mine, context, neutral, solver.parts, solver.constraints))
        return program

    original = single.SingleRobotSolver._member
    single.SingleRobotSolver._member = member
    try:
        site = loads_site(generate_site(robots, 3, seed=seed))
        planner = TaskPlanner(site, PlannerSettings(joint_time_limit=0))
        world = initial_world(site)
        plan = planner.plan(world, time_limit=60.0)
        for k in range(1, replans + 1):
            world = world_at(planner.builder, world, plan, plan.makespan * k / (replans + 1))
            plan = planner.plan(world, warm=plan)
    finally:
        single.SingleRobotSolver._member = original
    return recorded


def ground(facts: str, parts: list[str], constraints) -> tuple[float, int]:
    """Seconds to make and ground the program, as the planner does, and its ground atoms."""
    best = float("inf")
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        ctl = _grounded(facts, parts, constraints, ["--warn=none"])
        best = min(best, time.perf_counter() - t0)
    return best, len(ctl.symbolic_atoms)


def measure(robots: int, seed: int, replans: int) -> dict:
    programs = record_programs(robots, seed, replans)
    full_s, full_atoms, alone_s, alone_atoms = [], [], [], []
    for key, site_facts, mine, context, neutral, parts, constraints in programs:
        active = f"active({key[0]}).\n"
        s, a = ground(site_facts + mine + context + active, parts, constraints)
        full_s.append(s)
        full_atoms.append(a)
        s, a = ground(site_facts + mine + neutral + active, parts, constraints)
        alone_s.append(s)
        alone_atoms.append(a)
    per_problem = Counter(p[0] for p in programs)
    alone_by_problem: dict[tuple, list[float]] = {}
    for program, seconds in zip(programs, alone_s, strict=True):
        alone_by_problem.setdefault(program[0], []).append(seconds)
    # kept programs: each problem's part made and grounded once, plus each program's context on top
    once = sum(statistics.mean(v) for v in alone_by_problem.values())
    contexts = sum(max(f - a, 0.0) for f, a in zip(full_s, alone_s, strict=True))
    saved = sum(full_s) - once - contexts
    return {
        "robots": robots,
        "seed": seed,
        "replans": replans,
        "programs": len(programs),
        "problems": len(per_problem),
        "programs_per_problem_median": statistics.median(per_problem.values()) if per_problem else 0,
        "programs_per_problem_max": max(per_problem.values(), default=0),
        "seconds_as_planned": round(sum(full_s), 3),
        "seconds_problem_alone": round(sum(alone_s), 3),
        "saved_share_bound": round(saved / sum(full_s), 3) if programs else None,
        "ratio_problem_alone_to_as_planned_median": round(
            statistics.median(b / a for a, b in zip(full_s, alone_s, strict=True)), 3
        )
        if programs
        else None,
        "ground_atoms_as_planned_median": statistics.median(full_atoms) if programs else 0,
        "ground_atoms_problem_alone_median": statistics.median(alone_atoms) if programs else 0,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", default="6", help="team sizes, comma-separated (default 6)")
    parser.add_argument("--seeds", type=int, default=1, help="generated sites per team size (default 1)")
    parser.add_argument("--replans", type=int, default=2, help="replans after the first plan (default 2)")
    args = parser.parse_args(argv)
    rows = []
    for n in (int(x) for x in args.robots.split(",")):
        for seed in range(args.seeds):
            print(f"grounding_reuse: {n} robots, seed {seed} ...", file=sys.stderr, flush=True)
            rows.append(measure(n, seed, args.replans))
    print(json.dumps({"benchmark": "grounding_reuse", "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
