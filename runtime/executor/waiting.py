"""Which robot each robot waits for, and whether a robot kept back is in a queue or stuck.

A robot kept back by other robots (:mod:`.avoidance`) drives around them or asks them to make way
(:mod:`.make_way`); when neither helps for ``Avoidance.give_up`` seconds its action fails and the
planner plans again from where the robots stand. That replan is a last resort for a wait that cannot
end by itself, and only for one: a robot behind a robot that waits for a door, loads, or drives on
is in a queue, which moves on when the robot at its head does; giving up there only sends it back
to its place in the queue, to give up again 12 s later.

Each step the executor notes which robot a robot waits for, if any (:meth:`Waits.on`): the robot it
stops for (right of way, solid bodies) or the robot holding the doorway it is to cross. Following
those notes from a robot kept back gives a chain of robots; the wait cannot end by itself when the
chain comes back to a robot in it (a cycle: each waits on the next), or ends at a parked robot that
did not make way (it waits for nothing, so nothing moves it). Otherwise the chain ends at a robot
that waits for no robot - for a door, a hold of its trajectory, its load, or not at all - and the
queue moves on when it does. A robot kept back ``patience`` seconds gives up whatever the chain
says: a wait among robots that no note shows (robots waiting on one another through something else
than these rules) still ends.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from .right_of_way import PARKED, Body


@dataclass
class Waits:
    # s a robot kept back by robots waits at most, in a queue or not: ten times ``Avoidance.give_up``,
    # longer than a queue at a door held open 20 s takes to go through, one robot after another
    patience: float = 120.0
    waits_for: dict[str, str] = field(default_factory=dict)  # robot -> the robot it waits for this step

    def on(self, robot: str, other: str) -> None:
        """``robot`` waits for ``other`` this step."""
        self.waits_for[robot] = other

    def off(self, robot: str) -> None:
        """``robot`` waits for no robot this step (it drives, waits for a door or a hold, or dwells)."""
        self.waits_for.pop(robot, None)

    def chain(self, robot: str) -> list[str]:
        """The robots ``robot`` waits on, one after another, up to the first met twice (a cycle)."""
        chain = [robot]
        nxt = self.waits_for.get(robot)
        while nxt is not None:
            chain.append(nxt)
            if nxt in chain[:-1]:
                break
            nxt = self.waits_for.get(nxt)
        return chain

    def stuck(self, robot: str, fleet: Mapping[str, Body]) -> bool:
        """Whether the wait of ``robot`` (kept back by robots) cannot end by itself: the chain of
        robots waiting from it comes back into itself, ends at a parked robot, or is unknown."""
        chain = self.chain(robot)
        if len(chain) == 1:
            return True  # kept back with nobody noted: nothing says it is a queue
        if chain[-1] in chain[:-1]:
            return True  # a cycle
        return any(fleet.get(r) is None or fleet[r].phase in PARKED for r in chain[1:])
