"""Two real-robot drivers keep their robots apart as the simulator keeps its own: ``arroch sim
--ros2-bases`` plays two ROS 2 mobile bases (Twist in, Odometry out), each driven by its own
``arroch robot --ros2`` process, and the test sends them head-on through one doorway of a small
site: r0 from the corridor into the office, r1 from the office out to the corridor.

Only the drivers decide how the bases move, from what they hear of each other over Zenoh (the
other's RobotPose, RobotStatus and RobotTraffic): one holds the doorway while the other waits, and
the second, meeting the first parked on its way beyond the door, drives around it or has it make
way. Both arrive, and the bases' own odometry (the ROS 2 topics, read here as any ROS 2 node would)
says their discs never touched."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from protocol.messages import Event, RobotCommand, RobotStatus, RobotTraffic
from protocol.site import loads_site
from runtime.ros2.config import load_ros2_config
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.ros2.harness import OdometryWatch
from tests.sim.helpers import SMALL_SITE

pytestmark = pytest.mark.integration

# The simulator tests' small site, r1 moved into the office: the two robots face each other through
# the office's automatic door, d_office (on the corridor's wall y = 6, at x = 3).
R1_START = "start = [10.0, 5.0, 3.14159]"
assert R1_START in SMALL_SITE
SITE_TOML = SMALL_SITE.replace(R1_START, "start = [3.0, 9.0, -1.5708]")
SITE = loads_site(SITE_TOML, "headon.toml")
ROS2_TOML = """
[ros2]
key_format = "rmw_zenoh"
domain = 5
"""
DOOR = "d_office"
RATE = 2.0  # site seconds per wall second
# Each through d_office to where the other's way comes by: r0 into the office, r1 out to the corridor.
WAYS = {"r0": [(1.0, 5.0), (3.0, 5.0), (3.0, 7.5)], "r1": [(3.0, 9.0), (3.0, 5.0), (5.5, 5.0)]}
TIMEOUT = 40.0  # wall s for both to arrive once commanded (about 15 here)


def test_two_drivers_pass_head_on_through_a_doorway_without_touching(spawn, router, namespace, client, tmp_path: Path):
    site_file = tmp_path / "headon.toml"
    site_file.write_text(SITE_TOML)
    cfg_file = tmp_path / "robots.toml"
    cfg_file.write_text(ROS2_TOML)
    config = load_ros2_config(cfg_file)
    common = ("--site", str(site_file), "--connect", router, "--namespace", namespace, "--ros2-config", str(cfg_file))
    odometry = OdometryWatch(client, SITE, config.naming)
    statuses = client.collect(client.keys.robot_status(), RobotStatus)
    traffic = client.collect(client.keys.robot_traffic(), RobotTraffic)
    events = client.collect(client.keys.event(), Event)
    sim = spawn(arroch("sim", *common, "--ros2-bases", "--rate", f"{RATE:g}", "--time-limit", "600"), name="sim")
    drivers = {rid: spawn(arroch("robot", "--ros2", "--robot", rid, *common), name=rid) for rid in sorted(SITE.robots)}
    sim.wait_for("up on namespace", timeout=30)
    for proc in drivers.values():
        proc.wait_for("up on namespace", timeout=30)
    started = time.monotonic()
    for rid in SITE.robots:  # each driver knows where its robot is (the bases' odometry heartbeat)
        wait_for_message(statuses, lambda s, rid=rid: s.robot == rid and s.state == "idle", timeout=10)
    time.sleep(1.5)
    for rid, way in WAYS.items():
        legs = [math.atan2(b[1] - a[1], b[0] - a[0]) for a, b in zip(way, way[1:], strict=False)]
        rows = [[10.0 * i, x, y, legs[min(i, len(legs) - 1)]] for i, (x, y) in enumerate(way)]
        client.publish(
            client.keys.robot_command(rid),
            RobotCommand(robot=rid, plan_id=1, action_id=1, action="gothrough", args=[DOOR], trajectory=rows),
        )
    ended: dict[str, RobotStatus] = {}
    deadline = time.monotonic() + TIMEOUT
    while len(ended) < len(SITE.robots) and time.monotonic() < deadline:
        st = wait_for_message(statuses, lambda s: s.action_id == 1 and s.state in ("done", "failed"), timeout=TIMEOUT)
        ended[st.robot] = st
    wall = time.monotonic() - started
    logs = "\n".join(f"--- {rid}\n{p.output[-2500:]}" for rid, p in drivers.items())
    assert {rid: st.state for rid, st in ended.items()} == {"r0": "done", "r1": "done"}, (ended, logs)
    # Where each arrived, by its own odometry, and that the two never touched on the way.
    time.sleep(0.5)
    radius = SITE.params.robot_radius
    assert odometry.samples > 100, odometry.samples
    assert odometry.closest >= 2 * radius, f"the bases came {odometry.closest:.3f} m apart\n{logs}"
    kinds = []
    while not events.empty():
        kinds.append(events.get_nowait()[0].kind)
    assert "robot_overlap" not in kinds and "closed_door_crossing" not in kinds, kinds
    # The doorway went to one robot at a time: one of them waited for it, as its traffic told the other.
    said = []
    while not traffic.empty():
        said.append(traffic.get_nowait()[0])
    holders = {t.robot for t in said if t.holds}
    waiting = {t.robot for t in said if t.asking == DOOR and not t.holds}
    assert holders == {"r0", "r1"} and waiting, (holders, waiting)
    print(f"head-on through {DOOR}: both arrived in {wall:.1f} wall s, closest {odometry.closest:.3f} m")
