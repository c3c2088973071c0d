"""``arroch robot --ros2`` brings the base to zero velocity within 0.5 s of site time when its pose
goes stale, the planner is SIGKILLed, its command is refused, or it gets SIGTERM. The driver is a
real process; the base and the site clock are :class:`tests.ros2.harness.FakeBase` in the test
(site time = wall time there), the planner a real process holding the planner's liveliness token.
And at a closed door it holds short of the leaf, going on once the door opens."""

from __future__ import annotations

import signal
import sys
import textwrap
import time

import pytest

from protocol.messages import DoorState, RobotCommand, RobotStatus
from protocol.site import load_site
from runtime.ros2.config import Ros2Config
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.ros2.harness import FakeBase, straight_command

SITE = load_site()
ROBOT = "r0"
START = SITE.robots[ROBOT].start
LIMIT = 0.5  # s of site time from the event to the first zero Twist


@pytest.fixture
def base(client):
    b = FakeBase(client, ROBOT, START, Ros2Config())
    yield b
    b.close()


_DRIVERS: list = []


def driver_output() -> str:
    return "\n".join(p.output[-3000:] for p in _DRIVERS)


def start_driver(spawn, router: str, namespace: str, *extra: str, robot: str = ROBOT):
    _DRIVERS.clear()
    proc = spawn(
        arroch("robot", "--ros2", "--robot", robot, "--connect", router, "--namespace", namespace, *extra), name="robot"
    )
    proc.wait_for(f"robot robot-{robot}-", timeout=20)
    _DRIVERS.append(proc)
    return proc


def drive(client, base: FakeBase) -> float:
    """Send a long straight command; wait until the base moves. Returns that site time."""
    statuses = client.collect(client.keys.robot_status(ROBOT), RobotStatus)
    wait_for_message(statuses, lambda s: True, timeout=10)
    base.first_zero_after(0.0, timeout=10)  # the driver answers poses: it knows where the robot is
    client.publish(client.keys.robot_command(ROBOT), straight_command(ROBOT, START, 8.0))
    try:
        moving = base.wait_moving()
    except AssertionError as exc:
        raise AssertionError(f"{exc}\n{driver_output()}") from None
    assert base.map_pose()[0] >= START[0] - 0.01
    return moving


def assert_stops_in_time(base: FakeBase, trigger, what: str):  # noqa: ANN001
    """Pull ``trigger()`` while the base drives; the first zero Twist must follow within LIMIT site seconds."""
    t = base.now()
    trigger()
    stop = base.first_zero_after(t)
    assert stop.site_time - t <= LIMIT, f"zero Twist {stop.site_time - t:.3f} s after {what}"
    return stop


def test_stale_pose_stops_the_base(spawn, router, namespace, client, base):
    start_driver(spawn, router, namespace)
    drive(client, base)
    assert_stops_in_time(base, lambda: setattr(base, "odometry_on", False), "the last pose")


def test_killed_planner_stops_the_base(spawn, router, namespace, client, base):
    planner = spawn(
        [
            sys.executable,
            "-c",
            textwrap.dedent(f"""
        import time
        from runtime.service import Service
        from runtime.transport import ZenohOptions
        with Service("planner", "{namespace}", ZenohOptions(mode="client", connect=["{router}"])):
            print("planner token declared", flush=True)
            time.sleep(600)
    """),
        ],
        name="planner",
    )
    planner.wait_for("planner token declared", timeout=20)
    driver = start_driver(spawn, router, namespace)
    drive(client, base)
    assert_stops_in_time(base, lambda: planner.signal(signal.SIGKILL), "the planner died")
    driver.wait_for("planner lost", timeout=5)


def test_refused_command_stops_the_base(spawn, router, namespace, client, base):
    start_driver(spawn, router, namespace)
    statuses = client.collect(client.keys.robot_status(ROBOT), RobotStatus)
    drive(client, base)
    # A trajectory starting 3 m behind the robot: refused (the execution contract's 1.5 m).
    refused = straight_command(ROBOT, START, 8.0, action_id=2, offset=3.0)
    stop = assert_stops_in_time(
        base, lambda: client.publish(client.keys.robot_command(ROBOT), refused), "the refused command"
    )
    failed = wait_for_message(statuses, lambda s: s.action_id == 2 and s.state == "failed", timeout=5)
    assert "trajectory starts" in failed.detail
    assert all(tw.zero for tw in base.twists if tw.site_time > stop.site_time)


def test_sigterm_stops_the_base(spawn, router, namespace, client, base):
    driver = start_driver(spawn, router, namespace)
    drive(client, base)
    assert_stops_in_time(base, lambda: driver.signal(signal.SIGTERM), "SIGTERM")
    assert driver.wait(10) == 0
    assert base.twists[-1].zero


def test_closed_door_holds_the_robot_short_of_the_leaf(spawn, router, namespace, client):
    robot = "r1"  # in the lab, facing d_lab (on the wall y = 6) from 2 m
    start = SITE.robots[robot].start
    line = SITE.doors["d_lab"].center[1]
    radius = SITE.params.robot_radius
    base = FakeBase(client, robot, start, Ros2Config())
    try:
        statuses = client.collect(client.keys.robot_status(robot), RobotStatus)
        start_driver(spawn, router, namespace, robot=robot)
        base.first_zero_after(0.0, timeout=10)
        client.publish(client.keys.door_state("d_lab"), DoorState(door="d_lab", open=False))
        rows = straight_command(robot, start, 3.0).trajectory
        client.publish(
            client.keys.robot_command(robot),
            RobotCommand(robot=robot, plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=rows),
        )
        wait_for_message(statuses, lambda st: st.state == "waiting_at_door" and st.waiting_door == "d_lab", timeout=15)
        base.first_zero_after(base.now())
        time.sleep(0.3)
        gap = base.map_pose()[1] - line  # robot centre to the door's line
        assert radius < gap <= radius + 0.15 + 0.03, f"held {gap:.3f} m from the door's line"
        client.publish(client.keys.door_state("d_lab"), DoorState(door="d_lab", open=True))
        deadline = time.monotonic() + 10
        while base.map_pose()[1] > line - radius - 0.1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert base.map_pose()[1] < line - radius - 0.1, "the robot did not go through once the door opened"
    finally:
        base.close()


def test_bad_odometry_is_dropped_and_counted(spawn, router, namespace, client, base):
    from protocol.messages import Event
    from runtime.ros2 import types as ros
    from runtime.ros2.keys import TopicNaming

    driver = start_driver(spawn, router, namespace)
    base.first_zero_after(0.0, timeout=10)
    key = TopicNaming().data_key("/r0/odom", ros.ODOMETRY)
    client.session.put(key, b"\x00\x01\x00\x00not an odometry")
    nan = ros.odometry(base.now(), "odom", "base_link", float("nan"), 0.0, 0.0, 0.0, 0.0)
    client.session.put(key, ros.serialize(nan, ros.ODOMETRY))
    time.sleep(0.5)
    (stats,) = [e.data for e in client.query(client.keys.stats("robot"), Event)]
    assert stats["bad_messages"] >= 1 and stats["poses_not_finite"] >= 1, stats
    assert driver.alive()
    drive(client, base)  # and it still drives


def test_bad_traffic_is_dropped_and_counted(spawn, router, namespace, client, base):
    """Another robot's RobotTraffic that cannot be read, names a robot the site does not have, or
    comes on another robot's key: dropped and counted, and the driver still drives."""
    from protocol.messages import Event, RobotTraffic

    driver = start_driver(spawn, router, namespace)
    base.first_zero_after(0.0, timeout=10)
    keys = client.keys
    client.session.put(keys.robot_traffic("r1"), b"\x00not a traffic message")
    client.publish(keys.robot_traffic("r1"), RobotTraffic(robot="r1", blocked_by="r9"))
    client.publish(keys.robot_traffic("r2"), RobotTraffic(robot="r1"))
    time.sleep(0.5)
    (stats,) = [e.data for e in client.query(keys.stats("robot"), Event)]
    assert stats["bad_messages"] >= 1 and stats["traffic_refused"] == 2, stats
    assert "(counted as traffic_refused)" in driver.output
    assert driver.alive()
    drive(client, base)
