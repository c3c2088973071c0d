"""The five actions of the delivery domain, as robots, planner and simulator name them.

``Action`` is a ``StrEnum``: each member equals its name on the wire (``Action.LOAD == "load"``),
so messages keep carrying plain strings and comparisons with them need no conversion.
"""

from __future__ import annotations

from enum import StrEnum


class Action(StrEnum):
    APPROACH = "approach"  # drive to the near side of an opening of the current room
    OPENDOOR = "opendoor"  # ask the human to open a human-operated door the robot stands beside
    GOTHROUGH = "gothrough"  # cross an opening into the room on its other side
    LOAD = "load"  # take an object, in its room
    UNLOAD = "unload"  # drop a carried object, in its destination room

    @classmethod
    def parse(cls, name: str) -> Action:
        """The action called ``name``; ValueError naming it when there is none."""
        try:
            return cls(name)
        except ValueError:
            raise ValueError(f"unknown action {name!r} (one of {', '.join(a.value for a in cls)})") from None


MOVES = frozenset({Action.APPROACH, Action.GOTHROUGH})  # actions that drive the robot along a trajectory
HANDLING = frozenset({Action.LOAD, Action.UNLOAD})  # actions done in place, lasting load_time
