"""The detour family of buildings, and the real planner reordering a robot's deliveries around her declared window."""

from __future__ import annotations

import pytest

from protocol.site import loads_site
from runtime.site.generate import generate_site
from runtime.site.generate_detour import door_count, generate_detour_site
from services.planner.constraints import ConstraintProgram, unavailable
from services.planner.planner import PlannerSettings, TaskPlanner
from services.planner.validator import Windows, validate_result
from services.planner.world import initial_world


@pytest.mark.parametrize("share, expected", [(0.0, 0), (0.1, 1), (0.5, 4), (1 / 3, 3), (1.0, 9)])
def test_the_share_is_a_fixed_count_of_deliveries_behind_her_door(share: float, expected: int) -> None:
    site = loads_site(generate_detour_site(3, 3, 7, share), "d.toml")
    assert door_count(9, share) == expected
    assert sum(o.deliver_to == "storage" for o in site.objects.values()) == expected


def test_same_building_and_object_places_as_the_papers_site_only_destinations_differ() -> None:
    for seed in range(5):
        paper = loads_site(generate_site(2, 3, seed), "p.toml")
        detour = loads_site(generate_detour_site(2, 3, seed, 0.5, robot_capacity=2), "d.toml")
        assert detour.rooms == paper.rooms and detour.openings == paper.openings
        assert {o.id: (o.position, o.robot) for o in detour.objects.values()} == {
            o.id: (o.position, o.robot) for o in paper.objects.values()
        }
        assert detour.params.robot_capacity == 2
        for o in detour.objects.values():
            start = next(r.id for r in detour.rooms.values() if r.id != "corridor" and r.contains(*o.position))
            assert o.deliver_to != start and o.deliver_to != "corridor"
        assert generate_detour_site(2, 3, seed, 0.5, robot_capacity=2) == generate_detour_site(
            2, 3, seed, 0.5, robot_capacity=2
        )
    assert [o.deliver_to for o in loads_site(generate_detour_site(2, 3, 4, 1.0), "d").objects.values()] == [
        "storage"
    ] * 6


def test_the_planner_reorders_the_deliveries_around_a_declared_window() -> None:
    # One robot, two objects: one goes into her storage room, the other to another room. Seed 2 is a building in which,
    # free to, the robot delivers into storage first (checked below). With her door unavailable for the first 200 s,
    # the better order is the other errand first: it fills the wait, and the storage delivery follows the window.
    site = loads_site(generate_detour_site(1, 2, 2, 0.5), "unit.toml")
    planner = TaskPlanner(site, PlannerSettings(time_limit=60.0, joint_time_limit=60.0))
    world = initial_world(site)
    destination = {o.id: o.deliver_to for o in site.objects.values()}
    free = planner.plan(world)
    assert [destination[s.args[0]] for s in free.plans["r0"].steps if s.action == "unload"][0] == "storage"
    window = unavailable("d_storage", 0, 200, "c1")
    program = ConstraintProgram.build([window])
    result = planner.plan(world, program)
    assert result.status == "ok"
    order = [destination[s.args[0]] for s in result.plans["r0"].steps if s.action == "unload"]
    assert order[-1] == "storage" and order[0] != "storage"
    assert validate_result(site, world, result, Windows.of(program.facts())) == []
    # The other errand was done inside the window: the robot waits at her door less than the window is long, and it
    # finishes sooner than the free order would under the window (wait until 200 s, then everything from the door on).
    steps = result.plans["r0"].steps
    waited = sum(s.end - s.start for s in steps if s.action == "opendoor")
    assert waited < 200 - 60
    door_leg = free.makespan - next(
        s.start for s in free.plans["r0"].steps if s.action == "approach" and s.args == ("d_storage",)
    )
    assert result.makespan < 200 + door_leg
