"""Where robots wait to cross an opening, queue behind each other and unload: beside the opening's
lane (keep right), in a line along the wall, one slot per robot in the destination room."""

from __future__ import annotations

import math

from protocol.site import loads_site
from runtime.executor.doorways import in_lane
from runtime.site.generate import generate_site
from services.planner.dispatcher import Dispatcher
from services.planner.key_points import DROP_SPACING, PASSING_ROOM, QUEUE_SPACING
from services.planner.motion import MotionPlanner
from services.planner.plan import RobotPlan, Step
from services.planner.problem import ProblemBuilder
from services.planner.world import RobotState, World

from .conftest import planner_for


def lane_offset(opening, p) -> float:
    """How far ``p`` is from the opening's centre line (along the wall)."""
    return abs(p[0] - opening.center[0]) if opening.axis == "x" else abs(p[1] - opening.center[1])


def test_a_robot_waits_to_cross_on_the_right_of_the_lane_and_comes_out_on_it(office):
    builder = planner_for("office").builder
    radius = office.params.robot_radius
    for opening in office.openings.values():
        for room in opening.rooms:
            wait, out = builder.wait_point(opening.id, room), builder.beside(opening.id, room)
            assert lane_offset(opening, out) < 0.05  # a robot comes through onto the lane ...
            assert lane_offset(opening, wait) >= opening.width / 2  # ... and waits beside the gap,
            assert math.dist(wait, out) >= 2 * radius + 0.1  # clear of one coming out
    storage = office.opening("d_storage")
    corridor_side = builder.wait_point("d_storage", "corridor")
    storage_side = builder.wait_point("d_storage", "storage")
    # keep right: the two sides' waiting points are on opposite sides of the lane
    along = 0 if storage.axis == "x" else 1
    assert (corridor_side[along] - storage.center[along]) * (storage_side[along] - storage.center[along]) < 0


def test_queue_spots_stand_in_a_line_apart_and_off_every_lane(office):
    builder = planner_for("office").builder
    for opening in office.openings.values():
        for room in opening.rooms:
            spots = builder.queue_spots(opening.id, room)
            assert spots[0] == builder.wait_point(opening.id, room)
            assert all(math.dist(a, b) >= QUEUE_SPACING - 1e-6 for i, a in enumerate(spots) for b in spots[i + 1 :])
            assert all(builder.motion.is_free(p) and office.rooms[room].contains(*p) for p in spots[1:])
            assert all(lane_offset(opening, p) >= opening.width / 2 for p in spots)
            radius = office.params.robot_radius
            others = [o for o in office.openings.values() if o.id != opening.id]
            assert not any(in_lane(o, *p, reach=radius) for o in others for p in spots[1:])


def test_twelve_robots_queue_along_a_corridors_wall_and_leave_a_way_past():
    # the 12-robot site where six spots sent the seventh robot onto the sixth's spot, and a second
    # line in the middle of the 2 m corridor left no way past: the corridor jammed
    site = loads_site(generate_site(12, 3, seed=281555893))
    builder = ProblemBuilder(site, MotionPlanner(site))
    spots = builder.queue_spots("d_storage", "corridor")
    x0, y0, x1, y1 = site.rooms["corridor"].rect
    radius = site.params.robot_radius
    assert len(spots) > 6
    assert all(y1 - p[1] >= 3 * radius + PASSING_ROOM for p in spots)  # a robot gets past each
    doors = [o for o in site.openings.values() if o.id != "d_storage"]
    assert not any(in_lane(o, *p, reach=radius) for o in doors for p in spots)
    inside = builder.queue_spots("d_storage", "storage")  # a 4 m deep room has room for a second line
    assert len(inside) == len(site.robots)


def test_every_robot_has_its_own_drop_slot_in_a_crowded_storage_room():
    site = loads_site(generate_site(6, 3, seed=444237223))
    builder = ProblemBuilder(site, MotionPlanner(site))
    slots = {}
    for obj, spec in site.objects.items():
        slots.setdefault(spec.robot, set()).add(builder.drop_point(obj))
    assert all(len(s) == 1 for s in slots.values())  # one slot per robot ...
    points = [next(iter(s)) for s in slots.values()]
    assert len(set(points)) == len(site.robots)  # ... none shared
    assert all(math.dist(a, b) >= DROP_SPACING - 1e-6 for i, a in enumerate(points) for b in points[i + 1 :])


def test_the_dispatcher_sends_an_approaching_robot_to_the_first_free_queue_spot(office):
    planner = planner_for("office")
    builder = planner.builder
    spots = builder.queue_spots("d_storage", "corridor")
    x0, y0 = spots[0]
    robots = {
        "r0": RobotState(id="r0", pose=(x0, y0, 0.0), beside="d_storage"),  # waits at the first spot
        "r1": RobotState(id="r1", pose=(2.0, 5.0, 0.0)),
    }
    world = World(now=10.0, robots=robots, open_doors={})
    plan = RobotPlan(robot="r1", steps=(Step("approach", ("d_storage",), 10, 30),), finish=30, passes=())
    rows, _ = Dispatcher(builder, planner.motion).trajectory("r1", plan, plan.steps[0], world)
    assert math.dist(rows[-1][1:3], spots[1]) < 1e-6
