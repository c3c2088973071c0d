"""Robots the simulator does not drive: real robots (``--robots none``) and simulated ROS 2 bases
(``--ros2-bases``).

Either way the robot's own driver (``arroch robot --ros2``) executes its commands and publishes its
pose and status; the simulator keeps the rest of the world (doors, objects, the human, world
versions, metrics) and learns what the robot does from its ``RobotStatus``: a new object carried or
delivered, an action done or failed, waiting at a door (turned into the same events and world
versions its own robots produce). Automatic doors open for it as for a simulated robot: while it is
within ``auto_open_distance`` of a door its current command's trajectory goes through.

- ``--robots none``: its position is the last ``RobotPose`` its driver published.
- ``--ros2-bases``: the simulator plays the ROS 2 mobile base. It subscribes to the robot's
  ``cmd_vel`` (``geometry_msgs/Twist`` or ``TwistStamped``, as the robot's ``cmd_vel_type``) and
  integrates the last command each tick (the unicycle's exact arc, as the simulator's own robots
  move; a command older than :data:`CMD_VEL_TIMEOUT` site seconds counts as zero, the usual base
  watchdog), and publishes ``nav_msgs/Odometry`` in the odom frame (whose origin is the robot's
  start pose) every tick, and, for a robot with a ``scan_topic``, a ``sensor_msgs/LaserScan`` of
  the walls, door leaves, other robots and the human (:mod:`.scan`) just before it. In
  lockstep, while the driver says the robot executes an action, each tick waits for the Twist that
  answers the last odometry (sending the odometry again after :data:`REASK` without one: either
  may have been dropped), so the driver's executor, the simulator's own, controls the robot at
  every tick as for a simulated robot, whatever the machine's load.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

from protocol.events import ActionDone, ActionFailed, Delivered, Loaded, WaitingAtDoor
from protocol.messages import RobotCommand, RobotPose, RobotStatus
from runtime.executor import Outcome, Robot, outcome_of
from runtime.plane import wrap
from runtime.pursuit import Path, integrate, path_crossings
from runtime.ros2 import types as ros
from runtime.ros2.config import Ros2Config
from runtime.ros2.node import RosNode, RosPublisher

from .human import HUMAN_RADIUS
from .scan import Scanner

log = logging.getLogger("arroch.sim")

HEARTBEAT = 1.0  # wall s between odometry messages of bases at rest
ANSWER_TIMEOUT = 2.0  # wall s lockstep waits for a driver's Twist before going on without it
# wall s after which lockstep sends a base's odometry again while no Twist answered it: ROS 2
# publishers drop samples under congestion (rmw_zenoh's keep-last publishers do), the odometry's
# or the Twist, and a wait for an answer that will never come would stall site time
REASK = 0.25
CMD_VEL_TIMEOUT = 0.5  # s of site time after which a base stops on its own without a new Twist
# Driver states in which its robot does something as site time passes (drives, dwells): in lockstep
# every tick waits for its answer then, so the driver acts at the tick it must. A robot waiting at a
# door is not waited for (robots wait for the human's door for minutes): it hears of the door's
# opening a few ticks late, as a real robot would. A base that moves is waited for whatever its
# driver's state (a parked robot making way for another drives off its way).
EXECUTING = ("moving", "loading", "unloading")


@dataclass
class RosBase:
    """The simulated ROS 2 side of one robot: the Twist it obeys, the odometry it reports."""

    odom: RosPublisher
    origin: tuple[float, float, float]  # odom frame in the map (the start pose)
    odom_frame: str
    base_frame: str
    cmd_vel_type: str = ros.TWIST
    scan: RosPublisher | None = None  # its laser scanner's LaserScan (None: it has none)
    v: float = 0.0
    omega: float = 0.0
    twist_at: float = -math.inf  # site time the last Twist arrived
    awaiting: bool = False  # lockstep: an odometry went out and its Twist has not come yet
    awaiting_since: float = 0.0  # wall (monotonic) time it went out
    asked_at: float = 0.0  # wall time the odometry awaiting an answer was last sent
    silent: bool = False  # its driver missed ANSWER_TIMEOUT: not waited for until it answers again
    twists: int = 0

    def velocity(self, now: float) -> tuple[float, float]:
        if now - self.twist_at > CMD_VEL_TIMEOUT + 1e-9:
            return 0.0, 0.0
        return self.v, self.omega

    def publish_odometry(self, now: float, robot: Robot) -> None:
        ox, oy, oth = self.origin
        dx, dy = robot.x - ox, robot.y - oy
        c, s = math.cos(oth), math.sin(oth)
        self.odom.publish(
            ros.odometry(
                now,
                self.odom_frame,
                self.base_frame,
                c * dx + s * dy,
                -s * dx + c * dy,
                wrap(robot.theta - oth),
                robot.v,
                robot.omega,
            )
        )


@dataclass
class ExternalRobot:
    """One robot executed elsewhere; the engine steps it through :meth:`step`."""

    engine: Any
    id: str
    base: RosBase | None = None  # None: a real robot (pose from its RobotPose)
    pose: RobotPose | None = None
    door_route: list[str] = field(default_factory=list)  # doors the current command's trajectory crosses
    reported_action: int = 0  # the last action id whose end was turned into an event
    waiting_reported: tuple[int, str] = (0, "")
    driver_state: str = ""
    _pending: list[Outcome] = field(default_factory=list)

    # ------------------------------------------------------------------ from the outside

    def command(self, cmd: RobotCommand) -> None:
        """The planner's command for this robot (the driver executes it; the sim needs its doors)."""
        if cmd.trajectory:
            path = Path(cmd.trajectory)
            self.door_route = [
                d
                for _, d in path_crossings(path, {d.id: d.opening.endpoints for d in self.engine.doors.doors.values()})
            ]
        else:
            self.door_route = []
        if cmd.action in ("approach", "opendoor") and cmd.args and cmd.args[0] in self.engine.doors:
            self.door_route.append(cmd.args[0])

    def on_status(self, st: RobotStatus) -> None:
        robot: Robot = self.engine.robots[self.id]
        objects = self.engine.objects
        self.driver_state = st.state
        for oid in st.carrying:
            if oid not in robot.carrying and oid in objects:
                objects.pick(oid, self.id)
                self._pending.append(outcome_of(robot, Loaded, st, object=oid))
        for oid in st.delivered:
            if oid not in robot.delivered and oid in objects:
                objects.place(oid, robot.x, robot.y, delivered_at=self.engine.time)
                self._pending.append(outcome_of(robot, Delivered, st, object=oid))
        robot.carrying, robot.delivered = list(st.carrying), list(st.delivered)
        robot.state, robot.waiting_door, robot.detail, robot.progress = (
            st.state,
            st.waiting_door,
            st.detail,
            st.progress,
        )
        robot.last_action_id = max(robot.last_action_id, st.action_id)
        if st.state == "waiting_at_door" and (st.action_id, st.waiting_door) != self.waiting_reported:
            self.waiting_reported = (st.action_id, st.waiting_door)
            self._pending.append(outcome_of(robot, WaitingAtDoor, st, door=st.waiting_door))
        if st.action_id > self.reported_action and (
            st.state in ("done", "failed") or (st.state == "idle" and st.action == "stop")
        ):
            self.reported_action = st.action_id
            if st.state == "failed":
                self._pending.append(outcome_of(robot, ActionFailed, st, new_world=True, reason=st.detail or "failed"))
            else:
                # A stop is what the planner asked for: no new world version (as the simulator's robots).
                self._pending.append(outcome_of(robot, ActionDone, st, new_world=st.action != "stop"))

    def on_pose(self, pose: RobotPose) -> None:
        self.pose = pose

    def on_twist(self, msg: Any, now: float) -> bool:
        """Obey a Twist (or TwistStamped); False (ignored) for one that is not finite."""
        assert self.base is not None
        v, omega = ros.twist_of(msg, self.base.cmd_vel_type)
        if not (math.isfinite(v) and math.isfinite(omega)):
            return False
        self.base.v, self.base.omega = v, omega
        self.base.twist_at = now
        self.base.awaiting = False
        self.base.silent = False
        self.base.twists += 1
        return True

    # ------------------------------------------------------------------ the engine's tick

    def step(self, robot: Robot, now: float, dt: float) -> list[Outcome]:
        if self.base is not None:
            v, omega = self.base.velocity(now)
            robot.x, robot.y, robot.theta = integrate(robot.x, robot.y, robot.theta, v, omega, dt)
            robot.v, robot.omega = v, omega
        elif self.pose is not None:
            robot.x, robot.y, robot.theta, robot.v, robot.omega = (
                self.pose.x,
                self.pose.y,
                self.pose.theta,
                self.pose.vel,
                self.pose.omega,
            )
        if robot.state == "waiting_at_door":
            robot.wait_time += dt
        self._open_doors_ahead(robot)
        out, self._pending = self._pending, []
        return out

    def _open_doors_ahead(self, robot: Robot) -> None:
        engine = self.engine
        reach = engine.config.auto_open_distance + engine.site.params.robot_radius
        for door_id in self.door_route:
            if math.dist((robot.x, robot.y), engine.doors[door_id].opening.center) <= reach:
                engine.doors.request_open(door_id, self.id)


class ExternalRobots:
    """Every robot the simulator does not drive, with its Zenoh (and ROS 2) I/O."""

    def __init__(self, engine: Any, robots: list[str], *, ros2: Ros2Config | None, lockstep: bool) -> None:
        self.engine = engine
        self.ros2 = ros2
        self.lockstep = lockstep
        self.robots = {rid: ExternalRobot(engine, rid) for rid in robots}
        for rid in robots:
            engine.external[rid] = self.robots[rid]
        self.scanner: Scanner | None = None
        self.count: Any = lambda counter: None  # the service's counters (set up in setup())

    def setup(self, service: Any) -> None:
        keys = service.keys
        self.count = service.count
        for rid, ext in self.robots.items():
            service.subscribe(
                keys.robot_status(rid), RobotStatus, lambda st, key, ext=ext: ext.on_status(st), ordered=True
            )
            if self.ros2 is None:
                service.subscribe(keys.robot_pose(rid), RobotPose, lambda p, key, ext=ext: ext.on_pose(p), latest=True)
                continue
            link = self.ros2.link(rid)
            node = RosNode(service, self.ros2.naming(rid), f"arroch_sim_base_{rid}", link.namespace)
            start = self.engine.site.robots[rid].start
            scan = None
            if link.scan_topic:
                scan = node.publisher(link.scan_topic, ros.LASER_SCAN)
                self.scanner = self.scanner or Scanner(self.engine.site)
            ext.base = RosBase(
                node.publisher(link.pose_topic, ros.ODOMETRY),
                tuple(start),
                link.odom_frame,
                link.base_frame,
                link.cmd_vel_typename,
                scan,
            )
            node.subscribe(
                link.cmd_vel,
                link.cmd_vel_typename,
                lambda msg, key, ext=ext: ext.on_twist(msg, self.engine.time) or service.count("twists_not_finite"),
            )
        if self.ros2 is not None:
            # A driver started while time stands still (lockstep waiting for a plan) still learns where its
            # robot is; while the driver moves the robot, every tick's odometry does that.
            service.every(HEARTBEAT, self.heartbeat, first=0.0)

    def heartbeat(self) -> None:
        now = self.engine.time
        for rid, ext in self.robots.items():
            if ext.base is not None and ext.driver_state not in EXECUTING:
                self.publish_scan(rid, now)
                ext.base.publish_odometry(now, self.engine.robots[rid])

    def publish_scan(self, rid: str, now: float) -> None:
        """The robot's LaserScan now (before its odometry: the driver answers that with the scan in hand)."""
        base = self.robots[rid].base
        if base is None or base.scan is None or self.scanner is None:
            return
        engine = self.engine
        robot = engine.robots[rid]
        radius = engine.site.params.robot_radius
        discs = [(r.x, r.y, radius) for r in engine.robots.values() if r.id != rid]
        hx, hy, _ = engine.human_pose()
        discs.append((hx, hy, HUMAN_RADIUS))
        ranges = self.scanner.ranges((robot.x, robot.y, robot.theta), discs, engine.doors)
        base.scan.publish(
            ros.laser_scan(
                now,
                base.base_frame,
                self.scanner.angle_min,
                self.scanner.angle_increment,
                ranges,
                self.scanner.config.range_max,
            )
        )

    def after_tick(self) -> None:
        """Publish each base's odometry (the robots' new poses); in lockstep, wait for the answers
        of the bases whose driver executes an action, and of the bases that move."""
        now = self.engine.time
        for rid, ext in self.robots.items():
            if ext.base is not None:
                self.publish_scan(rid, now)
                ext.base.publish_odometry(now, self.engine.robots[rid])
                base = ext.base
                moving = base.velocity(now) != (0.0, 0.0)
                base.awaiting = self.lockstep and (ext.driver_state in EXECUTING or moving) and not base.silent
                base.awaiting_since = base.asked_at = time.monotonic()

    def blocker(self) -> str:
        """What lockstep waits for from the robots' drivers ("" for nothing)."""
        wall = time.monotonic()
        for rid, ext in self.robots.items():
            base = ext.base
            if base is not None and base.awaiting and wall - base.awaiting_since > ANSWER_TIMEOUT:
                # A driver that died or hangs must not stop the world: its base stops on its own (no Twist).
                log.warning(
                    "no cmd_vel from %s's driver for %.0f s: lockstep goes on without waiting for it "
                    "until it answers again",
                    rid,
                    ANSWER_TIMEOUT,
                )
                base.awaiting, base.silent = False, True
            elif base is not None and base.awaiting and wall - base.asked_at >= REASK:
                base.asked_at = wall  # the odometry or its Twist was dropped, or is late: ask again
                self.count("odometry_sent_again")
                self.publish_scan(rid, self.engine.time)
                base.publish_odometry(self.engine.time, self.engine.robots[rid])
        waiting = [rid for rid, ext in self.robots.items() if ext.base is not None and ext.base.awaiting]
        return f"cmd_vel of {', '.join(waiting)} answering the last odometry" if waiting else ""
