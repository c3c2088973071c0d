"""The five actions of the delivery domain, as robots, planner and simulator name them.

``Action`` is a ``StrEnum``: each member equals its name on the wire (``Action.LOAD == "load"``),
so messages keep carrying plain strings and comparisons with them need no conversion.

:data:`STEPS` is the one table of what each action is (its argument, where it leaves the robot,
whether its time is bounded by driving, whether it works in place) and :class:`Fluents` the one
account of how it changes a robot's domain state; the planner's validator, its replay of plans and
the dispatcher read them instead of each spelling the five actions out again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
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


class EndsAt(StrEnum):
    """Where an action leaves the robot (each interpreter turns this into a point its own way)."""

    STAYS = "stays"  # where it was
    NEAR_SIDE = "near_side"  # beside the opening, on the side of the room it is in
    FAR_SIDE = "far_side"  # beside the opening, in the room on its other side
    OBJECT = "object"  # at the object's pick-up point
    DROP = "drop"  # at the object's drop point in its destination room


@dataclass(frozen=True)
class StepRule:
    """What one action is, in the domain's terms: its argument, where it leaves the robot, whether
    its time is bounded below by the drive there, whether it works in place (``load_time``)."""

    action: Action
    arg: str  # what its argument names: "opening", "door" or "object"
    ends_at: EndsAt
    straight_line: bool  # lasts at least the straight line from where it starts to where it ends / robot_speed
    in_place: bool  # works in place for load_time (cannot be dropped halfway)


STEPS: dict[Action, StepRule] = {
    Action.APPROACH: StepRule(Action.APPROACH, "opening", EndsAt.NEAR_SIDE, straight_line=True, in_place=False),
    Action.OPENDOOR: StepRule(Action.OPENDOOR, "door", EndsAt.STAYS, straight_line=False, in_place=False),
    Action.GOTHROUGH: StepRule(Action.GOTHROUGH, "opening", EndsAt.FAR_SIDE, straight_line=True, in_place=False),
    Action.LOAD: StepRule(Action.LOAD, "object", EndsAt.OBJECT, straight_line=False, in_place=True),
    Action.UNLOAD: StepRule(Action.UNLOAD, "object", EndsAt.DROP, straight_line=False, in_place=True),
}


@dataclass
class Fluents:
    """A robot's domain state as steps change it: its room, the opening it stands beside, what it
    carries and what it has delivered."""

    room: str
    beside: str = ""
    carrying: set[str] = field(default_factory=set)
    delivered: set[str] = field(default_factory=set)

    def apply(self, action: Action | str, arg: str, room_after: str = "") -> None:
        """The effect of ``action(arg)``; ``room_after``: the room a gothrough enters."""
        match Action(action):
            case Action.APPROACH:
                self.beside = arg
            case Action.OPENDOOR:
                pass  # it needs the robot beside the door already, and leaves it there
            case Action.GOTHROUGH:
                self.room, self.beside = room_after, ""
            case Action.LOAD:
                self.carrying.add(arg)
                self.beside = ""
            case Action.UNLOAD:
                self.carrying.discard(arg)
                self.delivered.add(arg)
                self.beside = ""
