"""The other robots as a process that drives one robot sees them: from their messages over Zenoh.

The executor's rules read every robot's position and phase (:attr:`RobotExecutor.fleet`). A robot
process (``arroch robot``) hears the others' ``RobotPose`` (where each is), ``RobotStatus`` (what it
does: its state read as the executor's phase, :func:`phase_of`) and ``RobotTraffic`` (its rows of
the rules' shared tables, :mod:`.traffic`); :meth:`Peers.refresh` puts them into the executor
before each step. A robot is in the fleet from its first pose on.

Where each robot is when a step is decided is predicted from its last pose: moved on along the arc
its velocity describes for the pose's age on the site clock and ``lead`` seconds more (until the
step's Twist has acted: :mod:`services.robot.driver`), at most ``MAX_PREDICTION``. A robot at rest
stays where it was seen.

A robot not heard of for ``timeout`` wall seconds (its process died, its link is down: it publishes
its traffic at least once a second) is a *parked obstacle*: it stays where it was last seen, waits
for nothing and asks nothing (its rows are dropped), so the rules treat it as a robot whose action
is over: a robot kept back by it drives around it, asks it to make way, and in the end gives up and
lets the planner plan again. It is never touched: solid bodies hold against it as against any robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from protocol.messages import RobotPose, RobotStatus, RobotTraffic
from protocol.site.model import Site
from runtime.pursuit import integrate

from .executor import Robot, RobotExecutor
from .traffic import adopt, forget, traffic_problem

PEER_TIMEOUT = 3.0  # wall s without a message from a robot after which it is a parked obstacle
MAX_PREDICTION = 0.5  # s a robot's pose is carried on at most (a late pose is not a plan)
PARKED_PHASE = "idle"  # the phase of a robot nobody has heard of lately (or whose status never came)


def phase_of(status: RobotStatus | None) -> str:
    """The executor's phase of a robot whose latest status is ``status``."""
    if status is None:
        return PARKED_PHASE
    state = status.state
    if state == "moving":
        return "drive"
    if state == "waiting_at_door":
        # waiting for the door it was told to open; else held at a closed door on its way, still driving
        return "wait_open" if status.action == "opendoor" else "drive"
    if state in ("loading", "unloading"):
        return "dwell"
    return state  # idle, done, failed


@dataclass
class Peer:
    robot: Robot  # as the executor reads it: the pose predicted for the step
    pose: RobotPose | None = None  # the last pose heard (it is in the fleet from the first on)
    status: RobotStatus | None = None
    traffic: RobotTraffic | None = None
    heard: float = -math.inf  # wall s of its last message
    stale: bool = False


class Peers:
    def __init__(self, me: str, site: Site, *, lead: float = 0.0, timeout: float = PEER_TIMEOUT) -> None:
        self.me = me
        self.site = site
        self.lead = lead  # s a pose is carried on beyond its age
        self.timeout = timeout
        self.peers: dict[str, Peer] = {}

    def _peer(self, robot: str, wall: float) -> tuple[Peer | None, str]:
        """The robot's entry, heard of now; or None and why its message is refused."""
        if robot == self.me:
            return None, f"robot: {robot!r} is this process's own robot"
        if robot not in self.site.robots:
            return None, f"robot: no robot {robot!r} on site {self.site.name}"
        peer = self.peers.get(robot)
        if peer is None:
            peer = self.peers[robot] = Peer(Robot(robot, *self.site.robots[robot].start))
        peer.heard = wall
        return peer, ""

    def pose(self, pose: RobotPose, wall: float) -> str:
        """Another robot's pose; returns why it was refused ("" when taken)."""
        peer, problem = self._peer(pose.robot, wall)
        if peer is not None:
            peer.pose = pose
        return problem

    def status(self, status: RobotStatus, wall: float) -> str:
        """Another robot's status; why it was refused, or ""."""
        peer, problem = self._peer(status.robot, wall)
        if peer is not None:
            peer.status = status
        return problem

    def traffic(self, traffic: RobotTraffic, wall: float) -> str:
        """Another robot's rows of the traffic tables; why they were refused, or ""."""
        problem = traffic_problem(traffic, self.site)
        if problem:
            return problem
        peer, problem = self._peer(traffic.robot, wall)
        if peer is not None:
            peer.traffic = traffic
        return problem

    def fleet(self, own: Robot) -> dict[str, Robot]:
        """Every robot the executor knows where it is, ``own`` among them, in id order (as the simulator's)."""
        robots = {own.id: own, **{rid: p.robot for rid, p in self.peers.items() if p.pose is not None}}
        return {rid: robots[rid] for rid in sorted(robots)}

    def heard(self) -> list[tuple[float, float]]:
        """Where the robots heard of lately are, as the last refresh placed them."""
        return [(p.robot.x, p.robot.y) for p in self.peers.values() if p.pose is not None and not p.stale]

    def refresh(self, executor: RobotExecutor, now: float, wall: float) -> list[str]:
        """Put what the other robots said into ``executor`` before a step at site time ``now``: each
        one's predicted pose, its phase and its rows of the tables; for one not heard of for
        ``timeout`` (wall time), its last pose, parked and no rows. Returns the robots that went
        stale since the last refresh."""
        went: list[str] = []
        for rid, peer in self.peers.items():
            fresh = wall - peer.heard <= self.timeout
            if not fresh and not peer.stale:
                went.append(rid)
            peer.stale = not fresh
            self._place(peer, now if fresh else None)
            peer.robot.phase = phase_of(peer.status) if fresh else PARKED_PHASE
            if fresh and peer.traffic is not None:
                adopt(executor, peer.traffic, now)
            else:
                forget(executor, rid)
        return went

    def _place(self, peer: Peer, now: float | None) -> None:
        """Where the executor sees ``peer``: its last pose carried on to ``now`` and ``lead`` beyond
        (``now`` None: where it was seen)."""
        pose = peer.pose
        if pose is None:
            return
        ahead = 0.0 if now is None else min(max(now - pose.stamp, 0.0) + self.lead, MAX_PREDICTION)
        x, y, theta = integrate(pose.x, pose.y, pose.theta, pose.vel, pose.omega, ahead)
        robot = peer.robot
        robot.x, robot.y, robot.theta, robot.v, robot.omega = x, y, theta, pose.vel, pose.omega
