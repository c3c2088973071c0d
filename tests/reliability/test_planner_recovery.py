"""What the planner does to come through faults, against a real ``arroch planner`` process, with the
test client playing the simulator:

- started while a mission is under way (a restart), it plans only once every robot's pose and
  status are in, from that state: running actions are taken over (same id, not sent again),
  finished ones get new ids above the robots', delivered and carried objects are not planned again;
- a plan the simulator may have lost (it stays paused at a version the plan answers) is published
  again, and only then.
"""

from __future__ import annotations

import time

import pytest

from protocol.messages import Clock, RobotCommand, RobotPose, RobotStatus, TeamPlan
from tests.conftest import TestClient
from tests.planner.test_service import SITE, publish_world, start_planner

from .watch import Watch

pytestmark = pytest.mark.integration

VERSION = 5  # the world version of the mission the planner joins


def paused_clock(client: TestClient, version: int, at: float, paused: bool = True) -> None:
    client.publish(client.keys.clock(), Clock(time=at, mode="lockstep", world_version=version, paused=paused))


def test_a_planner_started_mid_mission_plans_from_the_robots_state_once_it_has_all_of_it(
    spawn, router, namespace, client
):
    plans = Watch(client, client.keys.plan(), TeamPlan)
    commands = Watch(client, client.keys.robot_command("*"), RobotCommand)
    start_planner(spawn, router, namespace)
    # The simulator is paused at world v5, waiting for a plan; its statuses and poses come once a second.
    for _ in range(5):
        paused_clock(client, VERSION, 120.0)
        time.sleep(0.5)
    assert not plans.messages(), "no plan before the planner knows where the robots are"

    o3 = SITE.objects["o3"]
    states = {
        # r0 has loaded o0 and ended that action (id 4): it must carry o0 to storage next.
        "r0": (
            (1.5, 8.1, 1.57),
            RobotStatus(
                robot="r0",
                state="done",
                action_id=4,
                action="load",
                args=["o0"],
                carrying=["o0"],
                world_version=VERSION,
            ),
        ),
        # r1 is loading o3 (action 7 of a plan of the planner that died): it must be left to finish.
        "r1": (
            (o3.position[0], o3.position[1] - 0.5, 1.57),
            RobotStatus(
                robot="r1",
                state="loading",
                action_id=7,
                action="load",
                args=["o3"],
                progress=0.5,
                world_version=VERSION,
            ),
        ),
        # r2 has delivered o6 and stands at its start.
        "r2": (
            SITE.robots["r2"].start,
            RobotStatus(
                robot="r2",
                state="idle",
                action_id=12,
                action="unload",
                args=["o6"],
                delivered=["o6"],
                world_version=VERSION,
            ),
        ),
    }
    assert SITE.room_at(*states["r1"][0][:2]).id == o3.room
    for rid, (pose, status) in states.items():
        client.publish(client.keys.robot_pose(rid), RobotPose(robot=rid, x=pose[0], y=pose[1], theta=pose[2]))
        client.publish(client.keys.robot_status(rid), status)
    _, plan = plans.first(lambda p: p.world_version == VERSION, "plan for the live world version")
    time.sleep(1.0)  # the commands of that plan, and nothing sent again

    steps = {rid: [(s.action, s.args[0] if s.args else "") for s in plan.robots[rid]] for rid in SITE.robots}
    assert ("load", "o0") not in steps["r0"] and ("unload", "o0") in steps["r0"], steps["r0"]
    assert steps["r1"][0] == ("load", "o3") and plan.robots["r1"][0].action_id == 7, plan.robots["r1"][:1]
    assert not [s for s in steps["r2"] if s[1] == "o6"] and ("load", "o7") in steps["r2"], steps["r2"]
    sent = commands.messages()
    assert not [c for c in sent if c.robot == "r1"], "r1's running load was taken over, not sent again"
    r0 = [c for c in sent if c.robot == "r0"]
    r2 = [c for c in sent if c.robot == "r2"]
    assert r0 and all(c.action_id > 4 for c in r0) and r2 and all(c.action_id > 12 for c in r2)
    assert plan.robots["r0"][0].action_id == r0[-1].action_id


def test_a_plan_is_published_again_while_the_simulator_stays_paused_at_the_version_it_answers(
    spawn, router, namespace, client
):
    plans = Watch(client, client.keys.plan(), TeamPlan)
    start_planner(spawn, router, namespace)
    publish_world(client, 1, 0.0)
    _, first = plans.first(lambda p: p.world_version >= 1, "first plan")
    time.sleep(0.5)  # replans as the statuses came in
    latest = plans.latest()
    assert latest is not None

    def copies() -> int:
        return sum(p.plan_id == latest.plan_id for p in plans.messages())

    # Running: nothing is sent again.
    for _ in range(6):
        paused_clock(client, 1, 3.0, paused=False)
        time.sleep(0.5)
    assert copies() == 1
    # Paused at the version the plan answers (the simulator lost it, or waits for something else):
    # the same plan again, every 2 s.
    start = time.monotonic()
    while copies() < 3 and time.monotonic() - start < 10:
        paused_clock(client, 1, 3.0)
        time.sleep(0.5)
    assert copies() >= 3, "published again while the simulator stays paused"
    repeated = [p for p in plans.messages() if p.plan_id == latest.plan_id]
    assert all(p.robots == latest.robots and p.world_version == latest.world_version for p in repeated)
    assert 3.0 <= time.monotonic() - start <= 8.0
