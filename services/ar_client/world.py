"""The AR client's picture of the world: robot poses, statuses, intents and door states.

Poses keep a short history per robot, so a camera frame is drawn with the poses of its capture
time (the newest stamped at or before it), not with whatever came in while it was processed: the
robots drawn then match the image, and a recorded run replayed into a fresh client draws the same.

A :class:`WorldView` is fed from Zenoh messages by the service (or from a ``STATE.json`` file by
``arroch ar render``) and read by the pipeline through :meth:`WorldView.snapshot`, an immutable copy
taken under a lock, so a drawing thread never sees a half-applied update.

``STATE.json`` (for ``arroch ar render``)::

    {
      "time": 12.0,                                  # site-clock "now" for the time marks (optional, default 0)
      "poses":   {"r0": [x, y, theta], ...},         # robot poses (metres, radians)
      "intents": {"r0": [[t, x, y, theta], ...]},    # trajectories, t on the site clock
      "doors":   {"d_storage": true, ...},           # true = open, false = closed
      "status":  {"r0": "waiting_at_door", ...}      # optional RobotStatus states
    }
"""

from __future__ import annotations

import bisect
import math
import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol.messages import ROBOT_STATES, DoorState, Intent, RobotPose, RobotStatus

POSE_HISTORY = 100  # poses kept per robot (chosen: 5 s at the sim's default 20 Hz, past any frame's latency)


@dataclass(frozen=True)
class RobotState:
    x: float
    y: float
    theta: float
    state: str = ""  # RobotStatus.state, "" until one arrives
    stamp: float = 0.0


@dataclass(frozen=True)
class WorldSnapshot:
    now: float
    robots: Mapping[str, RobotState] = field(default_factory=dict)
    intents: Mapping[str, np.ndarray] = field(default_factory=dict)  # rid -> rows (N, 4) [t, x, y, theta]
    doors: Mapping[str, DoorState] = field(default_factory=dict)  # only doors with a known state

    @property
    def open_doors(self) -> set[str]:
        return {d for d, s in self.doors.items() if s.open}


class WorldView:
    """Thread-safe holder of the latest world state seen on the wire."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._poses: dict[str, deque[RobotPose]] = {}  # rid -> poses, oldest first, stamps never decreasing
        self._status: dict[str, str] = {}
        self._intents: dict[str, np.ndarray] = {}
        self._doors: dict[str, DoorState] = {}

    # ------------------------------------------------------------------ updates from messages

    def on_pose(self, msg: RobotPose, key: str = "") -> None:
        with self._lock:
            kept = self._poses.setdefault(msg.robot, deque(maxlen=POSE_HISTORY))
            if not kept or msg.stamp >= kept[-1].stamp:  # an older sample overtaken on the wire is ignored
                kept.append(msg)

    def on_status(self, msg: RobotStatus, key: str = "") -> None:
        with self._lock:
            self._status[msg.robot] = msg.state

    def on_intent(self, msg: Intent, key: str = "") -> None:
        rows = np.asarray(msg.trajectory, dtype=np.float64).reshape(-1, 4)
        with self._lock:
            self._intents[msg.robot] = rows

    def on_door(self, msg: DoorState, key: str = "") -> None:
        with self._lock:
            self._doors[msg.door] = msg

    # ------------------------------------------------------------------ reading

    def follow(self, service: Any) -> None:
        """Subscribe ``service`` (a protocol Service) to everything this view shows: poses (latest
        only), statuses, intents and door states of its namespace."""
        keys = service.keys
        # inline, not latest: every pose goes into the history (a frame is drawn at its own time)
        service.subscribe(keys.robot_pose("*"), RobotPose, self.on_pose, inline=True)
        service.subscribe(keys.robot_status("*"), RobotStatus, self.on_status)
        service.subscribe(keys.intent("*"), Intent, self.on_intent)
        service.subscribe(keys.door_state("*"), DoorState, self.on_door)

    def snapshot(self, now: float, at: float | None = None) -> WorldSnapshot:
        """The world to draw at ``now``, with each robot's newest pose stamped at or before ``at``
        (a frame's capture time; its oldest kept pose when all are later; None: the newest)."""
        with self._lock:
            robots = {}
            for rid, kept in self._poses.items():
                p = kept[-1] if at is None else kept[max(bisect.bisect_right(kept, at, key=_stamp) - 1, 0)]
                robots[rid] = RobotState(p.x, p.y, p.theta, self._status.get(rid, ""), p.stamp)
            return WorldSnapshot(now=now, robots=robots, intents=dict(self._intents), doors=dict(self._doors))

    def open_doors(self) -> set[str]:
        with self._lock:
            return {d for d, s in self._doors.items() if s.open}

    # ------------------------------------------------------------------ STATE.json

    @staticmethod
    def from_state(data: Mapping[str, Any]) -> tuple[WorldView, float]:
        """A view filled from a ``STATE.json`` document (shape in the module docstring) and its time.

        Raises ``ValueError`` naming the offending entry.
        """
        if not isinstance(data, Mapping):
            raise ValueError("state: the document must be a JSON object")
        view = WorldView()
        now = _number(data.get("time", 0.0), "time")
        for rid, pose in _mapping(data.get("poses", {}), "poses").items():
            if not isinstance(pose, (list, tuple)) or len(pose) != 3:
                raise ValueError(f"state: poses.{rid} must be [x, y, theta]")
            x, y, th = (_number(v, f"poses.{rid}") for v in pose)
            view.on_pose(RobotPose(robot=str(rid), x=x, y=y, theta=th))
        for rid, rows in _mapping(data.get("intents", {}), "intents").items():
            if not isinstance(rows, list) or any(not isinstance(r, (list, tuple)) or len(r) != 4 for r in rows):
                raise ValueError(f"state: intents.{rid} must be a list of [t, x, y, theta] rows")
            traj = [[_number(v, f"intents.{rid}") for v in r] for r in rows]
            view.on_intent(Intent(robot=str(rid), trajectory=traj))
        for did, state in _mapping(data.get("doors", {}), "doors").items():
            if isinstance(state, str) and state in ("open", "closed"):
                state = state == "open"
            if not isinstance(state, bool):
                raise ValueError(f"state: doors.{did} must be true (open) or false (closed)")
            view.on_door(DoorState(door=str(did), open=state))
        for rid, state in _mapping(data.get("status", {}), "status").items():
            if state not in ROBOT_STATES:
                raise ValueError(f"state: status.{rid} must be one of {', '.join(ROBOT_STATES)}")
            view.on_status(RobotStatus(robot=str(rid), state=state))
        return view, now


def _mapping(value: Any, name: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ValueError(f"state: {name} must be an object")
    return value


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"state: {name} must hold finite numbers")
    return float(value)


def _stamp(pose: RobotPose) -> float:
    return pose.stamp
