"""The simulator's side of robots it does not drive (services/sim/ros2_base.py), without Zenoh:
their statuses become the mission's events and world versions, their poses move them in the world."""

from __future__ import annotations

import math

import msgspec

from protocol.messages import RobotCommand, RobotPose, RobotStatus
from protocol.site import load_site
from services.sim.engine import Engine
from services.sim.ros2_base import CMD_VEL_TIMEOUT, ExternalRobots, RosBase

SITE = load_site()


def status(action_id: int, action: str, state: str, **kw) -> RobotStatus:
    return RobotStatus(
        robot="r0", state=state, plan_id=1, action_id=action_id, action=action, args=kw.pop("args", []), **kw
    )


def kinds(engine: Engine) -> list[tuple[str, str, bool]]:
    return [(e.kind, e.object or e.door, "world_version" in msgspec.to_builtins(e.data)) for e in engine.take_events()]


def test_statuses_become_events_and_world_versions():
    engine = Engine(SITE, method="arroch", seed=0)
    ExternalRobots(engine, ["r0"], ros2=None, lockstep=True)
    engine.start()
    engine.take_events()
    version = engine.world_version
    cmd = RobotCommand(
        robot="r0",
        plan_id=1,
        action_id=1,
        action="load",
        args=["o0"],
        trajectory=[[0, 1.5, 5.0, 0.0], [1, 2.0, 5.0, 0.0]],
    )
    assert engine.apply_command(cmd) == "external"
    ext = engine.external["r0"]
    ext.on_pose(RobotPose(robot="r0", x=2.0, y=5.0, theta=0.1, vel=0.5, omega=0.0))
    ext.on_status(status(1, "load", "loading", args=["o0"]))
    engine.step()
    r0 = engine.robots["r0"]
    assert (r0.x, r0.y, r0.theta, r0.state) == (2.0, 5.0, 0.1, "loading") and r0.last_action_id == 1
    assert kinds(engine) == [] and engine.world_version == version
    ext.on_status(status(1, "load", "done", args=["o0"], carrying=["o0"]))
    ext.on_status(status(1, "load", "done", args=["o0"], carrying=["o0"]))  # a heartbeat repeats it: reported once
    engine.step()
    assert kinds(engine) == [("loaded", "o0", False), ("action_done", "", True)]
    assert engine.world_version == version + 1 and engine.objects["o0"].carrier == "r0"
    ext.on_status(status(2, "unload", "done", args=["o0"], delivered=["o0"]))
    ext.on_status(status(3, "stop", "idle"))
    engine.step()
    assert kinds(engine) == [("delivered", "o0", False), ("action_done", "", True), ("action_done", "", False)]
    assert engine.objects["o0"].delivered and engine.world_version == version + 2
    ext.on_status(status(4, "opendoor", "waiting_at_door", args=["d_storage"], waiting_door="d_storage"))
    engine.step()
    assert kinds(engine) == [("waiting_at_door", "d_storage", False)] and r0.wait_time > 0


def test_a_ros2_base_integrates_twists_and_stops_without_them():
    engine = Engine(SITE, method="arroch", seed=0)
    ExternalRobots(engine, ["r0"], ros2=None, lockstep=False)
    ext = engine.external["r0"]
    ext.base = RosBase(odom=None, origin=SITE.robots["r0"].start, odom_frame="odom", base_frame="base_link")  # type: ignore[arg-type]
    engine.start()

    class Twist:
        class linear:
            x = 0.5

        class angular:
            z = 0.0

    ext.on_twist(Twist, engine.time)
    x0 = engine.robots["r0"].x
    for _ in range(int(CMD_VEL_TIMEOUT / engine.config.tick) + 5):
        engine.step()
    moved = engine.robots["r0"].x - x0
    assert math.isclose(
        moved, 0.5 * CMD_VEL_TIMEOUT, abs_tol=0.5 * engine.config.tick + 1e-9
    )  # then the watchdog stopped it
    assert engine.robots["r0"].v == 0.0


def test_lockstep_waits_for_a_moving_robots_driver_but_not_for_ever():
    import time

    class Sink:
        def __init__(self) -> None:
            self.sent = 0

        def publish(self, msg) -> None:  # noqa: ANN001
            self.sent += 1

    engine = Engine(SITE, method="arroch", seed=0)
    robots = ExternalRobots(engine, ["r0"], ros2=None, lockstep=True)
    ext = engine.external["r0"]
    sink = Sink()
    ext.base = RosBase(odom=sink, origin=SITE.robots["r0"].start, odom_frame="odom", base_frame="base_link")  # type: ignore[arg-type]
    engine.start()
    robots.after_tick()
    assert sink.sent == 1 and robots.blocker() == ""  # idle: not waited for
    ext.on_status(status(1, "approach", "moving", args=["d_lab"]))
    robots.after_tick()
    assert "cmd_vel of r0" in robots.blocker()
    ext.base.awaiting_since = time.monotonic() - 3.0  # its driver died
    assert robots.blocker() == "" and ext.base.silent
    robots.after_tick()
    assert robots.blocker() == ""  # not waited for while silent

    class Twist:
        class linear:
            x = 0.0

        class angular:
            z = 0.0

    ext.on_twist(Twist, engine.time)  # back: waited for again
    robots.after_tick()
    assert "cmd_vel of r0" in robots.blocker()
