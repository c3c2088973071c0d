"""Mission progress as the supervisor sees it from ``event`` and ``robot/*/status`` messages.

Deliveries per robot (from ``delivered`` events and the ``delivered`` lists in statuses, so a
missed message is made up by the next status), door openings (all, and the human's among them),
plan conflicts, the site-clock time, and the final metrics carried by the ``mission_done`` event.
Rendering is kept apart from the bookkeeping so both the one-line and the bar form show the same
numbers; the final metrics are rendered by :mod:`.metrics_table`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocol.events import DoorOpened, data_to_wire
from protocol.messages import Event, RobotStatus

from .metrics_table import metrics_table


@dataclass
class RobotProgress:
    total: int | None = None  # objects this robot must deliver (from the site), when known
    delivered: set[str] = field(default_factory=set)
    state: str = "?"
    waiting_door: str = ""


class MissionProgress:
    def __init__(self, totals: dict[str, int] | None = None) -> None:
        self.robots: dict[str, RobotProgress] = {rid: RobotProgress(total=n) for rid, n in (totals or {}).items()}
        self.door_openings = 0  # every door_opened event: robots' automatic doors and the human's
        self.human_door_openings = 0  # those the human opened (the paper's measure)
        self.doors: dict[str, int] = {}
        self.conflicts = 0
        self.events = 0
        self.sim_time = 0.0
        self.metrics: dict[str, Any] | None = None

    @property
    def done(self) -> bool:
        return self.metrics is not None

    def _robot(self, rid: str) -> RobotProgress:
        return self.robots.setdefault(rid, RobotProgress())

    def on_status(self, msg: RobotStatus) -> None:
        robot = self._robot(msg.robot)
        robot.state = msg.state
        robot.waiting_door = msg.waiting_door
        robot.delivered.update(msg.delivered)
        self.sim_time = max(self.sim_time, msg.stamp)

    def on_event(self, msg: Event) -> None:
        self.events += 1
        self.sim_time = max(self.sim_time, msg.stamp)
        if msg.kind == "delivered" and msg.robot:
            self._robot(msg.robot).delivered.add(msg.object or f"#{len(self._robot(msg.robot).delivered)}")
        elif msg.kind == "door_opened":
            self.door_openings += 1
            self.human_door_openings += isinstance(msg.data, DoorOpened) and msg.data.by == "human"
            if msg.door:
                self.doors[msg.door] = self.doors.get(msg.door, 0) + 1
        elif msg.kind == "plan_conflict":
            self.conflicts += 1
        elif msg.kind == "mission_done":
            self.metrics = data_to_wire(msg.data)

    def on_time(self, now: float) -> None:
        self.sim_time = max(self.sim_time, now)

    # ------------------------------------------------------------------ rendering

    def delivered(self) -> tuple[int, int | None]:
        done = sum(len(r.delivered) for r in self.robots.values())
        totals = [r.total for r in self.robots.values()]
        return done, (sum(t for t in totals if t is not None) if totals and None not in totals else None)

    def _robots_text(self) -> str:
        parts = []
        for rid in sorted(self.robots):
            robot = self.robots[rid]
            count = f"{len(robot.delivered)}/{robot.total}" if robot.total is not None else str(len(robot.delivered))
            state = (
                f"waiting at {robot.waiting_door}"
                if robot.state == "waiting_at_door" and robot.waiting_door
                else robot.state
            )
            parts.append(f"{rid} {count} {state}")
        return ", ".join(parts) or "no robot heard yet"

    def line(self) -> str:
        done, total = self.delivered()
        delivered = f"{done}/{total}" if total is not None else str(done)
        text = (
            f"t={self.sim_time:.1f}s delivered {delivered} [{self._robots_text()}] "
            f"door openings {self.door_openings} (by the human {self.human_door_openings})"
        )
        if self.conflicts:
            text += f" plan conflicts {self.conflicts}"
        return text + (" (mission done)" if self.done else "")

    def bar(self, width: int = 24) -> str:
        done, total = self.delivered()
        if total:
            filled = round(width * min(done / total, 1.0))
            gauge = f"[{'#' * filled}{'.' * (width - filled)}] {done}/{total} delivered"
        else:
            gauge = f"{done} delivered"
        return f"{gauge} | t={self.sim_time:.0f}s | doors {self.door_openings} | {self._robots_text()}"

    def metrics_text(self) -> str:
        """The final metrics as a table: rounded, with units and what each figure means."""
        return metrics_table(self.metrics or {})
