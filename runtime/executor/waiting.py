"""Which robot each robot waits for, and whether a robot kept back is in a queue or stuck.

A robot kept back by other robots (:mod:`.avoidance`) drives around them or asks them to make way
(:mod:`.make_way`); when neither helps for ``Avoidance.give_up`` seconds its action fails and the
planner plans again from where the robots stand. That replan is a last resort for a wait that cannot
end by itself, and only for one: a robot behind a robot that waits for a door, loads, or drives on
is in a queue, which moves on when the robot at its head does; giving up there only sends it back
to its place in the queue, to give up again 12 s later.

A failed action breaks no wait by itself: the replan leaves the robots where they stand. So before a
robot's action fails, once per action, the executor tries what moves one of them
(:mod:`.executor`): a robot in a waiting cycle makes way, unasked, for the robot of the cycle that
waits on it (:meth:`.make_way.MakeWay.offer`); a robot holding a doorway it has not entered, kept
back by a robot making way for it, hands the doorway back until that robot is off its way (the
doorway's lane, which no other robot enters, may be that robot's only way out).

Each step the executor notes which robot a robot waits for, if any (:meth:`Waits.on`): the robot it
stops for (right of way, solid bodies) or the robot holding the doorway it is to cross. Following
those notes from a robot kept back gives a chain of robots; the wait cannot end by itself when the
chain comes back to a robot in it (a cycle: each waits on the next), or ends at a parked robot that
did not make way (it waits for nothing, so nothing moves it). Otherwise the chain ends at a robot
that waits for no robot - for a door, a hold of its trajectory, its load, or not at all - and the
queue moves on when it does. A robot that drives around others with nobody in its way (noted as
waiting for nobody) ends a chain too: it is on its way.

A robot gives up when its wait has been one that cannot end by itself for ``Avoidance.give_up``
seconds in a row (:meth:`Waits.stuck_for`), not as soon as a long wait turns into one: a queue whose
head, busy making way for a third robot, turns back into the robot behind it is a cycle of two from
that step on, and the one of the two that may ask the other to make way (:mod:`.make_way`) needs a
few seconds to ask. With these clocks the twelve-robot check (trials 0-3 of ``arroch experiment
robots --robots 12 --objects 3 --seed 0``) fails no action, against 1, 4, 6 and 1 when the give-up
counted from the wait's start and the patience counted the time queued at a door. A
robot kept back ``patience`` seconds gives up whatever the chain says (a wait among robots that no
note shows - robots waiting on one another through something else than these rules - still ends),
but the seconds it queues behind a robot waiting for a door to open do not count
(:meth:`Waits.waited`): that queue moves when the door opens, however long she takes, and giving up
would only send the robot back to its place in it.
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
    # s between two steps of one stuck wait: a longer break (the robot was not kept back) starts it again
    break_after: float = 1.0
    waits_for: dict[str, str] = field(default_factory=dict)  # robot -> the robot it waits for this step
    _stuck: dict[str, tuple[float, float]] = field(default_factory=dict)  # robot -> (stuck since, last seen)
    _waited: dict[str, tuple[float, float]] = field(default_factory=dict)  # robot -> (s counted, last seen)

    def on(self, robot: str, other: str) -> None:
        """``robot`` waits for ``other`` this step ("": kept back, by no robot known - it drives around)."""
        if other:
            self.waits_for[robot] = other
        else:
            self.waits_for.pop(robot, None)

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

    def head(self, robot: str) -> str:
        """The robot at the head of the queue ``robot`` waits in: the end of its chain ("" when the
        chain is a cycle or ``robot`` waits for nobody)."""
        chain = self.chain(robot)
        if len(chain) == 1 or chain[-1] in chain[:-1]:
            return ""
        return chain[-1]

    def stuck(self, robot: str, fleet: Mapping[str, Body]) -> bool:
        """Whether the wait of ``robot`` (kept back by robots) cannot end by itself: the chain of
        robots waiting from it comes back into itself, ends at a parked robot, or is unknown."""
        chain = self.chain(robot)
        if len(chain) == 1:
            return True  # kept back with nobody noted: nothing says it is a queue
        if chain[-1] in chain[:-1]:
            return True  # a cycle
        return any(fleet.get(r) is None or fleet[r].phase in PARKED for r in chain[1:])

    def stuck_for(self, robot: str, fleet: Mapping[str, Body], now: float) -> float:
        """Seconds the wait of ``robot`` (kept back by robots at this step) has been stuck without a
        break (:meth:`stuck`); 0 while it is a queue."""
        if not self.stuck(robot, fleet):
            self._stuck.pop(robot, None)
            return 0.0
        since, seen = self._stuck.get(robot, (now, now))
        if now - seen > self.break_after:
            since = now  # it was not kept back in between: a new wait
        self._stuck[robot] = (since, now)
        return now - since

    def waited(self, robot: str, now: float, *, counts: bool) -> float:
        """Seconds the wait of ``robot`` (kept back by robots at this step) counts toward
        ``patience``: its steps kept back without a break, but those in which it ``counts`` not (it
        queues behind a robot waiting for a door: that queue moves when the door opens)."""
        total, seen = self._waited.get(robot, (0.0, now))
        if now - seen > self.break_after:
            total = 0.0  # it was not kept back in between: a new wait
        elif counts:
            total += now - seen
        self._waited[robot] = (total, now)
        return total

    def gave_up(self, robot: str) -> None:
        """``robot`` gave up its wait (its action failed; the planner plans it again): it waits for
        nobody now, and the robots its chain ran through get ``give_up`` seconds afresh - in a cycle
        of two that gave up together, both actions failed where one replan frees both."""
        for other in self.chain(robot)[1:]:
            self._stuck.pop(other, None)
        self.off(robot)
        self._stuck.pop(robot, None)
        self._waited.pop(robot, None)
