"""The planner service as a real process on Zenoh: a router, ``arroch planner``, and a test client
playing the simulator (clock, robot statuses and poses) and the restrictor (ConstraintSet)."""

from __future__ import annotations

import time

import pytest

from protocol.messages import (
    Clock,
    Constraint,
    ConstraintSet,
    DoorState,
    Event,
    RobotCommand,
    RobotPose,
    RobotStatus,
    TeamPlan,
)
from protocol.site import load_site
from tests.conftest import TestClient, wait_for_message
from tests.procs import arroch

pytestmark = pytest.mark.integration

SITE = load_site()
UNAVAILABLE = (40, 200)  # the human cannot open d_storage in this window


def unavailable_set(version: int, t0: int, t1: int) -> ConstraintSet:
    asp = f"human_unavailable(d_storage, {t0}, {t1}).\n:- human_opens(d_storage, T), T >= {t0}, T < {t1}.\n"
    c = Constraint(
        id="c1",
        kind="door_unavailable",
        params={"door": "d_storage", "minutes": 3},
        start=t0,
        end=t1,
        asp=asp,
        origin="test",
    )
    return ConstraintSet(version=version, constraints=[c], asp=asp)


def start_planner(spawn, router: str, namespace: str):
    proc = spawn(arroch("planner", "--connect", router, "--namespace", namespace, "--time-limit", "5"), name="planner")
    proc.wait_for("planner-", timeout=30)  # "planner <instance> up on namespace ..."
    return proc


def publish_world(client: TestClient, version: int, now: float) -> None:
    """What the simulator publishes: the clock (lockstep), every robot's pose and status."""
    client.publish(client.keys.clock(), Clock(time=now, mode="lockstep", world_version=version))
    for rid, spec in SITE.robots.items():
        x, y, th = spec.start
        client.publish(client.keys.robot_pose(rid), RobotPose(robot=rid, x=x, y=y, theta=th))
        client.publish(client.keys.robot_status(rid), RobotStatus(robot=rid, state="idle", world_version=version))


def storage_openings(plan: TeamPlan) -> list[float]:
    return [o.start for o in plan.openings if o.door == "d_storage"]


def test_planner_answers_world_versions_and_new_constraints(spawn, router, namespace, client):
    plans = client.collect(client.keys.plan(), TeamPlan)
    every_plan = client.collect(client.keys.plan(), TeamPlan)
    commands = client.collect(client.keys.robot_command("*"), RobotCommand)
    start_planner(spawn, router, namespace)
    time.sleep(0.5)

    publish_world(client, 1, 0.0)
    first = wait_for_message(plans, lambda p: p.world_version >= 1, timeout=30)
    assert set(first.robots) == set(SITE.robots)
    assert all(first.robots[r] for r in SITE.robots), "every robot has work at the start"
    assert first.door_openings >= 1 and storage_openings(first)
    # the unconstrained plan opens the storage door inside the window we are about to forbid
    assert any(UNAVAILABLE[0] <= t < UNAVAILABLE[1] for t in storage_openings(first))
    # every robot got its front action, with a trajectory that starts where it stands (each command
    # names its plan; a replan as statuses arrive may have sent a newer one)
    seen = {first.plan_id: first}
    got = {}
    deadline = time.monotonic() + 10
    while len(got) < len(SITE.robots) and time.monotonic() < deadline:
        cmd = wait_for_message(commands, timeout=10)
        got[cmd.robot] = cmd
    assert set(got) == set(SITE.robots)
    time.sleep(0.5)
    while not every_plan.empty():
        p, _ = every_plan.get()
        seen[p.plan_id] = p
    for rid, cmd in got.items():
        front = seen[cmd.plan_id].robots[rid][0]
        assert (cmd.action, cmd.args) == (front.action, front.args) and cmd.action_id == front.action_id > 0
        x, y, _ = SITE.robots[rid].start
        assert abs(cmd.trajectory[0][1] - x) < 1e-6 and abs(cmd.trajectory[0][2] - y) < 1e-6

    # a world_version bump with nothing changed is still answered (lockstep waits for it)
    client.publish(client.keys.clock(), Clock(time=0.0, mode="lockstep", world_version=2))
    second = wait_for_message(plans, lambda p: p.world_version >= 2, timeout=20)
    assert second.plan_id > first.plan_id
    assert [(s.action, s.args) for s in second.robots["r0"]] == [(s.action, s.args) for s in first.robots["r0"]]

    # a new constraint set: the next plan answers its version and respects it
    client.publish(client.keys.constraints(), unavailable_set(1, *UNAVAILABLE))
    third = wait_for_message(plans, lambda p: p.constraints_version == 1, timeout=30)
    assert third.plan_id > second.plan_id and not third.diagnostic
    assert storage_openings(third), "deliveries still need the door"
    assert all(not (UNAVAILABLE[0] <= t < UNAVAILABLE[1]) for t in storage_openings(third)), storage_openings(third)
    for steps in third.robots.values():
        for s in steps:
            if s.action == "gothrough" and s.args == ["d_storage"]:
                assert not (UNAVAILABLE[0] + 20 <= s.start < UNAVAILABLE[1]), (
                    "nobody goes through a door the human cannot open"
                )

    # late joiners get the current plan from the queryable
    replies = client.query(client.keys.plan(), TeamPlan, timeout=5)
    assert replies and replies[0].plan_id == third.plan_id
    # and a lockstep simulator that missed them, each robot's current command (the plan's front action)
    sent = client.query(client.keys.robot_command("*"), RobotCommand, timeout=5)
    assert sorted(c.robot for c in sent) == sorted(SITE.robots)
    assert all(c.action_id == third.robots[c.robot][0].action_id for c in sent)


def test_unsatisfiable_constraints_give_a_conflict_event_and_the_planner_keeps_going(spawn, router, namespace, client):
    plans = client.collect(client.keys.plan(), TeamPlan)
    events = client.collect(client.keys.event(), Event)
    proc = start_planner(spawn, router, namespace)
    time.sleep(0.5)
    publish_world(client, 1, 0.0)
    before = wait_for_message(plans, lambda p: p.world_version >= 1, timeout=30)

    # r1 starts in the lab: keeping every robot out of the lab from now on cannot be satisfied
    asp = "room_forbidden(lab, 0, 600).\n:- robot_in(R, lab, S, E), S < 600, E > 0.\n"
    bad = ConstraintSet(
        version=5,
        constraints=[Constraint(id="keep_out_lab", kind="forbid_room", params={}, start=0, end=600, asp=asp)],
        asp=asp,
    )
    client.publish(client.keys.constraints(), bad)
    event = wait_for_message(events, lambda e: e.kind == "plan_conflict", timeout=30)
    assert event.data.constraints == ["keep_out_lab"]
    after = wait_for_message(plans, lambda p: p.constraints_version == 5, timeout=30)
    assert "keep_out_lab" in after.diagnostic
    assert {r: [(s.action, s.args) for s in v] for r, v in after.robots.items()} == {
        r: [(s.action, s.args) for s in v] for r, v in before.robots.items()
    }

    # garbage on its inputs does not kill it, and it still answers the next world version
    client.session.put(client.keys.robot_status("r0"), b"\x93\x01\x02")
    client.session.put(client.keys.constraints(), b"not msgpack at all")
    client.publish(client.keys.clock(), Clock(time=1.0, mode="lockstep", world_version=7))
    wait_for_message(plans, lambda p: p.world_version >= 7, timeout=30)
    assert proc.alive()
    stats = client.query(client.keys.stats("planner", "*"), Event, timeout=5)
    assert stats and stats[0].data["bad_messages"] >= 2
    assert proc.stop() == 0, proc.output


def test_a_finished_action_gets_the_next_one_and_a_new_action_id(spawn, router, namespace, client):
    plans, commands, first, cmd = start_and_first_command(spawn, router, namespace, client)
    assert cmd.action == "approach"
    # the robot drives to the end of its trajectory and reports the action done, as the simulator would
    t, x, y, _ = cmd.trajectory[-1]
    finish_front_action(client, cmd, t, 2)
    nxt = wait_for_message(commands, timeout=30)
    assert nxt.action_id > cmd.action_id
    # the new trajectory starts now, where the robot stands (the other robots have not moved, so the
    # plan may change, but the robot never repeats what it has just done)
    assert (
        abs(nxt.trajectory[0][0] - t) < 1.5
        and abs(nxt.trajectory[0][1] - x) < 1e-6
        and abs(nxt.trajectory[0][2] - y) < 1e-6
    )
    assert (nxt.action, nxt.args) != (cmd.action, cmd.args)
    later = wait_for_message(plans, lambda p: p.world_version >= 2, timeout=30)
    front = later.robots["r0"][0]
    assert (front.action, front.args, front.action_id) == (nxt.action, nxt.args, nxt.action_id)
    if nxt.action == "gothrough":
        assert nxt.args == cmd.args, "standing beside X, going through X needs no new approach"
    assert first.world_version < later.world_version


def start_and_first_command(spawn, router: str, namespace: str, client: TestClient):
    """Start the planner, publish the initial world.

    Returns (plans queue, r0's commands queue, first plan, r0's first command)."""
    plans = client.collect(client.keys.plan(), TeamPlan)
    commands = client.collect(client.keys.robot_command("r0"), RobotCommand)
    start_planner(spawn, router, namespace)
    time.sleep(0.5)
    publish_world(client, 1, 0.0)
    first = wait_for_message(plans, lambda p: p.world_version >= 1, timeout=30)
    return plans, commands, first, wait_for_message(commands, timeout=10)


def planner_counters(client: TestClient) -> dict:
    replies = client.query(client.keys.stats("planner", "*"), Event, timeout=5)
    assert replies, "the planner did not answer the stats query"
    return replies[0].data


def finish_front_action(client: TestClient, cmd: RobotCommand, at: float, version: int) -> None:
    """What the simulator publishes when r0 ends ``cmd`` at site time ``at``: pose, status, event, clock."""
    _, x, y, th = cmd.trajectory[-1]
    client.publish(client.keys.robot_pose("r0"), RobotPose(robot="r0", x=x, y=y, theta=th))
    client.publish(
        client.keys.robot_status("r0"),
        RobotStatus(
            robot="r0",
            state="done",
            plan_id=cmd.plan_id,
            action_id=cmd.action_id,
            action=cmd.action,
            args=cmd.args,
            progress=1.0,
            world_version=version,
        ),
    )
    data = {
        "plan_id": cmd.plan_id,
        "action_id": cmd.action_id,
        "action": cmd.action,
        "args": cmd.args,
        "pose": [x, y, th],
    }
    client.publish(client.keys.event(), Event(kind="action_done", robot="r0", data=data))
    client.publish(client.keys.clock(), Clock(time=at, mode="lockstep", world_version=version))


@pytest.mark.parametrize("late", [0.0, -0.5, 30.0], ids=["on-time", "early", "30-s-late"])
def test_an_action_ending_on_time_or_early_keeps_the_plan_and_a_late_one_is_solved_anew(
    spawn, router, namespace, client, late: float
):
    plans, commands, first, cmd = start_and_first_command(spawn, router, namespace, client)
    planned = first.robots["r0"]
    before = planner_counters(client)
    # early: half-way through the action's planned time (robots run ahead of the plan's waits)
    at = planned[0].start + (planned[0].end - planned[0].start) / 2 if late < 0 else planned[0].end + late
    finish_front_action(client, cmd, at, 2)
    later = wait_for_message(plans, lambda p: p.world_version >= 2, timeout=30)
    nxt = wait_for_message(commands, timeout=10)
    after = planner_counters(client)
    continued = after.get("plans_continued", 0) - before.get("plans_continued", 0)
    if late > 0:
        assert continued == 0, "an action 30 s late must be planned anew"
    else:
        assert continued == 1, "an action ending when planned, or before, keeps the plan without solving"
        assert (nxt.action, nxt.args) == (planned[1].action, planned[1].args)
        # the kept plan is the same sequence, moved on by one action, with the same times
        assert [(s.action, s.args, s.start, s.end) for s in later.robots["r0"]] == [
            (s.action, s.args, s.start, s.end) for s in planned[1:]
        ]


def test_off_track_robots_and_door_changes_trigger_replans(spawn, router, namespace, client):
    plans = client.collect(client.keys.plan(), TeamPlan)
    commands = client.collect(client.keys.robot_command("r2"), RobotCommand)
    start_planner(spawn, router, namespace)
    time.sleep(0.5)
    publish_world(client, 1, 0.0)
    wait_for_message(plans, lambda p: p.world_version >= 1, timeout=30)
    cmd = wait_for_message(commands, timeout=10)
    # r2 reports it is executing the command, but stands 3 m away from its trajectory. The clock is
    # in lockstep: that news waits for the next world version (a plan made in between would reach
    # the simulator at a moment that depends on the machine's load).
    x, y, _ = SITE.robots["r2"].start
    client.publish(
        client.keys.robot_status("r2"),
        RobotStatus(
            robot="r2",
            state="moving",
            plan_id=cmd.plan_id,
            action_id=cmd.action_id,
            action=cmd.action,
            args=cmd.args,
            world_version=1,
        ),
    )
    time.sleep(0.3)
    client.publish(client.keys.robot_pose("r2"), RobotPose(robot="r2", x=x - 3.0, y=y, theta=0.0))
    off_track = lambda c: abs(c.trajectory[0][1] - (x - 3.0)) < 1e-6  # noqa: E731
    with pytest.raises(AssertionError, match="no matching message"):
        wait_for_message(commands, off_track, timeout=1.5)
    client.publish(client.keys.clock(), Clock(time=1.0, mode="lockstep", world_version=2))
    again = wait_for_message(commands, off_track, timeout=30)
    assert again.action_id > cmd.action_id and abs(again.trajectory[0][2] - y) < 1e-6

    # r0 waits at the storage door with o0 when the human opens it: the next plan sends r0 through
    # in that opening, which is not counted as one the plan asks for; the plan's opendoor of the
    # door that is open now is skipped (it would be done at once, answered by the same plan, ...)
    client.publish(client.keys.clock(), Clock(time=30.0, mode="lockstep", world_version=3))
    client.publish(client.keys.robot_pose("r0"), RobotPose(robot="r0", x=6.45, y=4.6, theta=-1.5708))
    client.publish(
        client.keys.robot_status("r0"),
        RobotStatus(robot="r0", state="waiting_at_door", waiting_door="d_storage", carrying=["o0"], world_version=3),
    )
    time.sleep(0.5)
    client.publish(
        client.keys.door_state("d_storage"),
        DoorState(door="d_storage", open=True, by="human", until=50.0, world_version=4),
    )
    # the clock comes after everything of its version, as the simulator sends it: in lockstep the
    # planner plans a version only once its clock is in (a part of a version is not the version)
    client.publish(client.keys.clock(), Clock(time=30.0, mode="lockstep", world_version=4))
    after = wait_for_message(plans, lambda p: p.world_version >= 4, timeout=30)
    r0 = after.robots["r0"]
    assert [(s.action, s.args) for s in r0[:2]] == [("gothrough", ["d_storage"]), ("unload", ["o0"])]
    assert r0[0].start < 50 - 1 and r0[0].action_id > 0
    now_open = [o for o in after.openings if o.start == 30.0]
    assert now_open and "r0" in now_open[0].robots
    assert after.door_openings == len(after.openings) - 1


def test_a_command_the_robot_never_got_is_sent_again(spawn, router, namespace, client):
    """Commands published before the simulator subscribed are lost; a replan that keeps the front
    action does not send it anew, so the planner sends it again (same id) while the robot's status
    shows another action."""
    plans = client.collect(client.keys.plan(), TeamPlan)
    commands = client.collect(client.keys.robot_command("r0"), RobotCommand)
    start_planner(spawn, router, namespace)
    time.sleep(0.5)
    publish_world(client, 1, 0.0)
    wait_for_message(plans, lambda p: p.world_version >= 1, timeout=30)
    cmd = wait_for_message(commands, timeout=10)
    while not commands.empty():  # a replan as statuses arrived may have sent a newer one
        cmd, _ = commands.get()
    # the robot still reports no action: the command is sent again, with the same id
    again = None
    deadline = time.monotonic() + 10
    while again is None and time.monotonic() < deadline:
        client.publish(client.keys.robot_status("r0"), RobotStatus(robot="r0", state="idle", world_version=1))
        time.sleep(0.5)
        if not commands.empty():
            again, _ = commands.get()
    assert again is not None, "the lost command was not sent again"
    assert (again.action_id, again.action, again.args, again.trajectory) == (
        cmd.action_id,
        cmd.action,
        cmd.args,
        cmd.trajectory,
    )
    # once the robot reports it, nothing is sent again
    client.publish(
        client.keys.robot_status("r0"),
        RobotStatus(
            robot="r0",
            state="moving",
            plan_id=cmd.plan_id,
            action_id=cmd.action_id,
            action=cmd.action,
            args=cmd.args,
            world_version=1,
        ),
    )
    time.sleep(1.5)
    while not commands.empty():
        extra, _ = commands.get()
        assert extra.action_id != cmd.action_id, "a command the robot reports was sent again"


def test_in_lockstep_the_plan_waits_for_the_feedback_ack_and_answers_the_constraints_it_brought(
    spawn, router, namespace, client
):
    """A paused lockstep simulator says what it waits for. While it waits for the ack of the human's
    feedback, the planner holds (a new ConstraintSet follows): the world version is answered by one
    plan, made with that ConstraintSet, the moment the simulator says it waits for that plan."""
    every_plan = client.collect(client.keys.plan(), TeamPlan)
    start_planner(spawn, router, namespace)
    time.sleep(0.5)
    publish_world(client, 1, 0.0)
    wait_for_message(every_plan, lambda p: p.world_version >= 1, timeout=30)

    # version 2: the simulator has sent a feedback and waits for its ack
    for rid in SITE.robots:
        client.publish(client.keys.robot_status(rid), RobotStatus(robot=rid, state="idle", world_version=2))
    client.publish(
        client.keys.clock(), Clock(time=10.0, mode="lockstep", world_version=2, paused=True, awaiting="feedback")
    )
    time.sleep(0.6)  # SETTLE and more: without the hold, version 2 would have been planned by now
    early = [p for p, _ in iter(lambda: None if every_plan.empty() else every_plan.get(), None)]
    assert not [p for p in early if p.world_version >= 2], "planned while the simulator waited for the feedback's ack"

    # the ack came: the restrictor's new set, then the simulator waits for a plan answering it
    client.publish(client.keys.constraints(), unavailable_set(1, *UNAVAILABLE))
    client.publish(
        client.keys.clock(),
        Clock(time=10.0, mode="lockstep", world_version=2, paused=True, awaiting="plan", constraints_version=1),
    )
    answer = wait_for_message(every_plan, lambda p: p.world_version >= 2, timeout=30)
    assert (answer.world_version, answer.constraints_version) == (2, 1)
    time.sleep(0.5)
    # The same plan published again is no second answer: the planner repeats a plan the simulator
    # stays paused at (in case it was lost), which a loaded machine can make happen in this pause.
    later = [p for p, _ in iter(lambda: None if every_plan.empty() else every_plan.get(), None)]
    assert all(p.plan_id == answer.plan_id for p in later), "one plan answers the version and its constraints"
