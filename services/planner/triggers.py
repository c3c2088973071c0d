"""What can make the planner replan, as typed values.

Each input handler of the service turns news into one of these; the replan scheduler collects them
into a burst, and the plan continuation reads them to decide whether the plan being executed still
holds. ``str()`` gives the short form the logs show (``status:r0:moving``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

# states a robot following its plan goes through: news of them alone keeps the plan
ROUTINE_STATES = ("moving", "done", "loading", "unloading")


@dataclass(frozen=True)
class Trigger:
    """News that may call for a new plan."""

    # a lockstep simulator waits for a plan that answers this news (others wait for its next version)
    answered_in_lockstep: ClassVar[bool] = False
    # somebody waits for the plan that answers this news: it is planned without waiting for the burst
    # to settle (the human who pressed a feedback button watches for the robots' answer)
    urgent: ClassVar[bool] = False

    def keeps_plan(self) -> bool:
        """Whether this news alone leaves the plan being executed valid (no re-solve)."""
        return False


@dataclass(frozen=True)
class Start(Trigger):
    answered_in_lockstep: ClassVar[bool] = True

    def __str__(self) -> str:
        return "start"


@dataclass(frozen=True)
class NewWorldVersion(Trigger):
    answered_in_lockstep: ClassVar[bool] = True

    def keeps_plan(self) -> bool:
        return True  # a version with nothing else in it changes nothing the planner reads

    def __str__(self) -> str:
        return "world_version"


@dataclass(frozen=True)
class NewConstraints(Trigger):
    version: int
    answered_in_lockstep: ClassVar[bool] = True
    urgent: ClassVar[bool] = True

    def __str__(self) -> str:
        return f"constraints:v{self.version}"


@dataclass(frozen=True)
class StatusChanged(Trigger):
    robot: str
    state: str

    def keeps_plan(self) -> bool:
        return self.state in ROUTINE_STATES

    def __str__(self) -> str:
        return f"status:{self.robot}:{self.state}"


@dataclass(frozen=True)
class ActionEnded(Trigger):
    """A robot's ``action_done`` or ``action_failed`` event."""

    robot: str
    failed: bool = False

    def __str__(self) -> str:
        return f"action_{'failed' if self.failed else 'done'}:{self.robot}"


@dataclass(frozen=True)
class DoorChanged(Trigger):
    """A human-operated door opened or closed."""

    door: str
    open: bool

    def __str__(self) -> str:
        return f"door:{self.door}:{'open' if self.open else 'closed'}"


@dataclass(frozen=True)
class OffTrack(Trigger):
    """A robot far from the trajectory sent to it."""

    robot: str

    def __str__(self) -> str:
        return f"off_track:{self.robot}"
