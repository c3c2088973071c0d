"""The objects to deliver: where each one is, who carries it, whether it arrived.

A carried object rides on its robot: its position is the robot's, read when asked, so nothing has
to move it tick by tick.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.site.model import ObjectSpec

CARRY_HEIGHT = 0.45  # m: an object sits on top of the robot body while carried
FLOOR_HEIGHT = 0.1  # m: the centre of an object standing on the floor


@dataclass
class ObjectState:
    spec: ObjectSpec
    x: float
    y: float
    carrier: str | None = None
    delivered: bool = False
    delivered_at: float | None = None

    @property
    def id(self) -> str:
        return self.spec.id


class Objects:
    def __init__(self, specs: dict[str, ObjectSpec]) -> None:
        self.items: dict[str, ObjectState] = {
            oid: ObjectState(spec, *spec.position) for oid, spec in sorted(specs.items())
        }
        self.changed: set[str] = set(self.items)  # ids whose pose or carrier changed since last read

    def __contains__(self, oid: str) -> bool:
        return oid in self.items

    def __getitem__(self, oid: str) -> ObjectState:
        return self.items[oid]

    # what the executor reads (runtime/executor/interfaces.py)
    def owner(self, oid: str) -> str:
        return self.items[oid].spec.robot

    def carrier(self, oid: str) -> str | None:
        return self.items[oid].carrier

    def delivered(self, oid: str) -> bool:
        return self.items[oid].delivered

    def position(self, oid: str) -> tuple[float, float]:
        obj = self.items[oid]
        return obj.x, obj.y

    def pick(self, oid: str, robot: str) -> None:
        obj = self.items[oid]
        obj.carrier = robot
        self.changed.add(oid)

    def place(self, oid: str, x: float, y: float, *, delivered_at: float | None = None) -> None:
        """Put a carried object down at (x, y); ``delivered_at`` when that completes its delivery."""
        obj = self.items[oid]
        obj.carrier = None
        obj.x, obj.y = x, y
        if delivered_at is not None:
            obj.delivered = True
            obj.delivered_at = delivered_at
        self.changed.add(oid)

    @property
    def all_delivered(self) -> bool:
        return all(o.delivered for o in self.items.values())

    def of_robot(self, robot: str) -> list[ObjectState]:
        return [o for o in self.items.values() if o.spec.robot == robot]
