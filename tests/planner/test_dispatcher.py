"""Which step the dispatcher sends: an opendoor of a door that is open now is skipped."""

from __future__ import annotations

from services.planner.dispatcher import Dispatcher
from services.planner.plan import Pass, RobotPlan, Step, TeamResult
from services.planner.world import RobotState, World

from .conftest import planner_for


def plan_at_storage_door() -> RobotPlan:
    steps = (
        Step("opendoor", ("d_storage",), 0, 5),
        Step("gothrough", ("d_storage",), 5, 9),
        Step("load", ("o0",), 9, 25),
    )
    return RobotPlan(robot="r0", steps=steps, finish=25, passes=(Pass("d_storage", 5, 9, "", "", True),))


def beside_storage(office, open_doors: dict[str, float]) -> World:
    planner = planner_for("office")
    storage = office.opening("d_storage")
    outside = next(r for r in storage.rooms if r != office.objects["o0"].room)
    x, y = planner.builder.beside("d_storage", outside)
    return World(
        now=50.0, robots={"r0": RobotState(id="r0", pose=(x, y, 0.0), beside="d_storage")}, open_doors=open_doors
    )


def test_opendoor_of_a_closed_door_is_sent(office):
    assert Dispatcher.front(plan_at_storage_door(), beside_storage(office, {})) == 0


def test_opendoor_of_an_open_door_is_skipped_for_the_gothrough(office):
    # Sending it would be done at once, answered by the same plan, and so on until the door closes.
    planner = planner_for("office")
    world = beside_storage(office, {"d_storage": 45.0})
    plan = plan_at_storage_door()
    assert Dispatcher.front(plan, world) == 1
    dispatcher = Dispatcher(planner.builder, planner.motion)
    result = TeamResult(method="iidp", base=50, hold=20, plans={"r0": plan})
    commands, front = dispatcher.dispatch(result, world, plan_id=7)
    assert [(c.action, c.args) for c in commands] == [("gothrough", ["d_storage"])]
    assert dispatcher.front_index == {"r0": 1}
    # the next plan (same steps, as the door is still open) keeps that command
    again, front2 = dispatcher.dispatch(result, world, plan_id=8)
    assert again == [] and front2 == front
