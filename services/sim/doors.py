"""Door leaves: who opens them, how long they swing, when they close.

- A human-operated door opens only when the human opens it. It stays open ``door_hold_time``
  seconds from the moment it is fully open (she holds it, or it is propped open), and then closes
  as soon as the doorway is clear of robots.
- A human-operated door that follows its sensor (``arroch sim --doors sensor``: a real door) opens
  when its sensor says open and closes, as soon as the doorway is clear, when it says shut; no hold
  time: the sensor says how long it stays open. Its sensor saying shut while the leaf still swings
  open swings it back at once when the doorway is clear (it never became passable).
- Any other door opens for an approaching robot (the robot asks every tick while its path reaches
  the door within ``auto_open_distance``) and closes ``auto_close_delay`` seconds after no robot
  asks any more and the doorway is clear.

A leaf takes ``swing_time`` to open or close. A door is *passable* only fully open and not
closing; ``door_opened`` fires when it becomes passable, ``door_closed`` when it starts closing
(from then on no robot may enter). The doorway is clear when every robot's disc keeps
``clear_margin`` from the gap and from the area the leaf sweeps on its swing side (a quarter disc
of the leaf's length about the hinge), so a leaf never closes onto a robot. Robots waiting for a
door stop further out than the gap's margin (see :mod:`runtime.executor.executor`), so a queue of
waiting robots on the far side never props a door open.

Opening is not held back: a robot waiting on the swing side within the leaf's reach overlaps the
leaf while it swings open (the kinematic scene does not push bodies; a planner that parks robots
there, e.g. inside the human's room beside her door, sees them overlap the opening leaf).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from protocol.site.model import DoorLeaf, Opening
from runtime.plane import Point, segment_distance


@dataclass(frozen=True)
class DoorConfig:
    swing_time: float = 1.5  # s for a leaf to go from closed to open (or back)
    hold_time: float = 20.0  # s a human-opened door stays open (the site's door_hold_time)
    auto_close_delay: float = 1.0  # s an automatic door waits, unneeded and clear, before closing
    clear_margin: float = 0.1  # m between a robot's disc and the gap for the doorway to be clear


@dataclass(frozen=True)
class DoorChange:
    """A door became passable (``opened``) or started closing; ``by`` who opened it."""

    door: str
    opened: bool
    by: str
    until: float = 0.0  # for a human opening: when the hold ends


@dataclass
class Door:
    opening: Opening
    leaf: DoorLeaf | None = None
    fraction: float = 0.0  # 0 closed .. 1 open
    target_open: bool = False
    opened_by: str = ""
    hold_until: float = 0.0  # human doors: earliest closing time once fully open
    unneeded_since: float | None = None  # automatic doors: since when no robot has asked
    requests: set[str] = field(default_factory=set)  # robots asking this tick
    sensor: bool = False  # follows its sensor (a real door): open while it says open
    sensor_open: bool = False  # what its sensor said last
    # The gap's ends (Opening.endpoints), computed once: they are read for every robot every tick.
    gap: tuple[Point, Point] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.gap = self.opening.endpoints

    @property
    def id(self) -> str:
        return self.opening.id

    @property
    def human_operated(self) -> bool:
        return self.opening.human_operated

    @property
    def passable(self) -> bool:
        return self.target_open and self.fraction >= 1.0

    @property
    def open_or_opening(self) -> bool:
        return self.target_open

    @property
    def open_until(self) -> float:
        """When a human opening's hold ends (``DoorState.until``); 0 when not held open by a human, or
        for a door following its sensor (nobody knows when it will be shut)."""
        return self.hold_until if self.human_operated and not self.sensor and self.passable else 0.0


class Doors:
    """Every door of the site and its leaf state; stepped once per engine tick."""

    def __init__(
        self,
        doors: Iterable[Opening],
        config: DoorConfig,
        robot_radius: float,
        leaves: dict[str, DoorLeaf] | None = None,
    ) -> None:
        self.config = config
        self.robot_radius = robot_radius
        leaves = leaves or {}
        self.doors: dict[str, Door] = {o.id: Door(o, leaves.get(o.id)) for o in sorted(doors, key=lambda o: o.id)}

    def __getitem__(self, door_id: str) -> Door:
        return self.doors[door_id]

    def __contains__(self, door_id: str) -> bool:
        return door_id in self.doors

    def passable(self, door_id: str) -> bool:
        return self.doors[door_id].passable

    def request_open(self, door_id: str, robot: str) -> None:
        """A robot about to go through asks an automatic door to open (ignored by human doors)."""
        door = self.doors[door_id]
        if not door.human_operated:
            door.requests.add(robot)

    def human_open(self, door_id: str, now: float) -> None:
        """The human opens the door (or, if it is open, holds it open for another hold time)."""
        door = self.doors[door_id]
        door.opened_by = "human"
        if door.passable:
            door.hold_until = now + self.config.hold_time
        door.target_open = True

    def follow_sensors(self, door_ids: Iterable[str]) -> None:
        """These (human-operated) doors follow their sensors from now on (see the module docstring)."""
        for door_id in door_ids:
            door = self.doors[door_id]
            if not door.human_operated:
                raise ValueError(f"door {door_id!r} is not human-operated: automatic doors open for the robots")
            door.sensor = True

    def sensor_says(self, door_id: str, is_open: bool, by: str) -> bool:
        """Its sensor reports ``door_id`` open or shut. Returns whether the door starts opening (it
        was shut or closing); a shut report takes effect in :meth:`step`, once the doorway is clear."""
        door = self.doors[door_id]
        door.sensor_open = is_open
        if not is_open or door.target_open:
            return False
        door.opened_by = by
        door.target_open = True
        return True

    def into_swing(self, door_id: str, before: Point, after: Point) -> bool:
        """Whether a disc stepping from ``before`` to ``after`` enters the doorway (the gap's margin,
        or the area the leaf sweeps) of a door whose leaf is on the move, having been clear of it
        (the executor refuses such a step: :mod:`runtime.executor.interfaces`)."""
        door = self.doors[door_id]
        moving = 0.0 < door.fraction < 1.0 or (door.fraction >= 1.0 and not door.target_open)
        return moving and self.doorway_clear(door, [before]) and not self.doorway_clear(door, [after])

    def doorway_clear(self, door: Door, robots: Iterable[tuple[float, float]]) -> bool:
        a, b = door.gap
        limit = self.robot_radius + self.config.clear_margin
        leaf = door.leaf
        if leaf is not None:
            nx, ny = door.opening.normal_into(leaf.swing_into)
            hx, hy = leaf.hinge
        for p in robots:
            if segment_distance(p, a, b) <= limit:
                return False
            if leaf is not None:
                on_swing_side = (p[0] - hx) * nx + (p[1] - hy) * ny > 0.0
                if on_swing_side and math.hypot(p[0] - hx, p[1] - hy) <= leaf.length + limit:
                    return False
        return True

    def step(self, now: float, dt: float, robot_positions: list[tuple[float, float]]) -> list[DoorChange]:
        """Swing leaves, open automatic doors on request, close doors whose time has come."""
        changes: list[DoorChange] = []
        rate = dt / self.config.swing_time if self.config.swing_time > 0 else 1.0
        for door in self.doors.values():
            if not door.human_operated:
                self._automatic(door, now)
            if (
                door.target_open
                and door.fraction < 1.0
                and door.sensor
                and not door.sensor_open
                and self.doorway_clear(door, robot_positions)
            ):
                door.target_open = False  # shut again before it was ever passable: no change to report
            elif door.target_open and door.fraction < 1.0:
                door.fraction = min(1.0, door.fraction + rate)
                if door.fraction >= 1.0:
                    if door.human_operated and not door.sensor:
                        door.hold_until = now + dt + self.config.hold_time
                    changes.append(DoorChange(door.id, True, door.opened_by, door.open_until))
            elif door.target_open and self._closing_due(door, now + dt, robot_positions):
                door.target_open = False
                changes.append(DoorChange(door.id, False, door.opened_by))
            elif not door.target_open and door.fraction > 0.0:
                door.fraction = max(0.0, door.fraction - rate)
            door.requests.clear()
        return changes

    def _automatic(self, door: Door, now: float) -> None:
        if door.requests:
            door.unneeded_since = None
            if not door.target_open:
                door.target_open = True
                door.opened_by = min(door.requests)
        elif door.unneeded_since is None:
            door.unneeded_since = now

    def _closing_due(self, door: Door, t: float, robot_positions: list[tuple[float, float]]) -> bool:
        if door.sensor:
            due = not door.sensor_open
        elif door.human_operated:
            due = t >= door.hold_until
        else:
            due = door.unneeded_since is not None and t - door.unneeded_since >= self.config.auto_close_delay
        return due and self.doorway_clear(door, robot_positions)
