"""The ``arroch robot --ros2`` process: one real robot, ARROCH on one side, ROS 2 on the other.

ARROCH side: ``robot/<rid>/command`` (RobotCommand) in; ``robot/<rid>/pose`` (RobotPose) and
``robot/<rid>/status`` (RobotStatus) out, as the simulator publishes them; ``door/*/state`` in (a
closed door stops the robot); the planner's liveliness token watched (a planner that dies stops it).
The other robots: their ``robot/*/pose``, ``robot/*/status`` and ``robot/*/traffic`` in, this
robot's ``robot/<rid>/traffic`` (RobotTraffic) out, on every change and once a second: the
executor's traffic rules (right of way, driving around, making way, doorways, queues) run across
robot processes (:mod:`.driver`, :mod:`runtime.executor.traffic`).
ROS 2 side: the robot's pose in (``nav_msgs/Odometry`` in the odom frame, moved into the map frame
by a fixed map→odom transform or one from ``tf``; or ``geometry_msgs/PoseWithCovarianceStamped`` in
the map frame, possibly transient-local and sparse, with odometry carrying the pose between two of
them); ``geometry_msgs/Twist`` or ``TwistStamped`` out on its ``cmd_vel``, one per pose received;
``sensor_msgs/LaserScan`` in (the safety field, :mod:`runtime.safety_field`), when configured.

Safety: zero velocity goes out when the command ends or is refused, at a closed door, for another
robot (the traffic rules), when no pose came for ``pose_timeout`` site seconds (checked every 20 ms
of wall time), when the scan is stale or shows an obstacle in the stop zone (at once, on the scan;
points on the robots it hears of are the traffic rules' business), when the planner's liveliness
token goes away (until a planner is back), and three times on SIGINT/SIGTERM before the session
closes. docs/ros2.md has the details; the figures are in tests/ros2/test_safety.py, test_field.py,
test_driver.py and test_head_on.py.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from protocol.messages import DoorState, RobotCommand, RobotPose, RobotStatus, RobotTraffic
from protocol.site.model import Site
from runtime.executor import RobotConfig
from runtime.plane import wrap
from runtime.pursuit import ControllerConfig
from runtime.ros2 import types as ros
from runtime.ros2.config import RobotLink
from runtime.ros2.keys import TopicNaming
from runtime.ros2.node import RosNode
from runtime.safety_field import ROBOT_REACH, FieldConfig, Verdict, limit, scan_points, without_robots
from runtime.service import Service
from runtime.transport import ZenohOptions

from .driver import Driver, DriverConfig

WATCHDOG = 0.02  # wall s between checks of the pose's age and the planner's presence
HEARTBEAT = 1.0  # wall s between republications of the status (late joiners)
POSE_PERIOD = 0.05  # s (site and wall) between two RobotPose messages of a robot at rest, as the simulator's 20 Hz
# A robot that moved this far (m, rad) since its last RobotPose publishes one at once, whatever the
# time: the other robots' drivers keep apart from where it is (in lockstep, site time runs faster
# than 20 Hz of wall time, and a pose per 50 wall ms would be many ticks old)
MOVED, TURNED = 0.01, 0.02
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
            DriverConfig.for_robot(
                RobotConfig(
                    controller=ControllerConfig(speed=speed, max_turn_rate=link.max_turn_rate),
                    radius=p.robot_radius,
                    load_time=p.load_time,
                    capacity=p.robot_capacity,
                ),
                link.control_period,
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
        self._last_pose: tuple[float, float, float] | None = None  # the pose it gave
        self._planners: set[str] = set()
        self._planner_seen = False
        self._planner_lock = threading.Lock()
        self._holding = ""  # why the base is held at zero velocity ("" = not held)
        self._cmd_vel: Any = None
        self._cmd_vel_type = link.cmd_vel_typename
        # Sparse localisation (pose_type "pose" with odom_topic): the last fix in the map and the
        # odometry pose when it came; odometry moves the robot from there until the next fix.
        self._fix: tuple[tuple[float, float, float], tuple[float, float, float] | None] | None = None
        self._odom_last: tuple[float, float, float] | None = None
        # The safety field: the last scan's points (robot frame) and when it came.
        self.field = FieldConfig()
        self._scan = np.zeros((0, 2))
        self._scan_at = -math.inf
        self._blocked_since: float | None = None  # site time the field started holding a driving robot
        self._stopped_by_field = False  # it waits for the way to clear at cruising speed before going on
        self._speed = 0.0  # m/s the robot goes at (odometry's, else the last command's)
        self._bad_logged: set[str] = set()
        peers = self.driver.peers
        self._peer_inputs: dict[type, tuple[Any, str]] = {
            RobotPose: (peers.pose, "peer_poses_refused"),
            RobotStatus: (peers.status, "peer_statuses_refused"),
            RobotTraffic: (peers.traffic, "traffic_refused"),
        }

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        link, keys = self.link, self.keys
        node = RosNode(self, self.naming, f"arroch_robot_{self.robot}", link.namespace)
        self._cmd_vel = node.publisher(link.cmd_vel, self._cmd_vel_type)
        # Latest: a robot at rest with a simulator running ahead must not queue up poses.
        pose_key = node.subscribe(
            link.pose_topic,
            link.pose_typename,
            self._on_pose,
            latest=True,
            transient_local=link.pose_durability == "transient_local",
        )
        if link.odom_topic:
            node.subscribe(link.odom_topic, ros.ODOMETRY, self._on_odometry, latest=True)
        if link.scan_topic:
            node.subscribe(link.scan_topic, ros.LASER_SCAN, self._on_scan, latest=True)
        if link.tf_topic:
            node.subscribe(link.tf_topic, ros.TF_MESSAGE, self._on_tf)
        self.subscribe(keys.door_state(), DoorState, self._on_door, ordered=True)
        self.subscribe(keys.robot_command(self.robot), RobotCommand, self._on_command, ordered=True)
        # The other robots (latest per robot: a step reads where each is now, not where it was).
        self.subscribe(keys.robot_pose(), RobotPose, self._on_peer, latest=True)
        self.subscribe(keys.robot_status(), RobotStatus, self._on_peer, latest=True)
        self.subscribe(keys.robot_traffic(), RobotTraffic, self._on_peer, latest=True)
        self.advertise(keys.robot_pose(self.robot))
        self.advertise(keys.robot_status(self.robot))
        self.advertise(keys.robot_traffic(self.robot))
        self.hold(
            self.session.liveliness().declare_subscriber(
                keys.liveliness("planner"), self._on_planner_token, history=True
            )
        )
        self.every(WATCHDOG, self._watchdog)
        self.every(HEARTBEAT, self._heartbeat, first=0.0)
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

    def _bad(self, counter: str, what: str) -> None:
        """Count a dropped input; log the first of each kind (the rest are in the counters)."""
        self.count(counter)
        if counter not in self._bad_logged:
            self._bad_logged.add(counter)
            self.log.warning("robot %s: dropped %s (counted as %s)", self.robot, what, counter)

    def _pose_of(self, msg: Any, typename: str) -> ros.Pose2D | None:
        p = ros.pose_2d(msg, typename)
        fields = {"x": p.x, "y": p.y, "yaw": p.theta, "linear.x": p.v, "angular.z": p.omega}
        bad = [name for name, value in fields.items() if not math.isfinite(value)]
        if bad:
            # A NaN must never reach the controller.
            self._bad("poses_not_finite", f"a {typename} whose {', '.join(bad)} is not finite")
            return None
        return p

    def _on_pose(self, msg: Any, key: str) -> None:
        p = self._pose_of(msg, self.link.pose_typename)
        if p is None:
            return
        if self.link.pose_type == "odometry":
            if self.map_to_odom is None:
                self.count("poses_without_map_to_odom")
                return
            self._moved(_compose(self.map_to_odom, (p.x, p.y, p.theta)), (p.v, p.omega))
            return
        pose = (p.x, p.y, wrap(p.theta))
        if self.link.odom_topic:
            self._fix = (pose, self._odom_last)
            self.count("localisation_fixes")
        self._moved(pose, self._velocity)

    def _on_odometry(self, msg: Any, key: str) -> None:
        """Sparse localisation: odometry moves the robot from the last fix until the next one."""
        p = self._pose_of(msg, ros.ODOMETRY)
        if p is None:
            return
        odom = (p.x, p.y, p.theta)
        self._odom_last = odom
        if self._fix is None:
            return  # no fix in the map yet: odometry alone cannot say where the robot is
        fix, odom_at_fix = self._fix
        if odom_at_fix is None:
            self._fix = (fix, odom)  # the first odometry after the fix stands for the fix's instant
            odom_at_fix = odom
        self._moved(_compose(fix, _between(odom_at_fix, odom)), (p.v, p.omega))

    def _moved(self, pose: tuple[float, float, float], velocity: tuple[float, float]) -> None:
        """A new pose of the robot (map frame), going at ``velocity`` (odometry's, else the last
        command's): answer it with the velocity to send."""
        self.pose = pose
        self._speed = velocity[0]
        self._pose_at = self.clock.now()
        self.count("poses")
        v, omega = self._control()
        self._send(v, omega)  # first: the base waits for it
        self._publish_pose(velocity)
        self._publish_status()
        self._publish_traffic()

    def _on_scan(self, msg: Any, key: str) -> None:
        try:
            points = scan_points(msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max, msg.ranges)
        except ValueError as exc:
            self._bad("scans_bad", f"a LaserScan: {exc}")
            return
        self._scan, self._scan_at = points, self.clock.now()
        self.count("scans")
        v, omega = self._velocity
        if v != 0.0 or omega != 0.0:
            # Someone stepping in front of the robot stops it now, not at the next pose.
            speed = max(abs(v), abs(self._speed))
            verdict = limit(self._unknown(points), v, omega, speed, self.site.params.robot_radius, self.field)
            if verdict.stop:
                self._stopped_by_field = True
                self._send(0.0, 0.0)
                self._note_field(verdict, self._scan_at)
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
        if not self.driver.doors.heard(msg):
            self._bad("doors_unknown", f"the state of door {msg.door!r}, which is not on site {self.site.name}")

    def _on_peer(self, msg: RobotPose | RobotStatus | RobotTraffic, key: str) -> None:
        """Another robot's pose, status or traffic: the fleet the executor keeps this robot apart from."""
        owner = key.split("/")[-2]  # .../robot/<rid>/<pose|status|traffic>
        if owner == self.robot:
            return  # its own, heard back
        take, counter = self._peer_inputs[type(msg)]
        problem = f"robot: {msg.robot!r} on robot {owner!r}'s key" if msg.robot != owner else ""
        problem = problem or take(msg, time.monotonic())
        if problem:
            self._bad(counter, f"a {msg.TYPE} ({problem})")

    def _on_command(self, cmd: RobotCommand, key: str) -> None:
        if cmd.robot != self.robot:
            self.count("commands_refused")
            self.log.warning("command for robot %r arrived on %s's key: refused", cmd.robot, self.robot)
            return
        result = self.driver.assign(cmd, self.pose, self.clock.now())
        self.count(f"commands_{result}")
        if result == "refused":
            self.log.warning(
                "command %d (%s %s) refused: %s", cmd.action_id, cmd.action, cmd.args, self.driver.robot.detail
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
        moving = self.driver.may_move
        if self.pose is not None and moving and now - self._pose_at > self.link.pose_timeout:
            return f"pose stale ({now - self._pose_at:.2f} s old)"
        if self.link.scan_topic and moving and now - self._scan_at > self.link.scan_timeout:
            return "no scan" if self._scan_at == -math.inf else f"scan stale ({now - self._scan_at:.2f} s old)"
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
        step, outcomes = self.driver.control(self.pose, now, time.monotonic())
        for rid in self.driver.went_stale:
            self.log.warning("robot %s: nothing heard of robot %s for a while: a parked obstacle now", self.robot, rid)
        for outcome in outcomes:
            if outcome.kind == "action_failed":
                self.log.info("robot %s: action %s failed: %s", self.robot, outcome.data.action_id, outcome.data.reason)
        v, omega = step.v, step.omega
        if not self.link.scan_topic or not self.driver.may_move:
            return v, omega
        verdict = limit(
            self._unknown(self._scan),
            v,
            omega,
            max(abs(self._speed), abs(self._velocity[0])),
            self.site.params.robot_radius,
            self.field,
        )
        self._note_field(verdict if (v or omega) and (verdict.v, verdict.omega) == (0.0, 0.0) else None, now)
        return verdict.v, verdict.omega

    def _unknown(self, points: np.ndarray) -> np.ndarray:
        """The scan's points that are on no robot the driver hears of (those the traffic rules keep apart)."""
        if self.pose is None:
            return points
        return without_robots(points, self.pose, self.driver.peers.heard(), self.site.params.robot_radius + ROBOT_REACH)

    def _note_field(self, verdict: Verdict | None, now: float) -> None:
        """Track how long the field has held the robot (``verdict`` None: it is not holding it);
        past ``obstacle_patience`` the action fails, and the planner replans around the obstacle."""
        if verdict is None:
            if self._blocked_since is not None:
                self._blocked_since = None
                self.driver.note("")
                self.log.info("robot %s: the way is clear again", self.robot)
            return
        if self._blocked_since is None:
            self._blocked_since = now
            self.count("field_stops")
            self.log.info("robot %s: obstacle %.2f m ahead: stopped", self.robot, verdict.clearance)
        self.driver.note(f"obstacle {max(verdict.clearance, 0.0):.2f} m ahead")
        if now - self._blocked_since > self.link.obstacle_patience and self.driver.phase == "drive":
            self.driver.refuse(
                f"blocked: an obstacle {max(verdict.clearance, 0.0):.2f} m ahead for {self.link.obstacle_patience:g} s"
            )
            self.count("field_give_ups")
            self._blocked_since = None

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
        # A TwistStamped carries the robot computer's clock (Unix time): diff_drive_controller drops
        # commands older than its cmd_vel_timeout by that clock.
        self._cmd_vel.publish(ros.cmd_vel(self._cmd_vel_type, v, omega, time.time(), self.link.base_frame))

    def _publish_pose(self, velocity: tuple[float, float]) -> None:
        if self.pose is None:
            return
        now, wall = self.clock.now(), time.monotonic()
        due = now - self._last_pose_pub[0] >= POSE_PERIOD - 1e-9 and wall - self._last_pose_pub[1] >= POSE_PERIOD
        x, y, theta = self.pose
        last = self._last_pose
        moved = last is None or math.dist((x, y), last[:2]) >= MOVED or abs(wrap(theta - last[2])) >= TURNED
        if not (due or moved or self.driver.changed):
            return
        self._last_pose_pub, self._last_pose = (now, wall), self.pose
        self.publish(
            self.keys.robot_pose(self.robot),
            RobotPose(robot=self.robot, x=x, y=y, theta=theta, vel=velocity[0], omega=velocity[1]),
        )

    def _publish_status(self, force: bool = False) -> None:
        if not (force or self.driver.changed):
            return
        self.publish(self.keys.robot_status(self.robot), self.driver.status(getattr(self.clock, "world_version", 0)))

    def _publish_traffic(self, force: bool = False) -> None:
        traffic = self.driver.traffic(force=force)
        if traffic is not None:
            self.publish(self.keys.robot_traffic(self.robot), traffic)

    def _heartbeat(self) -> None:
        """Status and traffic again, for late joiners (and the others' watch of this robot)."""
        self._publish_status(force=True)
        self._publish_traffic(force=True)


def _compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """Pose ``b`` given in the frame whose pose is ``a``, in ``a``'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])


def _between(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """Pose ``b`` in the frame of pose ``a`` (both in one frame): how far the robot moved from a to b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])
