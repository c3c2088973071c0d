"""The clingo work counters the planner benchmark reads: one program per grounding, and the time of
each phase inside the solve call that spent it."""

from __future__ import annotations

import dataclasses

from services.planner.solver import WORK, solve, solve_each


def test_one_solve_is_one_program_and_its_phases_add_up_to_at_most_its_time():
    before = dataclasses.replace(WORK)
    out = solve("a(1..40). { b(X) : a(X) } 3. #minimize { X : b(X) }. :- not b(7).", [], time_limit=5)
    work = WORK.since(before)
    assert out.status == "optimal" and out.cost == (7,)
    assert work.programs == 1
    assert work.build_seconds > 0 and work.ground_seconds > 0 and work.solve_seconds > 0
    assert work.build_seconds + work.ground_seconds + work.solve_seconds <= out.seconds + 1e-6


def test_several_robots_grounded_together_count_as_one_program():
    facts = "r(a). r(b). v(1..5). { p(R,V) : v(V) } = 1 :- r(R), active(R). #minimize { V,R : p(R,V) }.\n"
    before = dataclasses.replace(WORK)
    outs = solve_each(facts, ["a", "b"], [])  # it declares the active/1 switches itself
    assert WORK.since(before).programs == 1
    assert [o.status for o in outs.values()] == ["optimal", "optimal"]
