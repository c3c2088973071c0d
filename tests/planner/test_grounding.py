"""What keeps single-robot programs small must not change what they find: the wait ends left out
before grounding (blocked/closed facts) lose no optimum, and several robots' programs grounded
together and solved one robot at a time give each robot the optimum it has alone."""

from __future__ import annotations

import re

import pytest

from services.planner.facts import Context, closed_facts, merged, minus, recross, site_facts
from services.planner.plan import RobotPlan
from services.planner.problem import Crossing, Leg, RobotProblem
from services.planner.replay import world_at
from services.planner.single import SingleRobotSolver
from services.planner.solver import solve
from services.planner.world import initial_world
from tests.planner.conftest import planner_for, site_named


@pytest.fixture(scope="module")
def mid_mission():
    """Four robots half-way through their first plan: every robot's problem and its context against
    the others' plans (busy doorways, openings to share), as IIDP's rounds see them."""
    name = "gen4"
    tp = planner_for(name)
    world = initial_world(site_named(name))
    first = tp.plan(world)
    now = first.makespan / 2
    mid = world_at(tp.builder, world, first, now)
    base = int(now)
    plans = {rid: p.shifted(first.base - base) for rid, p in first.plans.items()}
    problems = tp.problems(mid, base)
    single = SingleRobotSolver(site_facts(tp.site, base), tp.hold, None, base=base)
    requests = []
    for rid, prob in problems.items():
        if prob.done:
            continue
        others = {o: p for o, p in plans.items() if o != rid}
        requests.append((prob, single.context(prob, others)))
    assert len(requests) >= 3 and any(ctx.busy for _, ctx in requests)
    return single, requests


def figures(plan: RobotPlan | None, ctx: Context) -> tuple | None:
    """What the program optimises: finishing time and openings not already given."""
    if plan is None:
        return None
    return plan.finish, len(plan.uses - set(ctx.given_open))


# What the left-out times stand for, stated as constraints over the plan instead.
AS_CONSTRAINTS = """
:- go(R,P,L,K,G), cross(L,K,X,_,_,_,Dg), grp(R,Q), busy(Q,X,S,E,R2), R2 != R, G < E, S < G+Dg.
"""


def test_wait_ends_left_out_before_grounding_lose_no_optimum(mid_mission):
    """blocked/closed facts leave out times at which the gothrough would overlap another robot's or
    find its door closed; the same program stating that as constraints finds the same optimum."""
    single, requests = mid_mission
    pruned_somewhere = False
    for prob, ctx in requests:
        facts = single.site_facts + single._member(prob, ctx) + f"active({prob.robot}).\n"
        bare = re.sub(r"^(blocked|closed)\(.*\n", "", facts, flags=re.M) + AS_CONSTRAINTS
        pruned_somewhere |= bare != facts
        with_pruning = solve(facts, single.parts, time_limit=30, diagnose=False)
        without = solve(bare, single.parts, time_limit=30, diagnose=False)
        assert with_pruning.status == without.status == "optimal"
        a, _ = single._decoded(prob, ctx, with_pruning)
        b, _ = single._decoded(prob, ctx, without)
        assert figures(a, ctx) == figures(b, ctx), prob.robot
    assert pruned_somewhere, "the busy doorways leave some wait ends out"


def test_robots_grounded_together_get_the_optimum_they_have_alone(mid_mission):
    single, requests = mid_mission
    together = SingleRobotSolver(single.site_facts, single.hold, None, base=single.base)
    together.prefetch(requests)
    assert together.calls == len(requests)
    for prob, ctx in requests:
        apart = SingleRobotSolver(single.site_facts, single.hold, None, base=single.base)
        a, out_a = together.solve(prob, ctx)  # found in the cache the prefetch filled
        b, out_b = apart.solve(prob, ctx)
        assert out_a.status == out_b.status == "optimal"
        assert figures(a, ctx) == figures(b, ctx), prob.robot
    assert together.calls == len(requests) and together.cache_hits == len(requests)


def test_spans_join_and_cut():
    assert merged([(5, 9), (1, 3), (4, 4), (12, 15), (14, 20), (30, 29)]) == [(1, 9), (12, 20)]
    assert minus([(1, 10), (20, 30)], [(3, 4), (8, 22), (29, 40)]) == [(1, 2), (5, 7), (23, 28)]
    assert minus([(1, 10)], []) == [(1, 10)]


def _robot(legs: tuple[Leg, ...]) -> RobotProblem:
    return RobotProblem(
        robot="r0", room="a", ready=0, point=(0.0, 0.0), beside="", carrying=(), stops={}, legs=legs, capacity=1
    )


def test_a_door_closed_for_good_is_where_no_window_can_hold_the_gothrough():
    # into room b through human door d and out again: 3 s through, 11 s to the stop and its work,
    # 4 s back to the door, 3 s out: 21 s from the first gothrough's start to the second's end
    into = Leg("l(r0,0)", "start", "ld(o)", (Crossing("d", "a", "b", 4, 3, True),), 11, "b")
    out = Leg("l(r0,1)", "ld(o)", "ul(o)", (Crossing("d", "b", "a", 4, 3, True),), 10, "a")
    prob = _robot((into, out))
    ctx = Context(given_open=(("d", 100),))
    # hold 20: a window at 100 holds a 3 s gothrough starting 100..117; no new opening within 20 s of
    # it, so a gothrough starting 80..99 or 118..120 finds the door closed
    assert not recross(prob, "d", 20)
    facts = closed_facts(prob, ctx, 20)
    assert set(re.findall(r"closed\(r0,d,([\d.]+),3\)", facts)) == {"80..99", "118..120"}
    # with a hold of 21 s the robot is back within its own opening: it may share it, nothing is closed
    assert recross(prob, "d", 21)
    assert closed_facts(prob, ctx, 21) == "shares(r0,d).\n"
