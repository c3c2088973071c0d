"""The joint planner: every robot in one ASP program, optimised together (the quality reference).

All robots are free at once, so doorway conflicts between them are forbidden in the program
(``joint.lp``) and a door opening one robot asks for is shared by any other that goes through
within its hold window. Waits may end when another robot arrives at or leaves an opening, besides
the events single-robot planning knows. The program is bounded by a horizon (no robot finishes
later than it): the makespan of a known plan, normally IIDP's, whose times are added as wait
points and whose choices are tried first, so the joint optimum is never worse than that plan and
a first model comes quickly. Meant for small teams; solving stops at the time limit with the best
plan found.
"""

from __future__ import annotations

from .constraints import ConstraintProgram
from .decode import decode
from .facts import Busy, Context, context_facts, door_facts, robot_facts, throughs
from .plan import RobotPlan
from .problem import RobotProblem
from .solver import Outcome, parts_for, solve

TEAM = "team"  # the one group every robot is in: one context, openings shared (joint.lp)


def hint_facts(hints: dict[str, RobotPlan]) -> str:
    lines: list[str] = []
    points: set[tuple[str, int]] = set()
    for rid, plan in sorted(hints.items()):
        for pos, (stop, leg) in enumerate(zip(plan.order, plan.legs, strict=True), start=1):
            lines.append(f"hint_at({rid},{pos},{stop}). hint_use({rid},{pos},{leg}).")
        for p in plan.passes:
            points |= {(p.opening, p.start), (p.opening, p.end)}
        points |= set(plan.uses)
    lines += [f"evt({x},{t})." for x, t in sorted(points) if t > 0]
    return "\n".join(lines) + "\n"


def joint(
    site_facts: str,
    problems: dict[str, RobotProblem],
    hold: int,
    constraints: ConstraintProgram | None,
    *,
    existing: tuple[tuple[str, int], ...] = (),
    horizon: int,
    hints: dict[str, RobotPlan] | None = None,
    time_limit: float = 60.0,
) -> tuple[dict[str, RobotPlan] | None, Outcome]:
    busy = tuple(
        Busy(p.opening, p.start, p.end, rid) for rid, prob in sorted(problems.items()) for p in prob.prefix if p.opening
    )
    ctx = Context(given_open=tuple(sorted(existing)), busy=busy, horizon=horizon)
    team = "".join(robot_facts(problems[r]) + f"grp({r},{TEAM}).\n" for r in sorted(problems))
    text = site_facts + team + context_facts(ctx, TEAM) + door_facts(ctx, TEAM, throughs(problems.values()), hold)
    if hints:
        text += hint_facts(hints)
    out = solve(
        text,
        parts_for(constraints, joint=True),
        constraints,
        time_limit=time_limit,
        options=["--heuristic=Domain"] if hints else [],
    )
    if not out.ok:
        return None, out
    return decode(out.atoms, problems, hold, ctx.given_open), out
