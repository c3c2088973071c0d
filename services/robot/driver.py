"""Executing one robot's RobotCommands with velocities: the decisions of ``arroch robot``, no I/O.

The driver gets the robot's pose (map frame) as often as the robot reports it and answers each one
with the velocity to send, ``(v, omega)``. It follows a command's trajectory with the simulator's
pure-pursuit controller (:mod:`runtime.pursuit`), one control period per pose, so a robot driven
through ROS 2 makes the moves a simulated one makes. Phases, as in the simulator: *drive*, then
*wait for the door* (``opendoor``) or *dwell* (``load``/``unload``), then done.

It commands zero velocity whenever the robot must not move: no command or the command is over,
a command it refused, a closed door ahead (it holds ``radius + stop_margin`` short of the leaf's
line, ``waiting_at_door``), a hold in the trajectory not over yet (the planner making it give way
to another robot, :meth:`runtime.pursuit.Path.hold_limit`), and whenever the service tells it to
hold (stale pose, planner lost, shutting down).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from msgspec.structs import replace

from protocol.messages import RobotCommand, RobotStatus
from protocol.site.model import Site
from runtime.execution import REACH, START_TOLERANCE, command_problem, dwell_problem
from runtime.pursuit import ControllerConfig, Path, PurePursuit, crossing_behind, path_crossings


@dataclass(frozen=True)
class DriverConfig:
    controller: ControllerConfig = ControllerConfig()
    radius: float = 0.25
    load_time: float = 10.0
    stop_margin: float = 0.15  # m between a waiting robot's disc and a closed leaf's line (as the simulator)
    start_tolerance: float = START_TOLERANCE
    reach: float = REACH
    capacity: int = 1
    control_period: float = 0.05  # s between poses: the controller's step


class Driver:
    """One robot's command execution. Its state is the RobotStatus it reports (:attr:`s`);
    ``changed`` is set whenever that changed."""

    def __init__(self, robot: str, site: Site, config: DriverConfig) -> None:
        self.robot = robot
        self.site = site
        self.config = config
        self.s = RobotStatus(robot=robot, state="idle")
        self.command: RobotCommand | None = None
        self.last_action_id = 0
        self.phase = "idle"  # idle, drive, wait_open, dwell, done, failed
        self._follower: PurePursuit | None = None
        self._crossings: list[tuple[float, str]] = []
        self._dwell_end = 0.0
        self._dwell_total = 0.0
        self.changed = True

    # ------------------------------------------------------------------ commands

    def assign(self, cmd: RobotCommand, pose: tuple[float, float, float] | None, now: float) -> str:
        """Take a command. Returns ``"stale"`` (not newer than the last one: ignored), ``"refused"``
        (it cannot be executed: the robot stops, state ``failed``) or ``"accepted"``."""
        if cmd.action_id <= self.last_action_id:
            return "stale"
        self.command, self.last_action_id = cmd, cmd.action_id
        self._follower, self._crossings = None, []
        self._set(
            state="moving",
            plan_id=cmd.plan_id,
            action_id=cmd.action_id,
            action=cmd.action,
            args=list(cmd.args),
            waiting_door="",
            detail="",
            progress=0.0,
        )
        self.changed = True  # a new action id even if the state stays "moving"
        if cmd.action == "stop":
            self.phase = "idle"
            self._set(state="idle", detail="stopped")
            return "accepted"
        problem = self._problem(cmd, pose)
        if problem:
            self.refuse(problem)
            return "refused"
        if cmd.trajectory:
            self._follower = PurePursuit(Path(cmd.trajectory), self.config.controller)
            self._crossings = path_crossings(self._follower.path, {d.id: d.endpoints for d in self.site.doors.values()})
        self.phase = "drive"
        return "accepted"

    def _problem(self, cmd: RobotCommand, pose: tuple[float, float, float] | None) -> str:
        if pose is None:
            return "no pose of the robot yet"
        target = cmd.args[0] if cmd.args else ""
        if cmd.action in ("load", "unload") and target not in self.site.objects:
            return f"{cmd.action}: no object {target!r}"
        if cmd.action == "load":
            if self.site.objects[target].robot != self.robot:
                return f"load: object {target!r} belongs to robot {self.site.objects[target].robot!r}"
            if target in self.s.carrying or target in self.s.delivered:
                return f"load: object {target!r} is {'delivered' if target in self.s.delivered else 'carried already'}"
            if len(self.s.carrying) >= self.config.capacity:
                return f"load: robot is full ({self.config.capacity} object(s))"
        if cmd.action == "unload" and target not in self.s.carrying:
            return f"unload: robot does not carry {target!r}"
        return command_problem(self.site, pose[0], pose[1], cmd, self.config.start_tolerance)

    def note(self, detail: str) -> None:
        """Say why the robot is not moving though it drives (the safety field: an obstacle ahead)."""
        if self.phase == "drive":
            self._set(detail=detail)

    def refuse(self, reason: str) -> None:
        self.phase = "failed"
        self._follower = None
        self._set(state="failed", waiting_door="", detail=reason)

    # ------------------------------------------------------------------ control

    def control(
        self, pose: tuple[float, float, float], now: float, door_open: Callable[[str], bool]
    ) -> tuple[float, float]:
        """The velocity (v, omega) to command now, the robot being at ``pose`` (map frame)."""
        if self.phase == "drive":
            return self._drive(pose, now, door_open)
        if self.phase == "wait_open":
            self._wait_open(door_open)
        elif self.phase == "dwell":
            self._dwell(now)
        return 0.0, 0.0

    def _drive(
        self, pose: tuple[float, float, float], now: float, door_open: Callable[[str], bool]
    ) -> tuple[float, float]:
        follower = self._follower
        if follower is None:
            self._arrived(pose, now, door_open)
            return 0.0, 0.0
        cfg = self.config
        x, y, theta = pose
        s_limit, blocking = math.inf, ""
        for s_cross, door_id in self._crossings:
            gap = self.site.doors[door_id].endpoints
            if not crossing_behind(follower.path, s_cross, gap, follower.s, x, y) and not door_open(door_id):
                s_limit, blocking = s_cross - (cfg.radius + cfg.stop_margin), door_id
                break
        hold = follower.path.hold_limit(now)
        if hold < s_limit:
            s_limit, blocking = hold, ""  # the plan says wait here (for another robot) until then
        step = follower.step(x, y, theta, cfg.control_period, s_limit)
        length = follower.path.length
        self.s.progress = min(follower.s / length, 1.0) if length > 0 else 1.0
        if step.held and not blocking:
            if self.s.state == "waiting_at_door":
                self._set(state="moving", waiting_door="")
            return 0.0, 0.0
        if step.held:
            self._set(state="waiting_at_door", waiting_door=blocking)
            return 0.0, 0.0
        if self.s.state == "waiting_at_door":
            self._set(state="moving", waiting_door="")
        if step.arrived:
            self._arrived(pose, now, door_open)
            return 0.0, 0.0
        return step.v, step.omega

    def _arrived(self, pose: tuple[float, float, float], now: float, door_open: Callable[[str], bool]) -> None:
        cmd = self.command
        assert cmd is not None
        if cmd.action in ("approach", "gothrough"):
            self._done()
        elif cmd.action == "opendoor":
            self.phase = "wait_open"
            self._wait_open(door_open)
        else:
            # An object waits where the site file puts it until its robot loads it.
            problem = dwell_problem(
                self.site, pose[0], pose[1], cmd, self.site.objects[cmd.args[0]].position, self.config.reach
            )
            if problem:
                self.refuse(problem)
                return
            self.phase = "dwell"
            self._dwell_total = cmd.duration if cmd.duration > 0 else self.config.load_time
            self._dwell_end = now + self._dwell_total
            self._set(state="loading" if cmd.action == "load" else "unloading", progress=0.0)
            self._dwell(now)

    def _wait_open(self, door_open: Callable[[str], bool]) -> None:
        cmd = self.command
        assert cmd is not None
        if door_open(cmd.args[0]):
            self._done()
        else:
            self._set(state="waiting_at_door", waiting_door=cmd.args[0])

    def _dwell(self, now: float) -> None:
        cmd = self.command
        assert cmd is not None
        left = self._dwell_end - now
        self.s.progress = min(1.0, 1.0 - left / self._dwell_total) if self._dwell_total > 0 else 1.0
        if left > 1e-9:
            return
        oid = cmd.args[0]
        if cmd.action == "load":
            self.s.carrying.append(oid)
        else:
            self.s.carrying.remove(oid)
            self.s.delivered.append(oid)
        self._done()

    def _done(self) -> None:
        self.phase = "done"
        self._follower = None
        self._set(state="done", waiting_door="", progress=1.0)

    def _set(self, **changes: object) -> None:
        for name, value in changes.items():
            if getattr(self.s, name) != value:
                setattr(self.s, name, value)
                self.changed = True

    # ------------------------------------------------------------------ reporting

    def status(self, world_version: int) -> RobotStatus:
        """A copy of the status to report, with the world version the robot last heard of."""
        s = self.s
        return replace(
            s,
            args=list(s.args),
            carrying=list(s.carrying),
            delivered=list(s.delivered),
            detail=s.detail[:512],
            progress=max(0.0, min(1.0, s.progress)),
            world_version=world_version,
        )
