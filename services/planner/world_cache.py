"""The planner's picture of the site, kept from the robots' poses and statuses and the door states.

It stores the latest of each, notes the highest world version seen, says whether a message changed
anything worth replanning for, and builds the :class:`World` snapshot a plan starts from.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from protocol.actions import Action
from protocol.messages import DoorState, RobotStatus
from protocol.site import Site

from .dispatcher import Dispatched
from .motion import polyline_distance
from .world import InProgress, RobotState, World

Pose = tuple[float, float, float]


@dataclass
class WorldCache:
    site: Site
    beside_distance: float  # how far from an opening's centre a robot beside it stands (ProblemBuilder)
    poses: dict[str, Pose] = field(default_factory=dict)
    statuses: dict[str, RobotStatus] = field(default_factory=dict)
    doors: dict[str, DoorState] = field(default_factory=dict)
    world_version: int = 0

    def note_version(self, version: int) -> bool:
        """Whether ``version`` is newer than any seen (and note it)."""
        if version <= self.world_version:
            return False
        self.world_version = version
        return True

    def set_pose_from(self, robot: str, pose: object) -> None:
        """Store the pose an event carries (``[x, y, theta]``), when it is one."""
        if (
            isinstance(pose, list)
            and len(pose) == 3
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in pose)
        ):
            self.poses[robot] = (float(pose[0]), float(pose[1]), float(pose[2]))

    def set_status(self, msg: RobotStatus) -> bool:
        """Store a robot's status; whether it changed what the planner reads of it."""
        before = self.statuses.get(msg.robot)
        self.statuses[msg.robot] = msg
        return before is None or (
            before.state,
            before.action_id,
            tuple(before.carrying),
            tuple(before.delivered),
        ) != (msg.state, msg.action_id, tuple(msg.carrying), tuple(msg.delivered))

    def set_door(self, msg: DoorState) -> bool:
        """Store a door's state; whether a human-operated door opened or closed."""
        before = self.doors.get(msg.door)
        self.doors[msg.door] = msg
        opening = self.site.openings[msg.door]
        return opening.human_operated and (before is None or before.open != msg.open)

    def missing(self) -> list[str]:
        """The robots whose pose or status has not arrived yet."""
        return [rid for rid in self.site.robots if rid not in self.poses or rid not in self.statuses]

    def off_track(self, robot: str, sent: Dispatched | None, limit: float) -> bool:
        """Whether ``robot`` is moving along the trajectory sent to it but more than ``limit`` from it."""
        status = self.statuses.get(robot)
        pose = self.poses.get(robot)
        if (
            pose is None
            or sent is None
            or len(sent.trajectory) < 2
            or status is None
            or status.state != "moving"
            or status.action_id != sent.action_id
        ):
            return False
        return polyline_distance(pose[:2], sent.trajectory) > limit

    def snapshot(self, now: float, sent: Mapping[str, Dispatched]) -> World:
        """The world at site time ``now``; ``sent`` is each robot's command being executed."""
        hold = self.site.params.door_hold_time
        robots: dict[str, RobotState] = {}
        for rid, spec in self.site.robots.items():
            pose = self.poses.get(rid, spec.start)
            status = self.statuses.get(rid)
            if status is None:
                robots[rid] = RobotState(id=rid, pose=pose)
                continue
            robots[rid] = RobotState(
                id=rid,
                pose=pose,
                carrying=frozenset(o for o in status.carrying if o in self.site.objects),
                delivered=frozenset(o for o in status.delivered if o in self.site.objects),
                beside=self._beside(status),
                in_progress=self._in_progress(status, pose, sent.get(rid), now),
            )
        open_doors = {}
        for did, ds in self.doors.items():
            opening = self.site.openings.get(did)
            if ds.open and opening is not None and opening.human_operated:
                open_doors[did] = ds.until - hold if ds.until > 0 else ds.stamp
        return World(now=now, robots=robots, open_doors=open_doors)

    def _beside(self, status: RobotStatus) -> str:
        """The opening a robot stands beside: the door it waits at, or the one its last action
        (approach or opendoor, now over) brought it to."""
        if status.state == "waiting_at_door" and status.waiting_door in self.site.openings:
            return status.waiting_door
        if (
            status.state in ("done", "idle")
            and status.action in (Action.APPROACH, Action.OPENDOOR)
            and status.args
            and status.args[0] in self.site.openings
        ):
            return status.args[0]
        return ""

    def _in_progress(self, status: RobotStatus, pose: Pose, sent: Dispatched | None, now: float) -> InProgress | None:
        """Actions that must be finished first: a gothrough while in the doorway, a load/unload in place."""
        if sent is None or status.action_id != sent.action_id or not status.args:
            return None
        if status.state in ("loading", "unloading") and status.action in (Action.LOAD, Action.UNLOAD):
            left = max(1.0 - status.progress, 0.0) * self.site.params.load_time
            return InProgress(status.action, tuple(status.args[:1]), now + left)
        if status.state == "moving" and status.action == Action.GOTHROUGH and status.args[0] in self.site.openings:
            opening = self.site.openings[status.args[0]]
            if math.dist((pose[0], pose[1]), opening.center) < self.beside_distance * 0.9 and len(sent.trajectory) >= 2:
                end = sent.trajectory[-1]
                target = self.site.room_at(end[1], end[2])
                if target is not None and target.id in opening.rooms:
                    return InProgress(Action.GOTHROUGH.value, (opening.id,), now, target.id)
        return None
