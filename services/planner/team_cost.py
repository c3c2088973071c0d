"""How IIDP scores a team and bounds what one robot's new plan could gain.

The team objective is lexicographic (:meth:`.plan.TeamResult.cost`): conflicts, completion time of
the slowest robot, human door openings, openings outside the human's offers, total robot time.
"""

from __future__ import annotations

from dataclasses import replace

from .plan import RobotPlan, TeamResult, count_conflicts, share_windows

MIN_TIME_GAIN = 3  # s of total robot time a round must save when it changes nothing else


def team_cost(plans: dict[str, RobotPlan], hold: int, existing: frozenset) -> tuple[int, int, int, int, int]:
    return TeamResult("iidp", 0, hold, plans, existing=existing).cost()


def shared(plans: dict[str, RobotPlan], hold: int, existing: frozenset) -> dict[str, RobotPlan]:
    return share_windows(plans, hold, existing)


def improves(cost: tuple, current: tuple) -> bool:
    """A better team cost; on total robot time alone (the last level) only by ``MIN_TIME_GAIN`` s or
    more - a round per second saved would spend the time limit on rounding noise."""
    if cost[:-1] != current[:-1]:
        return cost[:-1] < current[:-1]
    return cost[-1] <= current[-1] - MIN_TIME_GAIN


def min_openings(plans, hold: int, existing: frozenset) -> int:
    """The fewest human openings that could cover these plans' passes through human doors.

    Per door, in order of start: an opening that starts when the first uncovered pass does covers
    every later pass that ends within its hold window, and none can cover more, so this greedy count
    is the minimum. Passes inside a door already open are free."""
    n = 0
    by_door: dict[str, list[tuple[int, int]]] = {}
    for plan in plans:
        for p in plan.passes:
            if p.human and not any(d == p.opening and t <= p.start and p.end <= t + hold for d, t in existing):
                by_door.setdefault(p.opening, []).append((p.start, p.end))
    for passes in by_door.values():
        cover_until = None
        for start, end in sorted(passes):
            if cover_until is not None and end <= cover_until:
                continue
            n += 1
            cover_until = start + hold
    return n


def lower_bound(
    rid: str, plans: dict[str, RobotPlan], alone: int, hold: int, existing: frozenset
) -> tuple[int, int, int, int, int]:
    """A cost no plan of ``rid`` can beat, with the others' plans fixed (component by component)."""
    others = [p for o, p in plans.items() if o != rid]
    overlaps = count_conflicts([replace(p, uses=frozenset()) for p in others], hold)  # doorway overlaps only
    makespan = max([alone] + [p.finish for p in others])
    return (overlaps, makespan, min_openings(others, hold, existing), 0, sum(p.finish for p in others) + alone)
