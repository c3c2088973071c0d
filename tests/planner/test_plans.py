"""Plans on the default site and on generated sites are executable, IIDP converges, openings are shared."""

from __future__ import annotations

import pytest

from services.planner.constraints import ConstraintProgram, unavailable
from services.planner.facts import Context, site_facts
from services.planner.iidp import NoPlan, iidp
from services.planner.plan import RobotPlan, Step, TeamResult, share_windows
from services.planner.planner import PlannerSettings, TaskPlanner
from services.planner.single import SingleRobotSolver
from services.planner.solver import Outcome
from services.planner.validator import validate_result
from services.planner.world import initial_world
from tests.planner.conftest import planner_for, site_named

_cache: dict[tuple[str, str], TeamResult] = {}


def plan(name: str, method: str = "iidp") -> TeamResult:
    key = (name, method)
    if key not in _cache:
        _cache[key] = planner_for(name).plan(initial_world(site_named(name)), method=method)
    return _cache[key]


@pytest.mark.parametrize("name", ["office", "gen2", "gen3", "gen4", "gen5", "gen6"])
def test_iidp_plans_are_valid(name):
    site = site_named(name)
    result = plan(name)
    assert result.status == "ok", result.diagnostic
    assert validate_result(site, initial_world(site), result) == []
    assert result.conflicts == 0
    # every robot has work, and the team needs the human at least once
    assert all(not p.empty for p in result.plans.values())
    assert result.door_openings >= 1
    assert result.makespan == max(p.finish for p in result.plans.values())


@pytest.mark.parametrize("name", ["office", "gen3", "gen6"])
def test_iidp_converges_within_its_round_cap(name):
    result = plan(name)
    n = len(site_named(name).robots)
    assert result.converged, "stopped because no robot could improve the team"
    assert 0 <= result.iterations <= 2 * n


def test_iidp_improves_on_planning_each_robot_alone():
    """Plans made alone (IIDP's first step) put robots in one doorway at once or ask the human for
    overlapping openings; the team IIDP hands out has none of that and is no worse otherwise."""
    name = "gen4"
    site = site_named(name)
    tp = planner_for(name)
    world = initial_world(site)
    problems = tp.problems(world, 0)
    single = SingleRobotSolver(site_facts(site, 0), tp.hold, None)
    alone = {rid: single.solve(p, Context())[0] for rid, p in problems.items()}
    alone_team = TeamResult("alone", 0, tp.hold, share_windows(alone, tp.hold))
    team = plan(name)
    assert alone_team.conflicts > 0 and team.conflicts == 0
    assert team.cost() < alone_team.cost()
    # and the rounds after placing the robots never make the team worse
    unpolished = TaskPlanner(site, PlannerSettings(max_rounds=0)).plan(world)
    assert team.cost() <= unpolished.cost()


def test_iidp_is_deterministic():
    name = "gen3"
    site = site_named(name)
    again = planner_for(name).plan(initial_world(site))
    first = plan(name)
    strip = lambda r: {k: v for k, v in r.as_json().items() if k != "solve_time"}  # noqa: E731
    assert strip(again) == strip(first)


def test_robots_heading_to_one_door_share_an_opening():
    site = site_named("pair")
    result = plan("pair")
    assert validate_result(site, initial_world(site), result) == []
    passes = [p for plan_ in result.plans.values() for p in plan_.passes if p.human]
    assert len(passes) == 2 and {p.opening for p in passes} == {"d_storage"}
    assert result.door_openings == 1 < len(site.robots)
    assert result.openings[0].robots == ("r0", "r1")


def test_openings_are_shared_on_the_default_site():
    result = plan("office")
    human_passes = sum(1 for p in result.plans.values() for x in p.passes if x.human)
    assert result.door_openings < human_passes
    assert any(len(o.robots) >= 2 for o in result.openings)


@pytest.mark.parametrize("name", ["pair", "gen2"])
def test_joint_plans_are_valid_and_no_worse_than_iidp(name):
    site = site_named(name)
    joint = plan(name, "joint")
    assert joint.status in ("ok", "timeout") and joint.plans
    assert validate_result(site, initial_world(site), joint) == []
    assert joint.cost()[1:3] <= plan(name).cost()[1:3]


def test_a_plan_from_scratch_keeps_the_better_of_two_ways_of_breaking_ties():
    """Robots have equally good plans; how one breaks the tie decides where the next can go. On this
    site the two ways give different teams, and the planner hands out the better one."""
    name = "gen2"
    site = site_named(name)
    tp = planner_for(name)
    world = initial_world(site)
    problems = tp.problems(world, 0)

    def team(extra: str) -> tuple:
        single = SingleRobotSolver(site_facts(site, 0) + extra, tp.hold, None)
        plans, _ = iidp(single, problems, time_limit=60.0)
        return TeamResult("iidp", 0, tp.hold, plans).cost()

    first, early = team(""), team("early.\n")
    assert first != early, "the ties matter here"
    assert plan(name).cost() == min(first, early)


def test_a_plan_moved_past_its_end_finishes_now_not_before():
    """Re-expressed against a later base (the service keeps a plan as robots end their actions), a
    robot done long ago finishes at 0, so the team's makespan is never negative on the wire."""
    done = RobotPlan("r0", steps=(), finish=40, passes=())
    going = RobotPlan("r1", steps=(Step("approach", ("d",), 50, 60),), finish=60, passes=())
    moved = {p.robot: p.shifted(-55) for p in (done, going)}
    assert moved["r0"].finish == 0 and moved["r1"].finish == 5
    assert TeamResult("iidp", 0, 20, moved).makespan == 5
    assert TeamResult("iidp", 0, 20, {"r0": moved["r0"]}).makespan == 0


def _iidp_out_of_time_first(times: int, limits: list[tuple[float, float]]):
    """IIDP that finds no model in time on its first ``times`` calls (as on a loaded machine),
    then plans for real; ``limits`` collects each call's (solve limit, time limit). Only the run
    breaking ties the first way counts: the other one (``early``) runs beside it on its own thread."""

    def fake(single, problems, *, time_limit, **kwargs):  # noqa: ANN001, ANN202
        if "early." in single.site_facts:
            return iidp(single, problems, time_limit=time_limit, **kwargs)
        limits.append((single.solve_limit, time_limit))
        if len(limits) <= times:
            raise NoPlan(sorted(problems)[0], Outcome(status="unknown"))
        return iidp(single, problems, time_limit=time_limit, **kwargs)

    return fake


def test_a_plan_out_of_time_without_a_model_is_made_again_with_longer_limits(monkeypatch):
    """Under load a solve can find no model within its limits: the plan is made again with 4x the
    limits, and is the plan an unloaded machine makes, not a failure left for nobody to retry."""
    name = "office"
    site = site_named(name)
    tp = TaskPlanner(site, PlannerSettings(time_limit=10.0, solve_limit=2.0))
    limits: list[tuple[float, float]] = []
    monkeypatch.setattr("services.planner.planner.iidp", _iidp_out_of_time_first(1, limits))
    result = tp.plan(initial_world(site))
    assert result.status == "ok" and not result.out_of_time, result.diagnostic
    assert limits[:2] == [(2.0, 10.0), (8.0, 40.0)]
    strip = lambda r: {k: v for k, v in r.as_json().items() if k != "solve_time"}  # noqa: E731
    assert strip(result) == strip(plan(name))


def test_a_plan_still_out_of_time_after_the_retries_fails_and_says_why(monkeypatch):
    site = site_named("office")
    tp = TaskPlanner(site, PlannerSettings(time_limit=10.0, solve_limit=2.0))
    limits: list[tuple[float, float]] = []
    monkeypatch.setattr("services.planner.planner.iidp", _iidp_out_of_time_first(99, limits))
    result = tp.plan(initial_world(site))
    assert result.status == "failed" and result.out_of_time
    assert "within the time limit" in result.diagnostic
    assert [s for s, _ in limits] == [2.0, 8.0, 32.0]  # tried, then retried twice


@pytest.mark.parametrize("name", ["gen2", "office"])
def test_the_two_tie_breaking_runs_side_by_side_give_the_plan_they_give_one_after_the_other(name):
    """A plan from scratch makes its two runs on two threads (``threads=2``, the default); the team
    handed out is the one the runs give in turn, with and without a constraint."""
    site = site_named(name)
    world = initial_world(site)
    door = next(d for d, o in site.doors.items() if o.human_operated)
    program = ConstraintProgram.build([unavailable(door, 0, 90, "busy")])
    strip = lambda r: {k: v for k, v in r.as_json().items() if k != "solve_time"}  # noqa: E731
    for constraints in (None, program):
        results = [
            TaskPlanner(site, PlannerSettings(time_limit=60.0, threads=threads)).plan(world, constraints)
            for threads in (1, 2)
        ]
        assert results[0].status == "ok" and results[0].solves > 0
        assert strip(results[1]) == strip(results[0])
        assert results[1].solves == results[0].solves  # both runs counted
