"""A real robot's driver (services/robot/driver.py: the shared executor behind the real-robot
adapter) against unicycles integrated here, on a clock the test advances: it follows trajectories
as the simulator's robots do, holds at closed doors, dwells, refuses what the execution contract
refuses; and among other robots it only hears of (their RobotPose, RobotStatus and RobotTraffic
messages, handed over in memory a control period late) it stops short, drives around, asks to make
way, and two drivers meeting head-on in a corridor pass without touching."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from protocol.messages import DoorState, RobotCommand, RobotPose, RobotStatus
from protocol.site import load_site
from runtime.executor import RobotConfig
from runtime.pursuit import ControllerConfig, integrate
from services.robot.driver import Driver, DriverConfig

SITE = load_site()
DT = 0.05
RADIUS = SITE.params.robot_radius
MARGIN = RobotConfig().robot_margin  # what robots keep between their discs when one stops for another
Pose = tuple[float, float, float]


def make(robot: str = "r1") -> Driver:
    p = SITE.params
    executor = RobotConfig(controller=ControllerConfig(speed=p.robot_speed), radius=RADIUS, load_time=p.load_time)
    return Driver(robot, SITE, DriverConfig.for_robot(executor, DT))


def line(start: tuple[float, float, float], end: tuple[float, float]) -> list[list[float]]:
    x, y, th = start
    return [[0.0, x, y, th], [5.0, end[0], end[1], th]]


def run(
    driver: Driver,
    pose: Pose,
    seconds: float,
    t0: float = 0.0,
    doors: dict[str, bool] | None = None,
):
    """Drive the unicycle by the driver's steps; returns the final pose, time and the largest speed."""
    x, y, th = pose
    top = 0.0
    t = t0
    for door, is_open in (doors or {}).items():
        driver.doors.heard(DoorState(door=door, open=is_open))
    for _ in range(int(seconds / DT)):
        step, _ = driver.control((x, y, th), t, t)
        top = max(top, abs(step.v))
        x, y, th = integrate(x, y, th, step.v, step.omega, DT)
        t += DT
    return (x, y, th), t, top


def test_follows_a_trajectory_to_its_end():
    d = make()
    start = SITE.robots["r1"].start  # (12.5, 8.0) facing -y, in the lab
    cmd = RobotCommand(
        robot="r1", plan_id=1, action_id=1, action="approach", args=["d_lab"], trajectory=line(start, (12.5, 7.0))
    )
    assert d.assign(cmd, start, 0.0) == "accepted" and d.robot.state == "moving"
    (x, y, _), _, top = run(d, start, 6.0)
    assert math.dist((x, y), (12.5, 7.0)) <= 0.02 and top <= SITE.params.robot_speed + 1e-9
    status = d.status(0)
    assert status.state == "done" and status.action_id == 1 and not d.changed
    assert d.assign(cmd, (x, y, 0.0), 6.0) == "stale"


def test_holds_short_of_a_closed_door_then_goes_through():
    d = make()
    start = SITE.robots["r1"].start
    cmd = RobotCommand(
        robot="r1", plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=line(start, (12.5, 5.0))
    )
    assert d.assign(cmd, start, 0.0) == "accepted"
    pose, t, _ = run(d, start, 8.0)
    assert d.robot.state == "waiting_at_door" and d.robot.waiting_door == "d_lab"
    assert pose[1] - 6.0 >= RADIUS + 0.15 - 0.01
    pose, _, _ = run(d, pose, 8.0, t, {"d_lab": True})
    assert d.robot.state == "done" and pose[1] < 5.1


def test_load_dwells_then_carries():
    d = make("r0")
    obj = next(o for o in SITE.objects.values() if o.robot == "r0")
    cmd = RobotCommand(robot="r0", plan_id=1, action_id=1, action="load", args=[obj.id], trajectory=[], duration=2.0)
    near = (obj.position[0] + 0.3, obj.position[1], 0.0)
    assert d.assign(cmd, near, 0.0) == "accepted"
    run(d, near, 1.0)
    assert d.robot.state == "loading" and d.robot.carrying == []
    run(d, near, 1.2, 1.0)
    assert d.robot.state == "done" and d.robot.carrying == [obj.id]


def test_refusals():
    d = make("r0")
    start = SITE.robots["r0"].start
    others = next(o for o in SITE.objects.values() if o.robot != "r0")
    assert (
        d.assign(RobotCommand(robot="r0", plan_id=1, action_id=1, action="load", args=[others.id]), start, 0.0)
        == "refused"
    )
    assert "belongs to robot" in d.robot.detail and d.robot.state == "failed"
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
    assert d.robot.detail == "no pose of the robot yet" and d.status(0).action_id == 3
    far = [[0.0, 5.0, 5.0, 0.0], [1.0, 6.0, 5.0, 0.0]]
    assert (
        d.assign(
            RobotCommand(robot="r0", plan_id=1, action_id=4, action="approach", args=["d_lab"], trajectory=far),
            start,
            0.0,
        )
        == "refused"
    )
    assert "trajectory starts" in d.robot.detail
    mine = next(o for o in SITE.objects.values() if o.robot == "r0")
    assert (
        d.assign(
            RobotCommand(robot="r0", plan_id=1, action_id=5, action="load", args=[mine.id], trajectory=[]), start, 0.0
        )
        == "accepted"
    )
    run(d, start, 0.2)
    assert d.robot.state == "failed" and "m away" in d.robot.detail  # arrived out of reach of the object
    step, _ = d.control(start, 1.0, 1.0)
    assert (step.v, step.omega) == (0.0, 0.0)


def test_keeps_a_hold_in_its_trajectory():
    """Two rows at one point mean "wait here until the second row's time" (the planner making it give
    way to another robot): the driver stands still until then, still "moving", then goes on."""
    d = make()
    x, y, th = SITE.robots["r1"].start
    rows = [[0.0, x, y, th], [1.0, x, y - 0.5, th], [6.0, x, y - 0.5, th], [7.0, x, y - 1.0, th]]
    cmd = RobotCommand(robot="r1", plan_id=1, action_id=1, action="approach", args=["d_lab"], trajectory=rows)
    assert d.assign(cmd, (x, y, th), 0.0) == "accepted"
    pose, t, _ = run(d, (x, y, th), 4.0)
    assert d.robot.state == "moving" and pose[1] == pytest.approx(y - 0.5, abs=0.03)  # held at the hold's point
    pose, _, _ = run(d, pose, 4.0, t)
    assert d.robot.state == "done" and math.dist(pose[:2], (x, y - 1.0)) <= 0.02


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
    pose, t, _ = run(d, back, 4.0, t, doors={"d_lab": False})
    assert d.robot.state == "waiting_at_door" and d.robot.waiting_door == "d_lab"
    assert pose[1] - 6.0 >= RADIUS + 0.15 - 0.01


# ---------------------------------------------------------------------- among other robots


class Fleet:
    """Robots driven by their own drivers, and robots that stand where they are, stepped together on
    one clock; what each robot says (its pose, status and traffic) reaches the others' drivers one
    control period later, as over Zenoh."""

    def __init__(self, poses: dict[str, Pose], driven: list[str]) -> None:
        self.poses = dict(poses)
        self.drivers = {rid: make(rid) for rid in driven}
        self.t = 0.0
        self.closest = math.inf
        self.asks: list[tuple[str, str]] = []  # (asker, asked) of every request to make way sent
        self.silent: set[str] = set()  # robots whose messages no longer come (their process died)
        self._mail: list[tuple[str, object]] = []  # (to, message) for the next period
        self._post()

    def command(self, rid: str, end: tuple[float, float], action: str = "approach") -> None:
        x, y, th = self.poses[rid]
        rows = [[0.0, x, y, th], [30.0, end[0], end[1], th]]
        cmd = RobotCommand(robot=rid, plan_id=1, action_id=1, action=action, args=["d_lab"], trajectory=rows)
        assert self.drivers[rid].assign(cmd, self.poses[rid], self.t) == "accepted"

    def _post(self) -> None:
        """What every robot says now, for the others' drivers at the next period."""
        for rid, (x, y, th) in self.poses.items():
            if rid in self.silent:
                continue
            driver = self.drivers.get(rid)
            v, omega = (driver.robot.v, driver.robot.omega) if driver is not None else (0.0, 0.0)
            says: list[object] = [RobotPose(robot=rid, x=x, y=y, theta=th, vel=v, omega=omega, stamp=self.t)]
            if driver is None:
                says.append(RobotStatus(robot=rid, state="done"))  # parked: its action is over
            else:
                says.append(driver.status(1))
                traffic = driver.traffic(force=True)
                self.asks.extend((rid, a.asked) for a in traffic.asks)
                says.append(traffic)
            self._mail.extend((to, msg) for to in self.drivers if to != rid for msg in says)

    def step(self) -> None:
        mail, self._mail = self._mail, []
        for to, msg in mail:
            if to not in self.drivers:
                continue  # its driver is gone
            peers = self.drivers[to].peers
            take: Callable = {RobotPose: peers.pose, RobotStatus: peers.status}.get(type(msg), peers.traffic)
            assert take(msg, self.t) == ""
        steps = {rid: d.control(self.poses[rid], self.t, self.t)[0] for rid, d in self.drivers.items()}
        for rid, step in steps.items():
            self.poses[rid] = integrate(*self.poses[rid], step.v, step.omega, DT)
        self.t += DT
        ids = sorted(self.poses)
        for i, a in enumerate(ids):
            for b in ids[i + 1 :]:
                self.closest = min(self.closest, math.dist(self.poses[a][:2], self.poses[b][:2]))
        self._post()

    def run_until(self, done: Callable[[], bool], seconds: float) -> None:
        for _ in range(int(seconds / DT)):
            self.step()
            if done():
                return


def test_a_robot_standing_in_the_way_is_stopped_for_then_driven_around():
    """r1 stands in the corridor on r0's way; r0 hears of it only through its messages. r0 stops
    short, a robot's width and the margin from it, then drives around it and arrives."""
    fleet = Fleet({"r0": (1.5, 5.0, 0.0), "r1": (4.5, 5.0, math.pi)}, driven=["r0"])
    fleet.command("r0", (8.0, 5.0))
    r0 = fleet.drivers["r0"]
    stop = None
    while fleet.t < 20.0 and r0.robot.phase == "drive":
        fleet.step()
        if stop is None and fleet.t > 1.0 and r0.robot.v == 0.0:
            stop = fleet.poses["r0"]
    assert stop is not None and math.dist(stop[:2], (4.5, 5.0)) >= 2 * RADIUS + MARGIN
    assert r0.robot.state == "done", r0.robot.detail
    assert math.dist(fleet.poses["r0"][:2], (8.0, 5.0)) <= 0.05
    # solid bodies: no step brings the discs nearer than the contact gap (the way around keeps more)
    assert fleet.closest >= 2 * RADIUS + r0.executor.avoidance.contact_gap
    assert fleet.asks == []  # there was room: nobody was asked to make way


def test_a_robot_with_no_way_around_is_asked_to_make_way_and_does():
    """In a doorway's lane there is no way around: r0, told through d_lab, finds r1 (driven by its own
    driver, parked in the lane on the corridor side) in its way, asks it to make way over the wire,
    and r1 steps aside; r0 goes through, nobody touches."""
    fleet = Fleet({"r0": (12.5, 8.0, -math.pi / 2), "r1": (12.5, 5.3, math.pi / 2)}, driven=["r0", "r1"])
    fleet.drivers["r0"].doors.heard(DoorState(door="d_lab", open=True))
    fleet.drivers["r1"].doors.heard(DoorState(door="d_lab", open=True))
    fleet.command("r0", (12.5, 4.6), action="gothrough")
    r0 = fleet.drivers["r0"]
    fleet.run_until(lambda: r0.robot.phase != "drive", 40.0)
    assert r0.robot.state == "done", r0.robot.detail
    assert ("r0", "r1") in fleet.asks
    assert fleet.closest >= 2 * RADIUS


def test_two_drivers_meeting_head_on_in_a_corridor_pass_without_touching():
    """r0 and r1 are sent along one line of the corridor toward each other. Each hears of the other
    only through its messages a period late; the right of way, driving around and making way work
    across the two drivers, and both arrive without their discs ever touching."""
    fleet = Fleet({"r0": (3.0, 5.0, 0.0), "r1": (9.0, 5.0, math.pi)}, driven=["r0", "r1"])
    fleet.command("r0", (10.0, 5.0))
    fleet.command("r1", (2.0, 5.0))
    drivers = fleet.drivers.values()
    fleet.run_until(lambda: all(d.robot.phase != "drive" for d in drivers), 60.0)
    assert [d.robot.state for d in drivers] == ["done", "done"], [d.robot.detail for d in drivers]
    assert fleet.closest >= 2 * RADIUS, f"discs {2 * RADIUS - fleet.closest:.3f} m into each other"
    assert (
        math.dist(fleet.poses["r0"][:2], (10.0, 5.0)) <= 0.05 and math.dist(fleet.poses["r1"][:2], (2.0, 5.0)) <= 0.05
    )


def test_a_robot_not_heard_of_is_a_parked_obstacle():
    """r1's driver falls silent while r1 drives: after the timeout r0 treats it as parked (no traffic
    rows of it left), still never touches it, and drives around it."""
    fleet = Fleet({"r0": (1.5, 5.0, 0.0), "r1": (4.5, 5.0, 0.0)}, driven=["r0", "r1"])
    r0, r1 = fleet.drivers["r0"], fleet.drivers["r1"]
    fleet.command("r1", (5.0, 5.0))
    fleet.run_until(lambda: r1.robot.phase != "drive", 5.0)
    del fleet.drivers["r1"]  # its process dies: nothing from it any more, it stands where it is
    fleet.silent.add("r1")
    fleet.command("r0", (8.0, 5.0))
    fleet.run_until(lambda: r0.peers.peers["r1"].stale, 10.0)
    assert r0.went_stale == ["r1"] or r0.peers.peers["r1"].stale
    assert r0.peers.peers["r1"].robot.phase == "idle" and "r1" not in r0.executor.right_of_way.blocked_by
    fleet.run_until(lambda: r0.robot.phase != "drive", 30.0)
    assert r0.robot.state == "done", r0.robot.detail
    assert fleet.closest >= 2 * RADIUS + r0.executor.avoidance.contact_gap
