"""The doors and objects as a process that drives one robot knows them (:mod:`.interfaces`).

A real robot's driver (``arroch robot``) does not run the world: it hears the doors' states and
knows the objects from the site file and from what its robot did.

- :class:`SensedDoors`: a door is passable while its last ``DoorState`` said open, closed until one
  came. Nobody reports a leaf on the move, so no step is refused for entering a leaf's sweep: a
  door is open (``DoorState.open``) only once it is passable. Asking an automatic door to open does
  nothing here: the simulator (``--robots none``, ``--ros2-bases``) or the building opens it for
  the robot whose command goes through it.
- :class:`SiteObjects`: an object is where the site file puts it; whether it is carried or
  delivered is what this robot did, as its ``carrying`` and ``delivered`` say (a driver restarted
  mid-mission starts from the site file again, as it always has).
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.messages import DoorState
from protocol.site.model import Site
from runtime.plane import Point

from .executor import Robot


@dataclass
class SensedDoor:
    id: str
    gap: tuple[Point, Point]
    passable: bool = False


class SensedDoors:
    def __init__(self, site: Site) -> None:
        self.doors: dict[str, SensedDoor] = {
            did: SensedDoor(did, door.endpoints) for did, door in sorted(site.doors.items())
        }

    def __getitem__(self, door_id: str) -> SensedDoor:
        return self.doors[door_id]

    def heard(self, state: DoorState) -> bool:
        """A door's state; False (ignored) for a door that is not on the site."""
        door = self.doors.get(state.door)
        if door is None:
            return False
        door.passable = state.open
        return True

    def passable(self, door_id: str) -> bool:
        return self.doors[door_id].passable

    def request_open(self, door_id: str, robot: str) -> None:
        """Nothing to do: whoever runs the doors opens automatic ones for the robot's command."""

    def into_swing(self, door_id: str, before: Point, after: Point) -> bool:
        return False  # no leaf is reported on the move: a door is open only once it is passable


class SiteObjects:
    """The objects as the site file has them, and as this robot's own ``carrying`` and
    ``delivered`` lists (which the executor keeps) say: picking one up and putting it down need not
    be noted again."""

    def __init__(self, site: Site, robot: Robot) -> None:
        self.specs = site.objects
        self.robot = robot

    def __contains__(self, oid: object) -> bool:
        return oid in self.specs

    def owner(self, oid: str) -> str:
        return self.specs[oid].robot

    def carrier(self, oid: str) -> str | None:
        return self.robot.id if oid in self.robot.carrying else None

    def delivered(self, oid: str) -> bool:
        return oid in self.robot.delivered

    def position(self, oid: str) -> tuple[float, float]:
        x, y = self.specs[oid].position
        return x, y

    def pick(self, oid: str, robot: str) -> None:
        """Noted by the executor in the robot's ``carrying``."""

    def place(self, oid: str, x: float, y: float, *, delivered_at: float | None = None) -> None:
        """Noted by the executor in the robot's ``delivered``."""
