"""``arroch sim --robots none`` with a real robot (a driver and a stand-in ROS 2 base) in real time:
the simulator keeps the world but not the robot. It opens an automatic door for the robot's
command, learns where the robot is from the driver's RobotPose (and publishes none itself), and turns
the driver's statuses into the mission's events with a new world version; no closed-door crossing."""

from __future__ import annotations

from protocol.messages import Event, RobotCommand, RobotPose
from protocol.site import load_site
from runtime.ros2.config import Ros2Config
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.ros2.harness import FakeBase, straight_command

SITE = load_site()


def test_a_real_robot_goes_through_an_automatic_door(spawn, router, namespace, client):
    robot = "r1"  # in the lab, 2 m in front of d_lab (automatic)
    start = SITE.robots[robot].start
    events = client.collect(client.keys.event(), Event)
    poses = client.collect(client.keys.robot_pose(robot), RobotPose)
    sim = spawn(arroch("sim", "--connect", router, "--namespace", namespace, "--robots", "none"), name="sim")
    sim.wait_for("sim sim-", timeout=20)
    base = FakeBase(client, robot, start, Ros2Config(), publish_clock=False)
    try:
        spawn(
            arroch("robot", "--ros2", "--robot", robot, "--connect", router, "--namespace", namespace), name="robot"
        ).wait_for("robot robot-r1-", timeout=20)
        base.first_zero_after(0.0, timeout=10)
        rows = straight_command(robot, start, 3.0).trajectory
        client.publish(
            client.keys.robot_command(robot),
            RobotCommand(robot=robot, plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=rows),
        )
        opened = wait_for_message(events, lambda e: e.kind == "door_opened" and e.door == "d_lab", timeout=15)
        assert opened.data.by == robot
        done = wait_for_message(
            events,
            lambda e: e.kind in ("action_done", "action_failed", "closed_door_crossing") and e.robot == robot,
            timeout=20,
        )
        assert done.kind == "action_done" and done.data.action_id == 1 and done.data.world_version >= 2, done
        assert done.data.pose[1] < SITE.doors["d_lab"].center[1] - SITE.params.robot_radius
        seen = []
        while not poses.empty():
            seen.append(poses.get_nowait()[0])
        assert seen and all(p.src.startswith("robot-r1-") for p in seen)  # the driver's, never the simulator's
    finally:
        base.close()
