"""A stand-in ROS 2 mobile base and site clock for testing ``arroch robot --ros2`` on its own.

:class:`FakeBase` runs in the test process: it publishes the site ``clock`` (realtime, so site
time = wall seconds since it started) and the robot's ``nav_msgs/Odometry`` at 20 Hz, records
every ``geometry_msgs/Twist`` (or ``TwistStamped``, as the robot's ``cmd_vel_type``) the driver
sends with the site time it arrived, and moves the robot by them (a unicycle, as a base would).
Odometry can be paused to make the pose go stale. With a ``scan_topic`` it is also the robot's
laser scanner: a ``sensor_msgs/LaserScan`` (the simulator's :class:`services.sim.scan.Scanner`:
the site's walls, and a person the test places) just before each odometry message.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from protocol.messages import Clock, RobotCommand
from protocol.site import Site, load_site
from runtime.pursuit import integrate
from runtime.ros2 import types as ros
from runtime.ros2.config import Ros2Config
from runtime.ros2.keys import TopicNaming
from runtime.ros2.node import RosNode
from services.sim.human import HUMAN_RADIUS
from services.sim.scan import Scanner
from tests.conftest import TestClient
from tests.procs import arroch

PERIOD = 0.05  # s between odometry messages (and clock messages)


@dataclass(frozen=True)
class TwistSeen:
    site_time: float
    v: float
    omega: float
    stamp: float = 0.0  # TwistStamped: its header's stamp (s)
    frame: str = ""

    @property
    def zero(self) -> bool:
        return self.v == 0.0 and self.omega == 0.0


class FakeBase:
    def __init__(
        self,
        client: TestClient,
        robot: str,
        start: tuple[float, float, float],
        config: Ros2Config,
        *,
        publish_clock: bool = True,
    ) -> None:
        self.client = client
        self.robot = robot
        self.start = start
        self.x, self.y, self.theta = 0.0, 0.0, 0.0  # odom frame: zero where the base booted (its start)
        self.v = self.omega = 0.0
        self.twists: list[TwistSeen] = []
        self.odometry_sent: list[float] = []  # site times the odometry messages went out
        self.odometry_on = True
        self.publish_clock = publish_clock  # False: a simulator keeps the site clock
        self._lock = threading.Lock()
        self._stop = threading.Event()
        link = config.link(robot)
        self.link = link
        self.person: tuple[float, float] | None = None  # where a person stands (map frame)
        node = RosNode(client, config.naming(robot), f"fake_base_{robot}", link.namespace)
        self._odom = node.publisher(link.odom_topic or link.pose_topic, ros.ODOMETRY)
        self._scan = node.publisher(link.scan_topic, ros.LASER_SCAN) if link.scan_topic else None
        self._scanner = Scanner(load_site()) if link.scan_topic else None
        key = config.naming(robot).subscription_key(link.topic(link.cmd_vel), link.cmd_vel_typename)
        client.hold(client.session.declare_subscriber(key, self._on_twist))
        self.t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="fake-base", daemon=True)
        self._thread.start()

    def now(self) -> float:
        """Site time (the clock this base publishes)."""
        return time.monotonic() - self.t0

    def _on_twist(self, sample) -> None:  # noqa: ANN001
        typename = self.link.cmd_vel_typename
        msg = ros.deserialize(sample.payload.to_bytes(), typename)
        v, omega = ros.twist_of(msg, typename)
        stamp, frame = (
            (ros.seconds(msg.header.stamp), msg.header.frame_id) if typename == ros.TWIST_STAMPED else (0, "")
        )
        with self._lock:
            self.v, self.omega = v, omega
            self.twists.append(TwistSeen(self.now(), v, omega, stamp, frame))

    def publish_scan(self) -> None:
        """The scan from where the robot is now (walls, and the person if one stands in the site)."""
        if self._scan is None or self._scanner is None:
            return
        person = [(*self.person, HUMAN_RADIUS)] if self.person else []
        ranges = self._scanner.ranges(self.map_pose(), person)
        scanner = self._scanner
        self._scan.publish(
            ros.laser_scan(
                self.now(), "base_link", scanner.angle_min, scanner.angle_increment, ranges, scanner.config.range_max
            )
        )

    def _run(self) -> None:
        seq = 0
        while not self._stop.wait(PERIOD):
            now = self.now()
            seq += 1
            if self.publish_clock:
                self.client.publish(
                    self.client.keys.clock(), Clock(time=now, mode="realtime", rate=1.0, world_version=1)
                )
            with self._lock:
                self.x, self.y, self.theta = integrate(self.x, self.y, self.theta, self.v, self.omega, PERIOD)
                x, y, theta, v, omega = self.x, self.y, self.theta, self.v, self.omega
            if self.odometry_on:
                self.publish_scan()
                self._odom.publish(ros.odometry(now, "odom", "base_link", x, y, theta, v, omega))
                self.odometry_sent.append(now)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    # ------------------------------------------------------------------ what the tests ask

    def map_pose(self) -> tuple[float, float, float]:
        ox, oy, oth = self.start
        with self._lock:
            x, y, th = self.x, self.y, self.theta
        return ox + math.cos(oth) * x - math.sin(oth) * y, oy + math.sin(oth) * x + math.cos(oth) * y, oth + th

    def wait_moving(self, timeout: float = 15.0) -> float:
        """Site time of the first non-zero Twist (the driver drives the base)."""
        return self._wait(lambda tw: not tw.zero, 0.0, timeout, "a non-zero Twist").site_time

    def wait_moving_after(self, t: float, timeout: float = 5.0) -> TwistSeen:
        return self._wait(lambda tw: not tw.zero, t, timeout, "a non-zero Twist")

    def first_zero_after(self, t: float, timeout: float = 5.0) -> TwistSeen:
        return self._wait(lambda tw: tw.zero, t, timeout, "a zero Twist")

    def _wait(self, pred, after: float, timeout: float, what: str) -> TwistSeen:  # noqa: ANN001
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                found = [tw for tw in self.twists if tw.site_time >= after and pred(tw)]
            if found:
                return found[0]
            time.sleep(0.01)
        raise AssertionError(
            f"no {what} after site time {after:.2f} within {timeout} s; last twists {self.twists[-5:]}"
        )


def straight_command(
    robot: str,
    start: tuple[float, float, float],
    length: float,
    *,
    action_id: int = 1,
    opening: str = "d_lab",
    offset: float = 0.0,
) -> RobotCommand:
    """An ``approach`` whose trajectory runs ``length`` m straight ahead of ``start`` (shifted ``offset`` m
    back along the heading: a trajectory that starts that far from the robot)."""
    x, y, th = start
    c, s = math.cos(th), math.sin(th)
    rows = [[0.1 * i, x + c * (i * length / 20 - offset), y + s * (i * length / 20 - offset), th] for i in range(21)]
    return RobotCommand(robot=robot, plan_id=1, action_id=action_id, action="approach", args=[opening], trajectory=rows)


class OdometryWatch:
    """Each base's pose in the site frame from its own nav_msgs/Odometry (odom frame: its start pose),
    read as any ROS 2 node would, and the closest any two bases came, taken at the odometry stamps
    every base reported: contacts counted from the bases' own odometry, not the simulator's count."""

    def __init__(self, client: TestClient, site: Site, naming: Callable[[str], TopicNaming]) -> None:
        self.site = site
        self.lock = threading.Lock()
        self.by_stamp: dict[float, dict[str, tuple[float, float]]] = {}
        self.closest = math.inf
        self.closest_pair: tuple[str, str] = ("", "")
        self.samples = 0  # stamps at which every base reported
        self.contacts = 0  # of those, the ones with two discs overlapping
        for rid in site.robots:
            key = naming(rid).subscription_key(f"/{rid}/odom", ros.ODOMETRY)
            client.hold(client.session.declare_subscriber(key, lambda s, rid=rid: self._on(rid, s)))

    def _on(self, rid: str, sample) -> None:  # noqa: ANN001
        msg = ros.deserialize(sample.payload.to_bytes(), ros.ODOMETRY)
        p = ros.pose_2d(msg, ros.ODOMETRY)
        ox, oy, oth = self.site.robots[rid].start
        c, s = math.cos(oth), math.sin(oth)
        where = (ox + c * p.x - s * p.y, oy + s * p.x + c * p.y)
        stamp = round(ros.seconds(msg.header.stamp), 3)
        with self.lock:
            at = self.by_stamp.setdefault(stamp, {})
            at[rid] = where
            if len(at) < len(self.site.robots):
                return
            del self.by_stamp[stamp]
            self.samples += 1
            touching = 2.0 * self.site.params.robot_radius
            pairs = [(math.dist(at[a], at[b]), (a, b)) for a, b in itertools.combinations(sorted(at), 2)]
            nearest, pair = min(pairs)
            if nearest < self.closest:
                self.closest, self.closest_pair = nearest, pair
            self.contacts += nearest < touching


def ros2_mission(
    robots: list[str],
    key_format: str,
    *,
    connect: str,
    namespace: str,
    run_dir: str,
    timeout: float,
    site_file: str = "",
) -> list[str]:
    """``arroch up`` for a lockstep mission with every robot a ROS 2 base: the planner and restrictor,
    ``arroch sim --ros2-bases`` as the world and one ``arroch robot --ros2`` per robot as children, on
    ROS 2 domain 7, connected to the router at ``connect`` (the mission test and benchmarks/ros2.py)."""
    site_args = f" --site {site_file}" if site_file else ""
    ros2 = f"--key-format {key_format} --domain 7{site_args} --connect {{connect}} --namespace {{namespace}}"
    return arroch(
        "up",
        *site_args.split(),
        *("--no-router", "--connect", connect, "--namespace", namespace),
        *("--services", "planner,restrictor", "--mode", "lockstep", "--seed", "1", "--until-done"),
        *("--run-dir", run_dir, "--progress", "off", "--timeout", f"{timeout:g}"),
        f"--child=world={{python}} -m services.cli sim --mode lockstep --seed 1 --ros2-bases {ros2}",
        *(f"--child={rid}={{python}} -m services.cli robot --ros2 --robot {rid} {ros2}" for rid in sorted(robots)),
    )
