"""One real robot under the shared executor: the decisions of ``arroch robot``, no I/O.

The driver gets the robot's pose (map frame) as often as the robot reports it and answers each one
with a :class:`~runtime.pursuit.Step` decided by the simulator's own executor
(:class:`runtime.executor.RobotExecutor`, one control period per pose): the service sends the
step's ``(v, omega)`` as the robot's Twist, and the robot's next pose comes from its odometry. So a
real robot follows its trajectory, keeps holds, waits at closed doors, dwells, and yields, waits,
drives around, makes way, queues and gives up among the other robots exactly as a simulated one.

What the executor cannot see by itself comes from the service: the doors' states
(:class:`~runtime.executor.sensed.SensedDoors`), the objects as the site file and this robot know
them (:class:`~runtime.executor.sensed.SiteObjects`), and the other robots from their poses,
statuses and traffic (:class:`~runtime.executor.peers.Peers`). The driver publishes its own rows of
the traffic tables (:meth:`Driver.traffic`).

A step is decided from news a little late: the others' poses are about a control period old, and
the robot's Twist acts from its next odometry on. So the executor sees each other robot where its
last pose, carried on at its velocity, puts it ``LATE`` control periods after that pose's age
(:class:`~runtime.executor.peers.Peers`), and a driving robot stops for another robot a little
further out than in the simulator: by what a robot at full speed covers in that time, should it
start or turn meanwhile (``RobotConfig.allowance``, 0.0375 m at 0.5 m/s and 20 Hz).

The service holds the robot at zero velocity on top of this (stale pose, no planner, the laser
safety field, shutting down): then the executor is not stepped.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from msgspec.structs import astuple

from protocol.messages import RobotCommand, RobotStatus, RobotTraffic
from protocol.site.model import Site
from runtime.executor import Outcome, Robot, RobotConfig, RobotExecutor, status_message
from runtime.executor.peers import Peers
from runtime.executor.sensed import SensedDoors, SiteObjects
from runtime.executor.traffic import traffic_of
from runtime.pursuit import Step

# Control periods by which what a step is decided from lags the robots' motion: another robot's pose
# is about a period old (its odometry, then its message), and this robot's Twist acts from its next
# odometry on, half a period later on average.
LATE = 1.5


@dataclass(frozen=True)
class DriverConfig:
    executor: RobotConfig = RobotConfig()
    control_period: float = 0.05  # s between poses: the executor's step

    @staticmethod
    def for_robot(executor: RobotConfig, control_period: float) -> DriverConfig:
        """The config of a robot stepped every ``control_period`` seconds, its allowance set."""
        return DriverConfig(
            replace(executor, allowance=executor.controller.speed * LATE * control_period), control_period
        )


class Driver:
    """One robot's command execution among the others it hears of."""

    def __init__(self, robot: str, site: Site, config: DriverConfig) -> None:
        self.site = site
        self.config = config
        self.robot = Robot(robot, *site.robots[robot].start)  # moved to its first pose when one comes
        self.doors = SensedDoors(site)
        self.objects = SiteObjects(site, self.robot)
        self.executor = RobotExecutor(site, self.doors, self.objects, config.executor)
        self.peers = Peers(robot, site, lead=LATE * config.control_period)
        self.executor.fleet = self.peers.fleet(self.robot)
        self._sent: tuple | None = None  # the traffic last published, without its envelope
        self.went_stale: list[str] = []  # robots the last step found not heard of for a while

    @property
    def phase(self) -> str:
        return self.robot.phase

    @property
    def may_move(self) -> bool:
        """Whether the executor may move the robot now (it drives, or makes way for another)."""
        return self.robot.phase == "drive" or self.executor.making_way(self.robot.id)

    # ------------------------------------------------------------------ commands

    def assign(self, cmd: RobotCommand, pose: tuple[float, float, float] | None, now: float) -> str:
        """Take a command. Returns ``"stale"`` (not newer than the last one: ignored), ``"refused"``
        (it cannot be executed: the robot stops, state ``failed``) or ``"accepted"``."""
        robot = self.robot
        if cmd.action_id <= robot.last_action_id:
            return "stale"
        if pose is None:
            self.executor.refuse(robot, cmd, "no pose of the robot yet")
            return "refused"
        robot.x, robot.y, robot.theta = pose
        self.executor.assign(robot, cmd)
        return "refused" if robot.phase == "failed" else "accepted"

    def note(self, detail: str) -> None:
        """Say why the robot is not moving though it drives (the safety field: an obstacle ahead)."""
        self.executor.note(self.robot, detail)

    def refuse(self, reason: str) -> list[Outcome]:
        """The action fails (the safety field blocked the robot too long): the planner plans again."""
        return self.executor.fail(self.robot, reason)

    # ------------------------------------------------------------------ control

    def control(self, pose: tuple[float, float, float], now: float, wall: float) -> tuple[Step, list[Outcome]]:
        """The step to take now, the robot being at ``pose`` (map frame) at site time ``now`` (wall
        time ``wall`` dates the others' news), and what the step caused."""
        robot = self.robot
        self.went_stale = self.peers.refresh(self.executor, now, wall)
        self.executor.fleet = self.peers.fleet(robot)
        self.executor.make_way.prune(robot.id, now, self.executor.fleet)
        robot.x, robot.y, robot.theta = pose
        outcomes = self.executor.step(robot, now, self.config.control_period)
        return Step(robot.x, robot.y, robot.theta, robot.v, robot.omega), outcomes

    # ------------------------------------------------------------------ reporting

    @property
    def changed(self) -> bool:
        return self.robot.status_changed

    def status(self, world_version: int) -> RobotStatus:
        """The status to report (it is then no longer changed)."""
        self.robot.status_changed = False
        return status_message(self.robot, world_version)

    def traffic(self, *, force: bool = False) -> RobotTraffic | None:
        """This robot's rows of the traffic tables when they changed since the last ones (``force``:
        anyway), else None."""
        msg = traffic_of(self.executor, self.robot.id)
        content = astuple(msg)  # before the publisher stamps its envelope
        if not force and content == self._sent:
            return None
        self._sent = content
        return msg
