"""What the executor needs from the world its robots move in: the doors and the objects.

The executor (:mod:`.executor`) decides every robot's steps the same way wherever it runs; what it
cannot know by itself comes through two small interfaces:

- :class:`Doors`: which doors are passable now, the gap of each, asking an automatic door to open,
  and whether a step brings a disc into the area a moving leaf sweeps. The simulator's doors
  (``services/sim/doors.py``) swing leaves and open automatic doors for the robots that ask; for a
  real robot (``services/robot/``) they are the ``door/<id>/state`` messages it hears
  (:mod:`.sensed`): a door is passable when its last state says open, nobody reports a leaf on
  the move, and the simulator or the building opens automatic doors for it.
- :class:`Objects`: which robot an object belongs to, whether it is delivered or carried and by
  whom, where it is, and picking it up and putting it down. The simulator tracks them
  (``services/sim/objects.py``); a real robot knows only the site file and what it did itself
  (:mod:`.sensed`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from runtime.plane import Point


class Door(Protocol):
    """One door as the executor reads it."""

    @property
    def id(self) -> str: ...

    @property
    def gap(self) -> tuple[Point, Point]:
        """The ends of the door's opening (``Opening.endpoints``)."""
        ...

    @property
    def passable(self) -> bool:
        """Whether a robot may drive through now (fully open and not closing)."""
        ...


class Doors(Protocol):
    @property
    def doors(self) -> Mapping[str, Door]: ...

    def __getitem__(self, door_id: str) -> Door: ...

    def passable(self, door_id: str) -> bool: ...

    def request_open(self, door_id: str, robot: str) -> None:
        """A robot about to go through asks an automatic door to open (human-operated ones ignore it)."""
        ...

    def into_swing(self, door_id: str, before: Point, after: Point) -> bool:
        """Whether a disc moving from ``before`` to ``after`` enters the area the door's leaf sweeps
        while the leaf is on the move (it was clear of it before)."""
        ...


class Objects(Protocol):
    def __contains__(self, oid: object) -> bool: ...

    def owner(self, oid: str) -> str:
        """The robot that is to deliver it (``ObjectSpec.robot``)."""
        ...

    def carrier(self, oid: str) -> str | None:
        """The robot carrying it, if any."""
        ...

    def delivered(self, oid: str) -> bool: ...

    def position(self, oid: str) -> tuple[float, float]:
        """Where it is (where the site file puts it, until a robot moves it)."""
        ...

    def pick(self, oid: str, robot: str) -> None: ...

    def place(self, oid: str, x: float, y: float, *, delivered_at: float | None = None) -> None:
        """Put a carried object down at (x, y); ``delivered_at`` when that completes its delivery."""
        ...
