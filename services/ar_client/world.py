"""The AR client's picture of the world: the latest robot poses, statuses, intents and door states.

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

import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol.messages import ROBOT_STATES, DoorState, Intent, RobotPose, RobotStatus


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
        self._poses: dict[str, RobotPose] = {}
        self._status: dict[str, str] = {}
        self._intents: dict[str, np.ndarray] = {}
        self._doors: dict[str, DoorState] = {}

    # ------------------------------------------------------------------ updates from messages

    def on_pose(self, msg: RobotPose, key: str = "") -> None:
        with self._lock:
            old = self._poses.get(msg.robot)
            if old is None or msg.stamp >= old.stamp:  # an older sample overtaken on the wire is ignored
                self._poses[msg.robot] = msg

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
        service.subscribe(keys.robot_pose("*"), RobotPose, self.on_pose, latest=True)
        service.subscribe(keys.robot_status("*"), RobotStatus, self.on_status)
        service.subscribe(keys.intent("*"), Intent, self.on_intent)
        service.subscribe(keys.door_state("*"), DoorState, self.on_door)

    def snapshot(self, now: float) -> WorldSnapshot:
        with self._lock:
            robots = {
                rid: RobotState(p.x, p.y, p.theta, self._status.get(rid, ""), p.stamp) for rid, p in self._poses.items()
            }
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
