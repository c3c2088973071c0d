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
  ``blocked``/``near``/``closed`` prune times; see ``docs/services/planner.md``, "Encoding");
- then the kept programs themselves (:func:`with_externals`), made, grounded and optimised against
  the planner's own fresh programs with the same time limit: the whole context held as
  ``#external`` atoms (one grounding per problem), and only its bounds (horizon, the others' end,
  the wait limits; one grounding per problem and distinct rest of the context). Optima must agree.

    .venv/bin/python benchmarks/grounding_reuse.py --robots 6 --seeds 1 --replans 2
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import clingo

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from protocol.site import loads_site  # noqa: E402
from runtime.site.generate import generate_site  # noqa: E402
from services.planner import single  # noqa: E402
from services.planner.facts import Context, closed_facts, context_facts, door_facts, throughs  # noqa: E402
from services.planner.planner import PlannerSettings, TaskPlanner  # noqa: E402
from services.planner.replay import world_at  # noqa: E402
from services.planner.solver import _grounded, _guards, _optimise, _options, solve  # noqa: E402
from services.planner.world import initial_world  # noqa: E402

# problem key, site facts, problem part, context part, neutral context, encoding parts, constraints
Recorded = tuple[tuple, str, str, str, str, list[str], object]
SOLVE_LIMIT = PlannerSettings().solve_limit  # s per optimisation, the planner's own
PROGRESS_EVERY = 30.0  # s between progress lines
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


def problem_of(program: Recorded) -> tuple:
    """What a kept program would be kept for: the same robot, legs, problem facts (its start, the
    base second), encoding parts and constraints."""
    key, site_facts, mine, _context, _neutral, parts, constraints = program
    return (key, site_facts, mine, tuple(parts), id(constraints))


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
    alone_by_problem: dict[tuple, list[float]] = {}
    for program, seconds in zip(programs, alone_s, strict=True):
        alone_by_problem.setdefault(problem_of(program), []).append(seconds)
    per_problem = {problem: len(seconds) for problem, seconds in alone_by_problem.items()}
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
        "kept_whole_context_external": with_externals(programs, SOLVE_LIMIT),
        "kept_bounds_external": with_externals(programs, SOLVE_LIMIT, BOUNDS),
    }


def context_atoms(text: str) -> frozenset[clingo.Symbol]:
    """The atoms a context's facts state (spans such as ``blocked(r0,x,88..99,3)`` expanded)."""
    ctl = clingo.Control(["--warn=none"])
    ctl.add("base", [], text)
    ctl.ground([("base", [])])
    return frozenset(a.symbol for a in ctl.symbolic_atoms)


# The context atoms that change a program's numbers but not which doorways and seconds are ruled out:
# held as externals alone, the rest stays facts and a problem is grounded again only when that changes.
BOUNDS = frozenset({"horizon", "others_end", "syncwait", "clearwait"})


def with_externals(programs: list[Recorded], limit: float, held: frozenset[str] | None = None) -> dict:
    """Kept programs measured: each problem's program grounded once per distinct context (apart from
    the predicates ``held``; ``None``: all of it) with the ``held`` atoms of every context it met as
    ``#external``, then optimised once per recorded context (those atoms assigned true, the others
    false), against each program made, grounded and optimised as the planner does.

    The externals' domain is the union of the contexts the problem actually met, known in advance
    here: a kept program in the planner would not know its future contexts and would need a wider
    domain (every second a context could name), so this is the most such a program could save. Both
    are solved to the same time limit; the costs must agree where both are proved optimal."""

    def is_held(atom: clingo.Symbol) -> bool:
        return held is None or atom.name in held

    groups: dict[tuple, list[tuple[Recorded, frozenset[clingo.Symbol]]]] = {}
    for program in programs:
        atoms = context_atoms(program[3])
        fixed = frozenset(a for a in atoms if not is_held(a))
        groups.setdefault((*problem_of(program), fixed), []).append((program, atoms))
    fresh_s = kept_s = kept_ground_s = 0.0
    kept_atoms: list[int] = []
    disagree = compared = 0
    shown = time.monotonic()
    for n, ((key, site_facts, mine, parts, _, fixed), members) in enumerate(groups.items(), 1):
        if time.monotonic() - shown > PROGRESS_EVERY:  # a periodic line: at 20 robots this takes minutes
            shown = time.monotonic()
            what = "the whole context" if held is None else "its bounds"
            print(f"  kept programs, {what} external: {n}/{len(groups)}", file=sys.stderr)
        constraints = members[0][0][6]
        active = f"active({key[0]}).\n"
        domain = sorted(frozenset().union(*(atoms for _, atoms in members)) - fixed)
        fresh_costs = []
        for program, _atoms in members:
            facts = site_facts + mine + program[3] + active
            t0 = time.perf_counter()
            out = solve(facts, list(parts), constraints, time_limit=limit, diagnose=False)
            fresh_s += time.perf_counter() - t0
            fresh_costs.append(levels(out.cost) if out.status == "optimal" else None)
        t0 = time.perf_counter()
        kept_facts = "".join(f"{a}.\n" for a in sorted(fixed)) + "".join(f"#external {a}.\n" for a in domain)
        ctl = _grounded(site_facts + mine + active + kept_facts, list(parts), constraints, _options())
        kept_ground_s += time.perf_counter() - t0
        kept_atoms.append(len(ctl.symbolic_atoms))
        for (_program, atoms), fresh_cost in zip(members, fresh_costs, strict=True):
            t1 = time.perf_counter()
            for a in domain:
                ctl.assign_external(a, a in atoms)
            out = _optimise(ctl, _guards(constraints), limit, t1, 0.0)
            kept_s += time.perf_counter() - t1
            if fresh_cost is not None and out.status == "optimal":
                compared += 1
                disagree += levels(out.cost) != fresh_cost
    kept_total = kept_ground_s + kept_s
    return {
        "held": "all" if held is None else sorted(held),
        "programs": len(programs),
        "groundings_kept": len(groups),
        "seconds_fresh": round(fresh_s, 3),  # make + ground + optimise, every program
        "seconds_kept": round(kept_total, 3),  # make + ground once per group, optimise every program
        "seconds_kept_grounding": round(kept_ground_s, 3),
        "kept_to_fresh": round(kept_total / fresh_s, 3) if fresh_s else None,
        # against the row's ground_atoms_as_planned_median (the same programs, grounded fresh)
        "ground_atoms_kept_median": statistics.median(kept_atoms) if kept_atoms else 0,
        "optima_compared": compared,
        "optima_that_differ": disagree,
    }


def levels(cost) -> tuple[int, ...]:
    """A cost vector without its zero levels: a program lists a priority level only when some
    minimize element at it is grounded, so the same optimum can read (0, 249) and (0, 0, 249)."""
    return tuple(c for c in cost if c)


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
