"""The laser safety field and the ROS 2 details real bases need, against a real ``arroch robot
--ros2`` process over a real router. The base, its laser scanner and the site clock are
:class:`tests.ros2.harness.FakeBase` (site time = wall time); the scan is the simulator's own
ray casting (:mod:`services.sim.scan`) of the site's walls and of a person the test places.

- a person stepping in front of the driving robot: zero Twist within 0.1 s of site time, no
  contact, and the robot goes on once she has left;
- a base that takes ``TwistStamped`` (Jazzy's diff_drive_controller) is driven, stamp and frame set;
- a transient-local localiser (Nav2's ``amcl_pose``) that published once, before the driver
  started: the driver gets that pose, and odometry carries it on from there (sparse poses).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh.ext

from protocol.messages import Event, RobotCommand, RobotPose, RobotStatus
from protocol.site import load_site
from runtime.ros2 import types as ros
from runtime.ros2.config import load_ros2_config
from runtime.safety_field import ROBOT_REACH, FieldConfig, limit, scan_points, stop_distance, without_robots
from services.sim.human import HUMAN_RADIUS
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.ros2.harness import FakeBase, straight_command
from tests.ros2.test_safety import start_driver

SITE = load_site()
ROBOT = "r0"
START = SITE.robots[ROBOT].start
RADIUS = SITE.params.robot_radius
SPEED = SITE.params.robot_speed


def config_file(tmp_path: Path, **keys: object) -> Path:
    body = "\n".join(f"{k} = {v!r}".replace("'", '"') for k, v in keys.items())
    f = tmp_path / "robots.toml"
    f.write_text(f"[ros2.robots.{ROBOT}]\n{body}\n")
    return f


# ---------------------------------------------------------------------- the field's rules


def points_ahead(distance: float, lateral: float = 0.0) -> np.ndarray:
    return np.array([[distance, lateral]])


def test_stop_zone_grows_with_speed_and_stops_at_once():
    cfg = FieldConfig()
    assert stop_distance(0.0, cfg) == cfg.stop_base < stop_distance(0.3, cfg) < stop_distance(0.5, cfg)
    grown = RADIUS + cfg.side_margin
    # 0.2 m in front of the grown disc: inside the stop zone at 0.5 m/s, not at rest.
    inside = points_ahead(grown + 0.2)
    assert 0.2 < stop_distance(0.5, cfg)
    verdict = limit(inside, 0.5, 0.1, 0.5, RADIUS, cfg)
    assert verdict.stop and (verdict.v, verdict.omega) == (0.0, 0.0)
    start = limit(inside, 0.5, 0.1, 0.0, RADIUS, cfg)  # at rest, not stopped by the field: on, slowly
    assert not start.stop and 0.0 < start.v < 0.5 and start.omega / start.v == pytest.approx(0.1 / 0.5)
    # Stopped by the field, it waits until the way is clear at its cruising speed.
    assert limit(inside, 0.5, 0.1, 0.0, RADIUS, cfg, resume_speed=0.5).stop
    assert not limit(points_ahead(grown + 0.3), 0.5, 0.0, 0.0, RADIUS, cfg, resume_speed=0.5).stop


def test_slow_zone_caps_the_speed_and_nothing_beside_or_behind_counts():
    cfg = FieldConfig()
    grown = RADIUS + cfg.side_margin
    far = limit(points_ahead(grown + 3.5), SPEED, 0.0, SPEED, RADIUS, cfg)
    near = limit(points_ahead(grown + 0.2), SPEED, 0.0, 0.2, RADIUS, cfg)  # going at 0.2 m/s
    assert far.v == SPEED and 0.0 < near.v < SPEED and not near.stop
    assert stop_distance(near.v, cfg) <= 0.2 - cfg.slow_gap + 1e-9  # it can stop short of it
    beside = np.array([[0.3, grown + 0.02], [-0.34, 0.0]])  # a wall beside the corridor, a person behind
    assert limit(beside, SPEED, 0.0, SPEED, RADIUS, cfg).v == SPEED
    assert limit(beside, -0.2, 0.0, 0.2, RADIUS, cfg).stop  # ... but backing up into her stops it
    touching = np.array([[0.0, grown - 0.01]])
    assert limit(touching, 0.0, 1.0, 0.0, RADIUS, cfg).stop  # a turn with someone touching the disc


def test_points_on_a_robot_the_driver_hears_of_are_left_to_the_traffic_rules():
    """The robot at (2, 5) facing +y: a robot reported at (2, 6) is 1 m ahead; the scan's returns off
    its front are left out, a person 0.4 m to the robot's right is not."""
    pose = (2.0, 5.0, math.pi / 2)
    other_front = np.array([[1.0 - RADIUS, 0.0], [1.0 - RADIUS + 0.02, 0.1]])  # robot frame: x ahead
    person = np.array([[0.0, -0.4]])
    points = np.vstack([other_front, person])
    kept = without_robots(points, pose, [(2.0, 6.0)], RADIUS + ROBOT_REACH)
    assert kept.tolist() == person.tolist()
    assert without_robots(points, pose, [], RADIUS + ROBOT_REACH) is points


def test_a_scan_that_cannot_be_read_names_its_field():
    with pytest.raises(ValueError, match="angle_increment"):
        scan_points(0.0, float("nan"), 0.05, 8.0, np.ones(3))
    with pytest.raises(ValueError, match="range_min"):
        scan_points(0.0, 0.1, 9.0, 8.0, np.ones(3))
    pts = scan_points(0.0, math.pi / 2, 0.05, 8.0, np.array([1.0, np.inf, np.nan, 0.01]))
    assert pts.shape == (1, 2) and pts[0] == pytest.approx([1.0, 0.0])  # no return, NaN, too close: none


# ---------------------------------------------------------------------- a person steps in


def test_person_stepping_in_stops_the_robot_within_a_tenth_of_a_second(spawn, router, namespace, client, tmp_path):
    cfg_file = config_file(tmp_path, scan_topic="scan")
    base = FakeBase(client, ROBOT, START, load_ros2_config(cfg_file))
    try:
        statuses = client.collect(client.keys.robot_status(ROBOT), RobotStatus)
        start_driver(spawn, router, namespace, "--ros2-config", str(cfg_file))
        base.first_zero_after(0.0, timeout=10)
        client.publish(client.keys.robot_command(ROBOT), straight_command(ROBOT, START, 8.0))
        base.wait_moving()
        time.sleep(1.0)  # up to speed
        x, y, th = base.map_pose()
        assert any(abs(tw.v) > 0.8 * SPEED for tw in base.twists[-5:]), base.twists[-5:]
        # She steps in 0.65 m ahead of the robot's centre: 0.19 m from its disc grown by the
        # margin, inside the stop zone at 0.5 m/s (0.225 m).
        person = (x + 0.65 * math.cos(th), y + 0.65 * math.sin(th))
        t_in = base.now()
        base.person = person
        base.publish_scan()  # the scanner sees her at once
        stop = base.first_zero_after(t_in, timeout=3)
        assert stop.site_time - t_in <= 0.1, f"zero Twist {stop.site_time - t_in:.3f} s after she stepped in"
        # She stays 2 s: the robot stands, short of her.
        nearest = math.inf
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            nearest = min(nearest, math.dist(base.map_pose()[:2], person))
            time.sleep(0.02)
        assert nearest > RADIUS + HUMAN_RADIUS + 0.05, f"robot came within {nearest:.3f} m of her"
        wait_for_message(statuses, lambda s: "obstacle" in s.detail and s.state == "moving", timeout=3)
        standing = base.map_pose()
        t_out = base.now()
        base.person = None  # she leaves
        base.wait_moving_after(t_out)
        deadline = time.monotonic() + 5
        while math.dist(base.map_pose()[:2], standing[:2]) < 0.3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert math.dist(base.map_pose()[:2], standing[:2]) >= 0.3, "the robot did not go on once she left"
        (stats,) = [e.data for e in client.query(client.keys.stats("robot"), Event)]
        assert stats["field_stops"] >= 1 and stats["scans"] > 20, stats
    finally:
        base.close()


def test_a_robot_with_a_scanner_and_no_scan_does_not_drive(spawn, router, namespace, client, tmp_path):
    cfg_file = config_file(tmp_path, scan_topic="scan")
    base = FakeBase(client, ROBOT, START, load_ros2_config(cfg_file))
    try:
        base._scan = None  # the scanner is dead: no LaserScan at all
        driver = start_driver(spawn, router, namespace, "--ros2-config", str(cfg_file))
        base.first_zero_after(0.0, timeout=10)
        client.publish(client.keys.robot_command(ROBOT), straight_command(ROBOT, START, 8.0))
        driver.wait_for("no scan", timeout=10)
        time.sleep(0.5)
        assert all(tw.zero for tw in base.twists) and math.dist(base.map_pose()[:2], START[:2]) < 1e-6
    finally:
        base.close()


# ---------------------------------------------------------------------- bases and localisers


def test_a_twist_stamped_base_is_driven(spawn, router, namespace, client, tmp_path):
    cfg_file = config_file(tmp_path, cmd_vel_type="twist_stamped", base_frame="base_footprint")
    base = FakeBase(client, ROBOT, START, load_ros2_config(cfg_file))
    try:
        start_driver(spawn, router, namespace, "--ros2-config", str(cfg_file))
        base.first_zero_after(0.0, timeout=10)
        client.publish(client.keys.robot_command(ROBOT), straight_command(ROBOT, START, 2.0))
        base.wait_moving()
        moving = next(tw for tw in base.twists if not tw.zero)
        assert moving.frame == "base_footprint" and abs(moving.stamp - time.time()) < 10.0
        deadline = time.monotonic() + 15
        while math.dist(base.map_pose()[:2], START[:2]) < 1.9 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert math.dist(base.map_pose()[:2], START[:2]) >= 1.9
    finally:
        base.close()


def test_transient_local_pose_published_before_the_driver_starts(spawn, router, namespace, client, tmp_path):
    """Nav2's AMCL publishes amcl_pose transient-local and only when its filter updates: a robot
    standing still gets no new one. Published once before the driver starts, by a cached (advanced)
    publisher as rmw_zenoh's transient-local publisher is, the driver still gets it; odometry then
    carries the pose on (a sparse localiser)."""
    cfg_file = config_file(
        tmp_path, pose_type="pose", pose_topic="amcl_pose", pose_durability="transient_local", odom_topic="odom"
    )
    config = load_ros2_config(cfg_file)
    key = config.naming(ROBOT).data_key(f"/{ROBOT}/amcl_pose", ros.POSE_COV_STAMPED)
    # The localiser's own session, with timestamps as rmw_zenoh's sessions have them (a cached
    # publisher orders its samples by them).
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{router}"]')
    conf.insert_json5("timestamping/enabled", "true")
    session = zenoh.open(conf)
    amcl = zenoh.ext.declare_advanced_publisher(
        session, key, cache=zenoh.ext.CacheConfig(max_samples=1), publisher_detection=True
    )
    x0, y0, th0 = START
    amcl.put(ros.serialize(ros.pose_with_covariance_stamped(0.0, "map", x0, y0, th0), ros.POSE_COV_STAMPED))
    time.sleep(0.3)
    base = FakeBase(client, ROBOT, START, config)
    try:
        poses = client.collect(client.keys.robot_pose(ROBOT), RobotPose)
        driver = start_driver(spawn, router, namespace, "--ros2-config", str(cfg_file))
        first = wait_for_message(poses, timeout=10)
        assert math.dist((first.x, first.y), (x0, y0)) < 0.01
        client.publish(client.keys.robot_command(ROBOT), straight_command(ROBOT, START, 2.0))
        base.wait_moving()
        deadline = time.monotonic() + 15
        while math.dist(base.map_pose()[:2], (x0, y0)) < 1.95 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)  # arrived: the last poses are out
        last = first
        while not poses.empty():
            last = poses.get_nowait()[0]
        # The driver's pose (the one fix, carried on by odometry since) is where the base is.
        assert math.dist((last.x, last.y), base.map_pose()[:2]) < 0.05, (last, base.map_pose())
        assert math.dist((last.x, last.y), (x0, y0)) > 1.9
        assert "no pose of the robot yet" not in driver.output
    finally:
        base.close()
        amcl.undeclare()
        session.close()


# ---------------------------------------------------------------------- the simulator's scanner


def test_simulated_bases_publish_a_scan_the_driver_goes_by(spawn, router, namespace, client, tmp_path):
    """``arroch sim --ros2-bases``: r1's base takes TwistStamped and has a laser scanner; its scan
    shows d_lab's closed leaf 2 m ahead; the driver, with the field on, takes r1 through the door
    once it opens for it."""
    robot = "r1"  # in the lab, 2 m in front of d_lab (automatic), facing it
    f = tmp_path / "robots.toml"
    f.write_text(f'[ros2.robots.{robot}]\nscan_topic = "scan"\ncmd_vel_type = "twist_stamped"\n')
    config = load_ros2_config(f)
    scans: list = []
    key = config.naming(robot).subscription_key(f"/{robot}/scan", ros.LASER_SCAN)
    client.hold(
        client.session.declare_subscriber(
            key, lambda s: scans.append(ros.deserialize(s.payload.to_bytes(), ros.LASER_SCAN))
        )
    )
    events = client.collect(client.keys.event(), Event)
    common = ("--connect", router, "--namespace", namespace, "--ros2-config", str(f))
    spawn(arroch("sim", "--ros2-bases", *common), name="sim").wait_for("sim sim-", timeout=20)
    deadline = time.monotonic() + 10
    while not scans and time.monotonic() < deadline:
        time.sleep(0.05)
    assert scans, "no LaserScan from the simulated base"
    first = scans[0]
    ranges = np.asarray(first.ranges)
    ahead = int(round((0.0 - first.angle_min) / first.angle_increment))
    assert first.header.frame_id == "base_link" and ranges[ahead] == pytest.approx(2.0, abs=0.03)
    spawn(arroch("robot", "--ros2", "--robot", robot, *common), name="robot").wait_for("robot robot-r1-", timeout=20)
    time.sleep(1.5)  # the driver hears the base's odometry (heartbeat)
    start = SITE.robots[robot].start
    rows = straight_command(robot, start, 3.0).trajectory
    client.publish(
        client.keys.robot_command(robot),
        RobotCommand(robot=robot, plan_id=1, action_id=1, action="gothrough", args=["d_lab"], trajectory=rows),
    )
    done = wait_for_message(
        events,
        lambda e: e.kind in ("action_done", "action_failed", "closed_door_crossing") and e.robot == robot,
        timeout=40,
    )
    assert done.kind == "action_done", done
    assert done.data.pose[1] < SITE.doors["d_lab"].center[1] - RADIUS
    (stats,) = [e.data for e in client.query(client.keys.stats("robot"), Event)]
    assert stats["scans"] > 10, stats
