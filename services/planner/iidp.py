"""IIDP, iterative inter-dependent planning (Jiang et al. 2019; paper Section III-C).

1. Plan every robot alone: its goals, the human's constraints, the doors open right now.
2. Plans made alone conflict where robots share a door. Place the robots one after the other, the
   one finishing last first, each against those already placed: a conflict-free team.
   (Resolving them with rounds instead, one robot per round, re-solves every robot in a conflict
   against plans that are themselves inconsistent: correct, but far slower for large teams.)
3. Rounds: for every robot, compute its best plan given the others' current plans (their doorway
   occupancy must not be overlapped, their door openings are free to share, their finishing time
   bounds the team's); evaluate the team objective with that plan swapped in; commit only the
   robot whose swap improves the team most (ties: the first robot id). Stop when no robot improves
   the team, after ``2·N`` rounds, or at the time limit.

The team objective is lexicographic (:meth:`.plan.TeamResult.cost`): conflicts, completion time of
the slowest robot, human door openings, openings outside the human's offers, total robot time.
After every swap the passes are re-assigned to the fewest openings the plans ask for
(:func:`.plan.share_windows`). Every committed swap strictly improves the cost, so the loop ends;
robots are visited in sorted order and clingo runs single-threaded, so the result is deterministic.

Work saved without changing the result:

- a robot is not solved for when no plan of it could beat the current team cost, or the best swap
  found so far in the round: its plan alone (step 1) bounds its finishing time from below, and the
  others' passes bound the openings (the fewest hold windows that cover them, :func:`.team_cost.min_openings`);
  robots are solved in order of that bound, so a round often stops after a few;
- a robot in no conflict can only improve the team without delaying it, so its program is bounded
  by the team's completion time (the horizon), which keeps it small;
- results are cached per robot, legs and context;
- programs solved side by side - every robot alone, every robot's retiming, every candidate's
  response in a round - are grounded together (:meth:`.single.SingleRobotSolver.prefetch`): one
  grounding instead of one per robot, each robot still optimised on its own.

Waits for other robots are bounded (see ``domain.lp``); when that leaves a robot that must have a
plan without one, it is solved again with looser bounds.

Replanning while a mission runs starts from the plan being executed (``warm``): step 1 is skipped;
every robot's current plan is retimed to the world as it is (its order of stops kept, against the
others' current plans: a small program, and an unchanged world gives the plan back); robots left
without a plan or in a conflict are then placed in turn against the rest, each keeping its order of
stops with waits bounded only by the plan (it may queue at a crowded door as long as it takes),
then with every order if that fails; the rounds polish. If the time limit cuts the rounds short
while conflicts remain, robots in conflict are replanned one after the other against all others
(each such plan is conflict-free).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

from .plan import Pass, RobotPlan, count_conflicts
from .problem import RobotProblem
from .single import SingleRobotSolver
from .team_cost import improves, lower_bound, shared, team_cost

log = logging.getLogger("arroch.planner.iidp")

# Bounds on waiting for other robots, loosened step by step when they leave a robot no plan:
# (wait to share an opening or for one to end, wait for a doorway to clear), in seconds; None: only
# the plan's own times bound them.
ESCALATION = ((4, 16), None)
RELAXED_TIME = 5  # times the usual solver time for those larger programs


class NoPlan(Exception):
    """A robot has no plan even on its own."""

    def __init__(self, robot: str, outcome) -> None:
        super().__init__(robot)
        self.robot = robot
        self.outcome = outcome


@dataclass
class IidpStats:
    rounds: int = 0
    converged: bool = False
    skipped: int = 0  # best responses not computed because they could not improve the team


def iidp(
    single: SingleRobotSolver,
    problems: dict[str, RobotProblem],
    *,
    time_limit: float = 10.0,
    max_rounds: int | None = None,
    warm: dict[str, RobotPlan] | None = None,
) -> tuple[dict[str, RobotPlan], IidpStats]:
    t0 = time.perf_counter()
    deadline = t0 + time_limit
    existing = frozenset(single.existing)
    robots = sorted(problems)
    hold = single.hold
    stats = IidpStats()

    def remaining() -> float:
        return max(deadline - time.perf_counter(), single.solve_limit)

    # Robots with nothing left to do only finish what they are in the middle of.
    fixed = {
        rid: single.solve(problems[rid], single.context(problems[rid], {}))[0] for rid in robots if problems[rid].done
    }

    def alone_context(rid: str):
        return single.context(problems[rid], {o: p for o, p in fixed.items() if o != rid and p is not None})

    def plan_alone(rid: str) -> RobotPlan:
        plan, out = single.solve(problems[rid], alone_context(rid), time_limit=remaining())
        if plan is None:
            raise NoPlan(rid, out)
        return plan

    # finishing-time bounds for the rounds' skipping; refined by the plans made alone when there are
    finish_bound = {rid: problems[rid].finish_bound() for rid in robots}
    if warm:
        plans = _warm_start(single, problems, warm, plan_alone, hold, existing)
    else:
        # 1. each robot alone (others' actions in progress are part of the world, so they count)
        single.prefetch([(problems[rid], alone_context(rid)) for rid in robots], time_limit=remaining())
        alone = {rid: plan_alone(rid) for rid in robots}
        finish_bound = {rid: max(finish_bound[rid], alone[rid].finish) for rid in robots}
        plans = shared(alone, hold, existing)
    if not warm and count_conflicts(plans.values(), hold):
        # Plans made alone conflict at shared doors. Rather than one conflict-resolving round at a
        # time (each re-solving every robot in a conflict against plans that are themselves
        # inconsistent), place the robots one after the other, the longest first, each against those
        # already placed; the rounds below then improve the team as IIDP does.
        order = sorted(problems, key=lambda r: (-alone[r].finish, r))
        plans = shared(_in_turn(single, problems, alone, order, None, plan_alone), hold, existing)

    # 2. rounds
    limit = 2 * len(robots) if max_rounds is None else max_rounds
    while stats.rounds < limit:
        current = team_cost(plans, hold, existing)
        # Solve the robots with the most promising bound first; once the best swap found is at least
        # as good as the next robot's bound, no later robot can beat it (ties go to the first id).
        candidates = []
        for rid in robots:
            bound = lower_bound(rid, plans, finish_bound[rid], hold, existing)
            if problems[rid].done or not improves(bound, current):
                stats.skipped += 1
            else:
                candidates.append((bound, rid))
        candidates.sort()
        single.prefetch([_response_request(single, problems[rid], plans, current, hold)[:2] for _, rid in candidates])
        best: tuple[tuple, str, dict[str, RobotPlan]] | None = None
        timed_out = False
        for bound, rid in candidates:
            if best is not None and (bound, rid) > (best[0], best[1]):
                stats.skipped += 1
                continue
            if time.perf_counter() > deadline:
                timed_out = True
                break
            cand = _response(single, problems[rid], plans, current, hold)
            if cand is None:
                continue
            trial = dict(plans)
            trial[rid] = cand
            trial = shared(trial, hold, existing)
            cost = team_cost(trial, hold, existing)
            if improves(cost, current) and (best is None or (cost, rid) < (best[0], best[1])):
                best = (cost, rid, trial)
        if timed_out:
            log.info("IIDP stopped by the time limit after %d rounds", stats.rounds)
            break
        if best is None:
            stats.converged = True
            break
        plans = best[2]
        stats.rounds += 1
        log.debug("round %d: committed %s, team cost %s (was %s)", stats.rounds, best[1], best[0], current)

    # 3. never hand out a plan with conflicts: replan each robot still in one against all others
    # (each such plan is conflict-free with the rest, so one pass normally suffices).
    for _ in range(len(robots)):
        if not count_conflicts(plans.values(), hold):
            break
        for rid in robots:
            others = {o: p for o, p in plans.items() if o != rid}
            if count_conflicts(plans.values(), hold) == count_conflicts(others.values(), hold):
                continue  # not involved in any conflict
            cand = _respond(single, problems[rid], others, None, relax=True)
            if cand is not None:
                plans[rid] = cand
                plans = shared(plans, hold, existing)
    return plans, stats


def _respond(
    single: SingleRobotSolver, prob: RobotProblem, others: dict[str, RobotPlan], horizon: int | None, relax: bool
) -> RobotPlan | None:
    """The robot's best plan against ``others``; with ``relax`` (the robot must get a plan), when the
    bounded waits leave it none, try again with looser bounds and no horizon, and more solver time
    (larger programs, rarely needed)."""
    cand, _ = single.solve(prob, single.context(prob, others, horizon))
    if cand is not None or not relax:
        return cand
    for factor in ESCALATION:
        ctx = single.context(prob, others, None, relaxed=factor is None)
        if factor is not None:
            ctx = replace(ctx, syncwait=single.syncwait * factor[0], clearwait=single.clearwait * factor[1] // 4)
        cand, _ = single.solve(prob, ctx, time_limit=single.solve_limit * RELAXED_TIME)
        if cand is not None:
            return cand
    return None


def _response_request(
    single: SingleRobotSolver, prob: RobotProblem, plans: dict[str, RobotPlan], current: tuple, hold: int
):
    """The program of the robot's best response (its problem and context), the others' plans and
    whether it is in a conflict."""
    others = {o: p for o, p in plans.items() if o != prob.robot}
    involved = current[0] > count_conflicts(others.values(), hold)
    # In no conflict, a plan that finishes after the team does is no improvement.
    return prob, single.context(prob, others, None if involved else current[1]), others, involved


def _response(
    single: SingleRobotSolver, prob: RobotProblem, plans: dict[str, RobotPlan], current: tuple, hold: int
) -> RobotPlan | None:
    """The robot's best response to the others' current plans, over every order of its stops."""
    _, ctx, others, involved = _response_request(single, prob, plans, current, hold)
    return _respond(single, prob, others, ctx.horizon, relax=involved)


def _in_progress(prob: RobotProblem) -> RobotPlan:
    """What binds others before a robot is placed: the crossing it is in the middle of, if any."""
    passes = tuple(Pass(p.opening, p.start, p.end, "", "", False) for p in prob.prefix if p.opening)
    return RobotPlan(robot=prob.robot, steps=(), finish=0, passes=passes)


def _in_turn(
    single: SingleRobotSolver,
    problems: dict[str, RobotProblem],
    alone: dict[str, RobotPlan],
    order: list[str],
    warm: dict[str, RobotPlan] | None,
    plan_alone,
    kept: dict[str, RobotPlan] | None = None,
) -> dict[str, RobotPlan]:
    """Plan the robots in ``order`` one after the other, each against the ``kept`` plans, those
    already placed, and what the rest are in the middle of; in a warm start each first in its current
    order of stops (a small program: only timing and openings change), then with every order. The rest's
    current plans are left out on purpose: made before the world changed, they may overlap the new ones, and a crowded
    door would then leave the robot only very long waits."""
    placed: dict[str, RobotPlan] = {}
    kept = kept or {}
    for rid in order:
        prob = problems[rid]
        context = {**kept, **placed}
        for other in problems:
            if other != rid and other not in context:
                context[other] = _in_progress(problems[other])
        plan = None
        previous = warm.get(rid) if warm else None
        skeleton = prob.following(previous.order, previous.routes) if previous is not None else None
        if skeleton is not None:
            # A robot placed again keeps its order of stops and routes, so only timing and openings
            # change and the program stays small even with waits bounded only by the plan itself:
            # the robot can queue at a crowded door as long as it takes.
            relaxed = single.context(skeleton, context, None, relaxed=True)
            plan, _ = single.solve(skeleton, relaxed, time_limit=single.solve_limit * RELAXED_TIME)
        if plan is None:
            plan = _respond(single, prob, context, None, relax=False)
        if plan is None:
            # Before the larger programs: a robot with no plan even alone has nothing to gain from
            # them (plan_alone raises NoPlan, and the caller explains why).
            fallback = alone.get(rid) or plan_alone(rid)
            plan = _respond(single, prob, context, None, relax=True) or fallback
        placed[rid] = plan
    return placed


def _warm_start(
    single: SingleRobotSolver,
    problems: dict[str, RobotProblem],
    warm: dict[str, RobotPlan],
    plan_alone,
    hold: int,
    existing: frozenset,
) -> dict[str, RobotPlan]:
    """A replan's starting team: every robot's current plan retimed to the world as it is now, each in
    its current order of stops against the others' current plans (an unchanged world gives the plan
    back); the robots this leaves without a plan or in a conflict are then placed in turn, the one
    finishing last first, against the rest."""
    retime: dict[str, tuple] = {}
    for rid in sorted(problems):
        previous = warm.get(rid)
        skeleton = problems[rid].following(previous.order, previous.routes) if previous is not None else None
        if skeleton is not None:
            others = {o: p for o, p in warm.items() if o != rid and o in problems}
            retime[rid] = (skeleton, single.context(skeleton, others))
    single.prefetch(list(retime.values()))
    plans: dict[str, RobotPlan] = {}
    for rid, (skeleton, ctx) in retime.items():
        plan, _ = single.solve(skeleton, ctx)
        if plan is not None:
            plans[rid] = plan
    plans = shared(plans, hold, existing)
    total = count_conflicts(plans.values(), hold)
    involved = {rid for rid in problems if rid not in plans}
    if total:
        involved |= {rid for rid in plans if count_conflicts([p for o, p in plans.items() if o != rid], hold) < total}
    if not involved:
        return plans
    kept = {rid: p for rid, p in plans.items() if rid not in involved}
    order = sorted(involved, key=lambda r: (-warm[r].finish if r in warm else 0, r))
    placed = _in_turn(single, problems, {}, order, warm, plan_alone, kept)
    return shared({**kept, **placed}, hold, existing)
