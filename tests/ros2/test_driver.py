"""The driver's decisions (services/robot/driver.py) against a unicycle integrated here: it follows
trajectories as the simulator's robots do, holds at closed doors, dwells, and refuses what the
execution contract refuses."""

from __future__ import annotations

import math

import pytest

from protocol.messages import RobotCommand
from protocol.site import load_site
from runtime.pursuit import ControllerConfig, integrate
from services.robot.driver import Driver, DriverConfig

SITE = load_site()
DT = 0.05


def make(robot: str = "r1") -> Driver:
    p = SITE.params
    return Driver(
        robot,
        SITE,
        DriverConfig(
            controller=ControllerConfig(speed=p.robot_speed),
            radius=p.robot_radius,
            load_time=p.load_time,
            control_period=DT,
        ),
    )


def line(start: tuple[float, float, float], end: tuple[float, float]) -> list[list[float]]:
    x, y, th = start
    return [[0.0, x, y, th], [5.0, end[0], end[1], th]]


def run(
    driver: Driver,
    pose: tuple[float, float, float],
    seconds: float,
    t0: float = 0.0,
    doors: dict[str, bool] | None = None,
):
    """Drive the unicycle by the driver's answers; returns the final pose, time and the largest speed."""
    x, y, th = pose
    top = 0.0
    t = t0
    for _ in range(int(seconds / DT)):
        v, w = driver.control((x, y, th), t, lambda d: (doors or {}).get(d, False))
        top = max(top, abs(v))
        x, y, th = integrate(x, y, th, v, w, DT)
        t += DT
    return (x, y, th), t, top


def test_follows_a_trajectory_to_its_end():
    d = make()
    start = SITE.robots["r1"].start  # (12.5, 8.0) facing -y, in the lab
    cmd = RobotCommand(
        robot="r1", plan_id=1, action_id=1, action="approach", args=["d_lab"], trajectory=line(start, (12.5, 7.0))
    )
    assert d.assign(cmd, start, 0.0) == "accepted" and d.s.state == "moving"
    (x, y, _), _, top = run(d, start, 6.0)
    assert math.dist((x, y), (12.5, 7.0)) <= 0.02 and top <= SITE.params.robot_speed + 1e-9
    assert d.s.state == "done" and d.s.action_id == 1
    assert d.assign(cmd, (x, y, 0.0), 6.0) == "stale"


def test_holds_short_of_a_closed_door_then_goes_through():
    d = make()
    start = SITE.robots["r1"].start
    cmd = RobotCommand(
        robot="r1", plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=line(start, (12.5, 5.0))
    )
    assert d.assign(cmd, start, 0.0) == "accepted"
    pose, t, _ = run(d, start, 8.0)
    assert d.s.state == "waiting_at_door" and d.s.waiting_door == "d_lab"
    assert pose[1] - 6.0 >= SITE.params.robot_radius + 0.15 - 0.01
    pose, _, _ = run(d, pose, 8.0, t, {"d_lab": True})
    assert d.s.state == "done" and pose[1] < 5.1


def test_load_dwells_then_carries():
    d = make("r0")
    obj = next(o for o in SITE.objects.values() if o.robot == "r0")
    cmd = RobotCommand(robot="r0", plan_id=1, action_id=1, action="load", args=[obj.id], trajectory=[], duration=2.0)
    near = (obj.position[0] + 0.3, obj.position[1], 0.0)
    assert d.assign(cmd, near, 0.0) == "accepted"
    run(d, near, 1.0)
    assert d.s.state == "loading" and d.s.carrying == []
    run(d, near, 1.2, 1.0)
    assert d.s.state == "done" and d.s.carrying == [obj.id]


def test_refusals():
    d = make("r0")
    start = SITE.robots["r0"].start
    others = next(o for o in SITE.objects.values() if o.robot != "r0")
    assert (
        d.assign(RobotCommand(robot="r0", plan_id=1, action_id=1, action="load", args=[others.id]), start, 0.0)
        == "refused"
    )
    assert "belongs to robot" in d.s.detail and d.s.state == "failed"
    assert (
        d.assign(RobotCommand(robot="r0", plan_id=1, action_id=2, action="unload", args=["o0"]), start, 0.0)
        == "refused"
    )
    assert (
        d.assign(
            RobotCommand(
                robot="r0",
                plan_id=1,
                action_id=3,
                action="approach",
                args=["d_lab"],
                trajectory=line(start, (3.0, 5.0)),
            ),
            None,
            0.0,
        )
        == "refused"
    )
    assert d.s.detail == "no pose of the robot yet"
    far = [[0.0, 5.0, 5.0, 0.0], [1.0, 6.0, 5.0, 0.0]]
    assert (
        d.assign(
            RobotCommand(robot="r0", plan_id=1, action_id=4, action="approach", args=["d_lab"], trajectory=far),
            start,
            0.0,
        )
        == "refused"
    )
    assert "trajectory starts" in d.s.detail
    mine = next(o for o in SITE.objects.values() if o.robot == "r0")
    assert (
        d.assign(
            RobotCommand(robot="r0", plan_id=1, action_id=5, action="load", args=[mine.id], trajectory=[]), start, 0.0
        )
        == "accepted"
    )
    run(d, start, 0.2)
    assert d.s.state == "failed" and "m away" in d.s.detail  # arrived out of reach of the object
    assert d.control(start, 1.0, lambda door: True) == (0.0, 0.0)


def test_keeps_a_hold_in_its_trajectory():
    """Two rows at one point mean "wait here until the second row's time" (the planner making it give
    way to another robot): the driver stands still until then, still "moving", then goes on."""
    d = make()
    x, y, th = SITE.robots["r1"].start
    rows = [[0.0, x, y, th], [1.0, x, y - 0.5, th], [6.0, x, y - 0.5, th], [7.0, x, y - 1.0, th]]
    cmd = RobotCommand(robot="r1", plan_id=1, action_id=1, action="approach", args=["d_lab"], trajectory=rows)
    assert d.assign(cmd, (x, y, th), 0.0) == "accepted"
    pose, t, _ = run(d, (x, y, th), 4.0)
    assert d.s.state == "moving" and pose[1] == pytest.approx(y - 0.5, abs=0.03)  # held at the hold's point
    pose, _, _ = run(d, pose, 4.0, t)
    assert d.s.state == "done" and math.dist(pose[:2], (x, y - 1.0)) <= 0.02


def test_waits_again_for_a_door_it_is_back_in_front_of():
    """Its progress along the path had passed the door line, but the robot is in front of it again
    (pushed back, or it backed away): a closed door there holds it, as if never reached."""
    d = make()
    start = SITE.robots["r1"].start
    cmd = RobotCommand(
        robot="r1", plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=line(start, (12.5, 5.0))
    )
    assert d.assign(cmd, start, 0.0) == "accepted"
    pose, t, _ = run(d, start, 4.5, doors={"d_lab": True})
    assert pose[1] < 5.95  # through the door line (y = 6)
    back = (pose[0], 6.8, pose[2])
    pose, t, _ = run(d, back, 4.0, t)  # the door is shut now
    assert d.s.state == "waiting_at_door" and d.s.waiting_door == "d_lab"
    assert pose[1] - 6.0 >= SITE.params.robot_radius + 0.15 - 0.01
