"""The ``arroch robot --ros2`` process: one real robot, ARROCH on one side, ROS 2 on the other.

ARROCH side: ``robot/<rid>/command`` (RobotCommand) in; ``robot/<rid>/pose`` (RobotPose) and
``robot/<rid>/status`` (RobotStatus) out, as the simulator publishes them; ``door/*/state`` in (a
closed door stops the robot); the planner's liveliness token watched (a planner that dies stops it).
ROS 2 side: the robot's pose in (``nav_msgs/Odometry`` in the odom frame, moved into the map frame
by a fixed map→odom transform or one from ``tf``; or ``geometry_msgs/PoseWithCovarianceStamped`` in
the map frame); ``geometry_msgs/Twist`` out on its ``cmd_vel``, one per pose received.

Safety: zero velocity goes out when the command ends or is refused, at a closed door, when no pose
came for ``pose_timeout`` site seconds (checked every 20 ms of wall time), when the planner's
liveliness token goes away (until a planner is back), and three times on SIGINT/SIGTERM before the
session closes. docs/ros2.md has the details; the watchdog's figures are in tests/ros2/test_safety.py.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import zenoh

from protocol.messages import DoorState, RobotCommand, RobotPose
from protocol.plane import wrap
from protocol.pursuit import ControllerConfig
from protocol.ros2 import types as ros
from protocol.ros2.config import RobotLink
from protocol.ros2.keys import TopicNaming
from protocol.ros2.node import RosNode
from protocol.service import Service
from protocol.site.model import Site
from protocol.transport import ZenohOptions

from .driver import Driver, DriverConfig

WATCHDOG = 0.02  # wall s between checks of the pose's age and the planner's presence
HEARTBEAT = 1.0  # wall s between republications of the status (late joiners)
POSE_PERIOD = 0.05  # s (site and wall) between two RobotPose messages, as the simulator's 20 Hz
STOP_REPEATS = 3  # zero Twists sent when shutting down (one lost sample must not leave the base moving)


@dataclass(frozen=True)
class RobotOptions:
    hold_without_planner: bool = True  # stop while no planner is alive (once one was seen)


class RobotService(Service):
    def __init__(
        self,
        site: Site,
        robot: str,
        link: RobotLink,
        naming: TopicNaming,
        zenoh_options: ZenohOptions,
        *,
        namespace: str | None = None,
        clock: Any = None,
        options: RobotOptions = RobotOptions(),
    ) -> None:
        if robot not in site.robots:
            raise ValueError(f"robot {robot!r} is not on site {site.name!r} (robots: {', '.join(sorted(site.robots))})")
        super().__init__(
            "robot", namespace or site.name, zenoh_options, instance=f"robot-{robot}-{os.getpid()}", clock=clock
        )
        self.site = site
        self.robot = robot
        self.link = link
        self.naming = naming
        self.options = options
        p = site.params
        speed = min(link.max_speed, p.robot_speed) if link.max_speed else p.robot_speed
        self.driver = Driver(
            robot,
            site,
            DriverConfig(
                controller=ControllerConfig(speed=speed, max_turn_rate=link.max_turn_rate),
                radius=p.robot_radius,
                load_time=p.load_time,
                capacity=p.robot_capacity,
                control_period=link.control_period,
            ),
        )
        start = site.robots[robot].start
        self.map_to_odom: tuple[float, float, float] | None = (
            None if link.tf_topic else (link.map_to_odom or tuple(start))
        )
        self.pose: tuple[float, float, float] | None = None
        self._velocity = (0.0, 0.0)
        self._pose_at = -math.inf  # site time the last pose arrived
        self._last_pose_pub = (-math.inf, -math.inf)  # (site, wall) of the last RobotPose
        self._doors_open: dict[str, bool] = {}
        self._planners: set[str] = set()
        self._planner_seen = False
        self._planner_lock = threading.Lock()
        self._holding = ""  # why the base is held at zero velocity ("" = not held)
        self._cmd_vel: Any = None

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        link, keys = self.link, self.keys
        node = RosNode(self, self.naming, f"arroch_robot_{self.robot}", link.namespace)
        self._cmd_vel = node.publisher(link.cmd_vel, ros.TWIST)
        # Latest: a robot at rest with a simulator running ahead must not queue up poses.
        pose_key = node.subscribe(link.pose_topic, link.pose_typename, self._on_pose, latest=True)
        if link.tf_topic:
            node.subscribe(link.tf_topic, ros.TF_MESSAGE, self._on_tf)
        self.subscribe(keys.door_state(), DoorState, self._on_door, ordered=True)
        self.subscribe(keys.robot_command(self.robot), RobotCommand, self._on_command, ordered=True)
        self.advertise(keys.robot_pose(self.robot))
        self.advertise(keys.robot_status(self.robot))
        self.hold(
            self.session.liveliness().declare_subscriber(
                keys.liveliness("planner"), self._on_planner_token, history=True
            )
        )
        self.every(WATCHDOG, self._watchdog)
        self.every(HEARTBEAT, lambda: self._publish_status(force=True), first=0.0)
        self.log.info(
            "robot %s: %s on %s (%s, domain %d), pose from %s",
            self.robot,
            link.cmd_vel,
            link.namespace,
            self.naming.key_format,
            self.naming.domain,
            pose_key,
        )

    def on_stop_signal(self) -> None:
        self.log.info("received %s: stopping the base", self.signals.name)
        for _ in range(STOP_REPEATS):
            self._send(0.0, 0.0)
        self.stop()

    # ------------------------------------------------------------------ inputs

    def _on_pose(self, msg: Any, key: str) -> None:
        p = ros.pose_2d(msg, self.link.pose_typename)
        if not all(math.isfinite(value) for value in (p.x, p.y, p.theta, p.v, p.omega)):
            self.count("poses_not_finite")  # dropped: a NaN must never reach the controller
            return
        if self.link.pose_type == "odometry":
            if self.map_to_odom is None:
                self.count("poses_without_map_to_odom")
                return
            ox, oy, oth = self.map_to_odom
            c, s = math.cos(oth), math.sin(oth)
            pose = (ox + c * p.x - s * p.y, oy + s * p.x + c * p.y, wrap(oth + p.theta))
            velocity = (p.v, p.omega)
        else:
            pose = (p.x, p.y, wrap(p.theta))
            velocity = self._velocity
        self.pose = pose
        self._pose_at = self.clock.now()
        self.count("poses")
        v, omega = self._control()
        self._send(v, omega)
        self._publish_pose(velocity)
        self._publish_status()

    def _on_tf(self, msg: Any, key: str) -> None:
        for tr in msg.transforms:
            if (
                tr.header.frame_id.strip("/") == self.link.map_frame
                and tr.child_frame_id.strip("/") == self.link.odom_frame
            ):
                t = tr.transform
                transform = (t.translation.x, t.translation.y, ros.yaw_of(t.rotation))
                if all(math.isfinite(value) for value in transform):
                    self.map_to_odom = transform
                else:
                    self.count("transforms_not_finite")

    def _on_door(self, msg: DoorState, key: str) -> None:
        self._doors_open[msg.door] = msg.open

    def _on_command(self, cmd: RobotCommand, key: str) -> None:
        if cmd.robot != self.robot:
            self.count("commands_refused")
            self.log.warning("command for robot %r arrived on %s's key: refused", cmd.robot, self.robot)
            return
        result = self.driver.assign(cmd, self.pose, self.clock.now())
        self.count(f"commands_{result}")
        if result == "refused":
            self.log.warning(
                "command %d (%s %s) refused: %s", cmd.action_id, cmd.action, cmd.args, self.driver.s.detail
            )
            self._send(0.0, 0.0)
        self._publish_status()

    def _on_planner_token(self, sample: zenoh.Sample) -> None:
        # On Zenoh's thread: only note it; the watchdog acts.
        with self._planner_lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._planners.add(str(sample.key_expr))
                self._planner_seen = True
            else:
                self._planners.discard(str(sample.key_expr))

    # ------------------------------------------------------------------ control

    def _hold_reason(self, now: float) -> str:
        # Staleness matters while the driver would move the robot; at rest it is sending zero anyway.
        if self.pose is not None and self.driver.phase == "drive" and now - self._pose_at > self.link.pose_timeout:
            return f"pose stale ({now - self._pose_at:.2f} s old)"
        if self.options.hold_without_planner:
            with self._planner_lock:
                if self._planner_seen and not self._planners:
                    return "planner lost"
        return ""

    def _control(self) -> tuple[float, float]:
        now = self.clock.now()
        reason = self._hold_reason(now)
        self._note_hold(reason)
        if reason or self.pose is None:
            return 0.0, 0.0
        return self.driver.control(self.pose, now, lambda door: self._doors_open.get(door, False))

    def _watchdog(self) -> None:
        reason = self._hold_reason(self.clock.now())
        if reason and reason != self._holding:
            self._send(0.0, 0.0)  # at once: the next pose may never come
        self._note_hold(reason)

    def _note_hold(self, reason: str) -> None:
        if reason == self._holding:
            return
        if reason:
            self.log.warning("robot %s held at zero velocity: %s", self.robot, reason)
            self.count("holds")
        else:
            self.log.info("robot %s released (%s over)", self.robot, self._holding)
        self._holding = reason

    # ------------------------------------------------------------------ outputs

    def _send(self, v: float, omega: float) -> None:
        self._velocity = (v, omega)
        self._cmd_vel.publish(ros.twist(v, omega))

    def _publish_pose(self, velocity: tuple[float, float]) -> None:
        if self.pose is None:
            return
        now, wall = self.clock.now(), time.monotonic()
        due = now - self._last_pose_pub[0] >= POSE_PERIOD - 1e-9 and wall - self._last_pose_pub[1] >= POSE_PERIOD
        if not (due or self.driver.changed):
            return
        self._last_pose_pub = (now, wall)
        x, y, theta = self.pose
        self.publish(
            self.keys.robot_pose(self.robot),
            RobotPose(robot=self.robot, x=x, y=y, theta=theta, vel=velocity[0], omega=velocity[1]),
        )

    def _publish_status(self, force: bool = False) -> None:
        if not (force or self.driver.changed):
            return
        self.driver.changed = False
        self.publish(self.keys.robot_status(self.robot), self.driver.status(getattr(self.clock, "world_version", 0)))
