"""The human's constraints, as the restrictor writes them, shape the plans (docs/architecture.md,
"ASP vocabulary"); unsatisfiable ones are named, not crashed on."""

from __future__ import annotations

from dataclasses import replace

import pytest

from services.planner.constraints import ConstraintProgram, ConstraintText, unavailable
from services.planner.facts import Context, site_facts
from services.planner.single import SingleRobotSolver
from services.planner.validator import Windows, validate_result
from services.planner.world import initial_world
from tests.planner.conftest import planner_for, site_named


def program(*items: ConstraintText) -> ConstraintProgram:
    prog = ConstraintProgram.build(list(items))
    assert not prog.invalid, prog.invalid
    return prog


def forbid_room(room: str, t0: int, t1: int, cid: str) -> ConstraintText:
    return ConstraintText(
        cid, f"room_forbidden({room}, {t0}, {t1}).\n:- robot_in(R, {room}, S, E), S < {t1}, E > {t0}.\n"
    )


def storage_openings(result) -> list[int]:
    return [result.absolute(o.start) for o in result.openings if o.door == "d_storage"]


def test_door_unavailable_moves_every_opening_out_of_the_window():
    site = site_named("office")
    world = initial_world(site)
    free = planner_for("office").plan(world)
    assert any(40 <= t < 200 for t in storage_openings(free)), "the window matters for this site"
    c = unavailable("d_storage", 40, 200, "c1")
    result = planner_for("office").plan(world, program(c))
    assert result.status == "ok"
    assert storage_openings(result) and all(not (40 <= t < 200) for t in storage_openings(result))
    assert validate_result(site, world, result, Windows.of(program(c).facts())) == []


def test_times_are_absolute_site_clock_seconds():
    site = site_named("office")
    world = initial_world(site, now=1000.4)
    c = unavailable("d_storage", 1030, 1160, "c1")
    result = planner_for("office").plan(world, program(c))
    assert result.base == 1000
    starts = [result.absolute(s.start) for p in result.plans.values() for s in p.steps]
    assert min(starts) >= 1000
    assert storage_openings(result) and all(not (1030 <= t < 1160) for t in storage_openings(result))
    assert validate_result(site, world, result, Windows.of(program(c).facts())) == []


def test_while_the_door_is_unavailable_the_robot_does_other_work_first():
    site = site_named("errand")
    world = initial_world(site)
    free = planner_for("errand").plan(world)
    order = [s.args[0] for s in free.plans["r0"].steps if s.action == "unload"]
    assert order == ["o_store", "o_office"], "without the constraint the storage delivery comes first"
    c = unavailable("d_storage", 0, 150, "c1")
    result = planner_for("errand").plan(world, program(c))
    plan = result.plans["r0"]
    assert [s.args[0] for s in plan.steps if s.action == "unload"] == ["o_office", "o_store"]
    assert validate_result(site, world, result, Windows.of(program(c).facts())) == []
    # the office delivery fills the wait: the robot is done soon after the door may open again
    door_part = free.makespan - next(
        s.start for s in free.plans["r0"].steps if s.action == "approach" and s.args == ("d_storage",)
    )
    assert result.makespan <= 150 + door_part + 5
    waited = sum(s.end - s.start for s in plan.steps if s.action == "opendoor")
    assert waited < 150 - 60, "most of the window was spent working, not waiting at the door"


def test_a_forbidden_room_is_kept_clear_for_its_window():
    site = site_named("office")
    world = initial_world(site)
    free = planner_for("office").plan(world)
    visits = [(r, s, e) for p in free.plans.values() for r, s, e in p.visits if r == "office_b"]
    assert visits, "some robot uses office_b without the constraint"
    until = min(s for _, s, _ in visits) + 60  # forbidden from the start to past its first use
    c = forbid_room("office_b", 0, until, "c2")
    result = planner_for("office").plan(world, program(c))
    assert result.status == "ok", result.diagnostic
    assert validate_result(site, world, result, Windows.of(program(c).facts())) == []
    for p in result.plans.values():
        for room, s, e in p.visits:
            assert not (room == "office_b" and s < until and e > 0)


def test_goes_through_constraints_are_honoured():
    site = site_named("errand")
    c = ConstraintText("c3", ":- goes_through(r0, p_corridor_annex, T), T < 60.\n")
    result = planner_for("errand").plan(initial_world(site), program(c))
    through = [s.start for s in result.plans["r0"].steps if s.action == "gothrough" and s.args == ("p_corridor_annex",)]
    assert through and min(through) >= 60


def test_an_offer_from_the_human_is_preferred_when_it_costs_no_time_to_the_team():
    site = site_named("errand")
    prob = planner_for("errand").problems(initial_world(site), 0)["r0"]

    def first_opening(constraints):
        solver = SingleRobotSolver(site_facts(site, 0), 20, constraints)
        # another robot finishes late, so this one has time to spare
        plan, out = solver.solve(prob, replace(Context(), others_end=600))
        assert plan is not None, out.status
        return min(t for _, t in plan.uses)

    assert first_opening(None) < 150
    offer = ConstraintText("c4", "human_available(d_storage, 150, 200).\n")
    assert 150 <= first_opening(program(offer)) < 200


def test_a_warm_replan_does_not_reuse_openings_a_new_constraint_forbids():
    site = site_named("office")
    world = initial_world(site)
    before = planner_for("office").plan(world)
    c = unavailable("d_storage", 40, 200, "c1")
    after = planner_for("office").plan(world, program(c), warm=before)
    assert validate_result(site, world, after, Windows.of(program(c).facts())) == []


def test_unsatisfiable_constraints_are_named():
    site = site_named("office")
    keep_out = forbid_room("lab", 0, 600, "keep_out_lab")  # r1 starts in the lab
    harmless = unavailable("d_storage", 10, 20, "harmless")
    result = planner_for("office").plan(initial_world(site), program(harmless, keep_out))
    assert result.status == "conflict"
    assert result.conflict_ids == ["keep_out_lab"]
    assert "keep_out_lab" in result.diagnostic and not result.plans


@pytest.mark.parametrize(
    "text, why",
    [
        ("#script (python)\nimport os\n#end.\n", "directive"),
        ('#include "/etc/passwd".\n', "string"),
        ("foo(1).\n", "vocabulary"),
        (":- human_opens(D, T), T >\n", "ASP"),
    ],
)
def test_unsafe_or_broken_constraints_are_left_out(text, why):
    prog = ConstraintProgram.build([ConstraintText("bad", text), unavailable("d_storage", 0, 10, "ok")])
    assert set(prog.invalid) == {"bad"} and why.lower() in prog.invalid["bad"].lower()
    assert prog.ids(prog.active) == ["ok"]
