"""The plan validator catches what makes a plan impossible to execute (so a pass means something)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from services.planner.validator import StepView, Windows, validate
from services.planner.world import initial_world
from tests.planner.conftest import planner_for, site_named

SITE = site_named("office")
WORLD = initial_world(SITE)


@pytest.fixture(scope="module")
def plan():
    result = planner_for("office").plan(WORLD)
    robots = {
        rid: [StepView(s.action, s.args, result.absolute(s.start), result.absolute(s.end)) for s in p.steps]
        for rid, p in result.plans.items()
    }
    openings = [(o.door, float(result.absolute(o.start)), float(result.absolute(o.end))) for o in result.openings]
    assert validate(SITE, WORLD, robots, openings, Windows()) == []
    return robots, openings


def check(robots, openings, windows: Windows | None = None):
    return validate(SITE, WORLD, robots, openings, Windows() if windows is None else windows)


def first(steps, action, arg=None):
    return next(i for i, s in enumerate(steps) if s.action == action and (arg is None or s.args[0] == arg))


def test_a_human_door_without_opendoor(plan):
    robots, openings = plan
    steps = list(robots["r0"])
    del steps[first(steps, "opendoor")]
    errors = check({**robots, "r0": steps}, openings)
    assert any("without opendoor" in e for e in errors)


def test_a_crossing_outside_every_opening(plan):
    robots, openings = plan
    steps = robots["r0"]
    g = steps[first(steps, "gothrough", "d_storage")]
    kept = [o for o in openings if not (o[1] <= g.start and g.end <= o[2])]
    errors = check(robots, kept)
    assert any("door is not open" in e for e in errors)


def test_gothrough_without_approach(plan):
    robots, openings = plan
    steps = list(robots["r1"])
    i = first(steps, "approach")
    del steps[i]
    errors = check({**robots, "r1": steps}, openings)
    assert any("not preceded by approach" in e for e in errors)


def test_loading_elsewhere_and_unloading_what_is_not_carried(plan):
    robots, openings = plan
    steps = list(robots["r2"])
    i, j = first(steps, "load"), first(steps, "unload")
    steps[i], steps[j] = replace(steps[i], action="unload"), replace(steps[j], action="load")
    errors = check({**robots, "r2": steps}, openings)
    assert any("is not carried" in e for e in errors) and any("is in" in e or "goes to" in e for e in errors)


def test_capacity(plan):
    robots, openings = plan
    steps = list(robots["r0"])
    i = first(steps, "unload")
    del steps[i]
    errors = check({**robots, "r0": steps}, openings)
    assert any("capacity 1 exceeded" in e for e in errors)
    assert any("never delivered" in e for e in errors)


def test_another_robots_object(plan):
    robots, openings = plan
    steps = list(robots["r0"])
    i = first(steps, "load")
    steps[i] = replace(steps[i], args=("o5",))
    assert any("belongs to r1" in e for e in check({**robots, "r0": steps}, openings))


def test_two_robots_in_one_doorway(plan):
    robots, openings = plan
    a = robots["r0"][first(robots["r0"], "gothrough", "d_storage")]
    steps = list(robots["r1"])
    j = first(steps, "gothrough", "d_storage")
    shift = a.start - steps[j].start
    steps[j] = replace(steps[j], start=a.start, end=steps[j].end + shift)
    errors = check({**robots, "r1": steps}, openings)
    assert any("both in the doorway of d_storage" in e for e in errors)


def test_overlapping_openings_and_unavailability(plan):
    robots, openings = plan
    d, s, e = openings[0]
    errors = check(robots, openings + [(d, s + 5, e + 5)])
    assert any("overlap" in e for e in errors)
    errors = check(robots, openings, Windows(unavailable=[(d, int(s), int(s) + 1)]))
    assert any("unavailable" in e for e in errors)


def test_forbidden_room_and_time_travel(plan):
    robots, openings = plan
    assert any(
        "forbidden room storage" in e for e in check(robots, openings, Windows(forbidden=[("storage", 0, 10_000)]))
    )
    steps = list(robots["r0"])
    steps[1] = replace(steps[1], start=steps[0].start - 1)
    assert any("starts before the previous step ends" in e for e in check({**robots, "r0": steps}, openings))


def test_too_fast(plan):
    robots, openings = plan
    steps = list(robots["r2"])
    i = first(steps, "approach", "d_storage")
    steps[i] = replace(steps[i], end=steps[i].start)
    assert any("straight line takes" in e for e in check({**robots, "r2": steps}, openings))
