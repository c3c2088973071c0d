"""A study participant in place of the simulated human (``arroch sim --human participant``).

The simulator no longer decides for her: a person does, on her tablet page, and each thing she does
reaches the simulator as a ``ParticipantAction``. :class:`ParticipantHuman` meets the engine through
the interface of :class:`~services.sim.human.HumanModel` (``step``, ``pose``, ``done``,
``done_time``, ``available``, ``counters``, ``focus_report``, ``task_duration``), so the engine,
the camera and the metrics work alike; what the model draws, she decides, through :meth:`act`:

- ``go_to_door(door)``: only from her desk and only for a door she operates. Her avatar walks at
  the config's ``walk_speed`` to the point in front of the door the model uses (``to_door``, then
  ``at_door`` on arrival), where the page offers the door;
- ``open_door(door)``: only ``at_door`` at that door (the page's press-and-hold lasted
  ``open_time`` already). The door opens now (:class:`~services.sim.human.OpenDoor`) and she walks
  back on her own;
- ``back_to_desk``: she turns back without opening; from ``to_door`` the way she came (as the
  model's turn-back), from ``at_door`` the whole way;
- ``task_done``: her own task is complete (:class:`~services.sim.human.TaskDone`, once).

Anything else is refused with :class:`Refused`, naming the field at fault; nothing raises anything
else. With real doors (``--doors sensor``) there is no avatar: she walks and opens the real door,
whose sensor reports it (the engine counts those openings as hers), so her door acts are refused
and only ``task_done`` is taken.

What is not known is not made up: she declares no focus interval here (``focus_report`` is empty;
her declarations are the page's feedback, which goes to the restrictor directly), and her task's
length is only known once she says it is done: ``task_duration`` is then the site time she spent
at her desk until then (``done_time`` minus her time away), ``None`` before.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from .human import HumanAction, HumanConfig, HumanCounters, OpenDoor, TaskDone

EPS = 1e-9
HUMAN_MODES = ("simulated", "participant")  # who plays the human: the model, or a person on her page
DOOR_MODES = ("sim", "sensor")  # human-operated doors: simulated, or real ones following their sensors
DOOR_ACTS = ("go_to_door", "open_door", "back_to_desk")
ACTS = (*DOOR_ACTS, "task_done")  # what the simulator takes from her; her other acts are for the recording


class Refused(ValueError):
    """An act she cannot take now; ``field`` is the ParticipantAction field at fault."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class ParticipantHuman:
    """Her state as the simulator holds it: where her avatar is, what she has done."""

    def __init__(
        self,
        config: HumanConfig,
        desk: tuple[float, float],
        doors: dict[str, tuple[float, float]],
        *,
        sensor: bool = False,
    ) -> None:
        self.config = config
        self.desk = desk
        self.door_points = dict(doors)  # where she stands to open each door she operates
        self.walk_time = {d: math.dist(desk, p) / config.walk_speed for d, p in doors.items()}
        self.sensor = sensor  # real doors: no avatar walks; their sensors report her openings
        self.counters = HumanCounters()
        self.done_time: float | None = None
        self.place = "desk"  # desk | to_door | at_door | back (HumanState.place)
        self.door = ""  # the door she walks to, stands at or comes back from
        self.walked = 0.0  # s walked toward the door (to_door; at_door: the whole walk)
        self.left = 0.0  # s of the walk back still to go (back)
        self.opened_at: list[float] = []  # times her doors were opened (by her or their sensors)
        self._away_at_done = 0.0

    # ------------------------------------------------------------------ what the engine asks

    @property
    def done(self) -> bool:
        return self.done_time is not None

    @property
    def available(self) -> bool:
        """At her desk: free to set off for a door."""
        return self.place == "desk"

    @property
    def task_duration(self) -> float | None:
        """Site seconds she spent at her desk until her task was done (None before)."""
        if self.done_time is None:
            return None
        return round(self.done_time - self._away_at_done, 9)

    def focus_report(self) -> list[dict[str, Any]]:
        return []  # her focus is not known to the simulator

    def pose(self) -> tuple[float, float, float]:
        """Where her avatar is (x, y) and which way it faces (as the model's: the camera follows it)."""
        if self.place == "desk":
            door = next(iter(self.door_points.values()), None)
            yaw = math.atan2(door[1] - self.desk[1], door[0] - self.desk[0]) if door else 0.0
            return (*self.desk, yaw)
        target = self.door_points[self.door]
        walk = self.walk_time[self.door] or 1.0
        if self.place == "to_door":
            f, a, b = self.walked / walk, self.desk, target
        elif self.place == "at_door":
            f, a, b = 1.0, self.desk, target
        else:
            f, a, b = 1.0 - self.left / walk, target, self.desk
        f = min(max(f, 0.0), 1.0)
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), math.atan2(b[1] - a[1], b[0] - a[0]))

    def step(
        self,
        now: float,
        dt: float,
        waiting: dict[str, dict[str, float]],
        door_open: dict[str, bool],
        planned: Mapping[str, Mapping[str, float]] | None = None,
    ) -> list[HumanAction]:
        """Walk for ``dt`` seconds. She decides nothing here (her acts come through :meth:`act`), so
        what the model would read (robots waiting, doors open, the robots' plans) goes unused."""
        left = dt
        while left > EPS:
            if self.place == "desk":
                break
            if self.place == "at_door":
                self.counters.time_away += left
                break
            if self.place == "to_door":
                spend = min(left, self.walk_time[self.door] - self.walked)
                self.walked += spend
                if self.walked >= self.walk_time[self.door] - EPS:
                    self.place = "at_door"
            else:
                spend = min(left, self.left)
                self.left -= spend
                if self.left <= EPS:
                    self.place, self.door, self.left = "desk", "", 0.0
            self.counters.time_away += spend
            left -= spend
        return []

    # ------------------------------------------------------------------ what she does

    def act(self, act: str, door: str, now: float) -> list[HumanAction]:
        """Take her act at site time ``now``; returns what the engine must do, or raises :class:`Refused`."""
        if act == "task_done":
            if self.done_time is not None:
                raise Refused("act", f"her task is already done (at t={self.done_time:.2f})")
            self.done_time = now
            self._away_at_done = self.counters.time_away
            return [TaskDone(now)]
        if act not in DOOR_ACTS:
            raise Refused("act", f"{act!r} is not an act the simulator takes (it takes {', '.join(ACTS)})")
        if self.sensor:
            raise Refused("act", f"{act}: the doors follow their sensors (--doors sensor); no avatar walks")
        if act == "go_to_door":
            self._check_door(door)
            if self.place != "desk":
                raise Refused("act", f"go_to_door: she is not at her desk ({self._where()})")
            self.counters.door_trips += 1
            self.place, self.door, self.walked = "to_door", door, 0.0
            if self.walk_time[door] <= EPS:
                self.place = "at_door"
            return []
        if act == "open_door":
            self._check_door(door)
            if self.place != "at_door" or self.door != door:
                raise Refused("act", f"open_door {door}: she is not at that door ({self._where()})")
            self.counters.door_openings += 1
            self.opened_at.append(now)
            self._walk_back(self.walk_time[door])
            return [OpenDoor(door)]
        # back_to_desk
        if door and door != self.door:
            raise Refused("door", f"back_to_desk from {door!r}: she is {self._where()}")
        if self.place == "to_door":
            self.counters.turned_back += 1
            self._walk_back(self.walked)  # back the way she came
        elif self.place == "at_door":
            self.counters.turned_back += 1
            self._walk_back(self.walk_time[self.door])
        else:
            raise Refused("act", f"back_to_desk: she is {self._where()}")
        return []

    def sensor_opening(self, door: str, now: float) -> None:
        """A sensor reported her door opened (real doors: the opening is hers, or the experimenter's)."""
        self.counters.door_openings += 1
        self.opened_at.append(now)

    # ------------------------------------------------------------------ helpers

    def _check_door(self, door: str) -> None:
        if door not in self.door_points:
            hers = ", ".join(sorted(self.door_points)) or "none"
            raise Refused("door", f"{door!r} is not a door she operates (hers: {hers})")

    def _walk_back(self, seconds: float) -> None:
        self.place, self.left, self.walked = "back", seconds, 0.0
        if seconds <= EPS:
            self.place, self.door, self.left = "desk", "", 0.0

    def _where(self) -> str:
        return {
            "desk": "at her desk",
            "to_door": f"walking to {self.door}",
            "at_door": f"at {self.door}",
            "back": f"walking back from {self.door}",
        }[self.place]
