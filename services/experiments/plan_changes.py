"""How feedback changed the plans of one trial: from the TeamPlans it published and the sim's events.

- **constraint replans**: for each constraints version ``c`` the restrictor accepted (an a2(N)),
  the first plan that answers it (``constraints_version == c``, at the lowest world version) against
  the plan it replaced (the last one for a lower constraints version at a world version no later).
  In lockstep the sim's time stands still from the declaration until that plan comes (the gate waits
  for a plan of the new constraints version), so both plans start from the same world version and
  differ only by what the constraint asks. (Should the same instant also bring a new world version,
  e.g. a door closing, the difference holds both; the count says how often the pair spans two.)
- **plans changed**: those constraint replans in which some robot's sequence of actions (action and
  arguments) differs from the plan replaced: the constraint changed what the robots do, not only
  when.
- **deliveries reordered**: per constraint replan, the robots whose order of the deliveries still to
  make (their ``unload`` steps, on the objects both plans still deliver) differs; summed.
- **door wait time**: the seconds robots waited at a human-operated door for it to open, all robots
  together: from each ``waiting_at_door`` event of an ``opendoor`` action at such a door to that
  door's next ``door_opened`` (the door is passable: the action ends), or to the robot's next
  action ending first (a replan sent it elsewhere, or the action failed), or to the mission's end.

The plans kept for a (world version, constraints version) are the last the planner published for it
(the planner's limits never bind in a trial, so that plan follows from the mission's state alone).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

Action = tuple[str, tuple[str, ...]]


@dataclass(frozen=True)
class PlanRecord:
    """What a TeamPlan said, as much as these measures need."""

    plan_id: int
    world: int
    constraints: int
    actions: dict[str, tuple[Action, ...]]  # robot -> its steps (action, args)

    @classmethod
    def of(cls, plan: Any) -> PlanRecord:
        """From a TeamPlan (or anything with its fields)."""
        return cls(
            int(plan.plan_id),
            int(plan.world_version),
            int(plan.constraints_version),
            {rid: tuple((s.action, tuple(s.args)) for s in steps) for rid, steps in plan.robots.items()},
        )

    def deliveries(self, robot: str) -> list[str]:
        return [args[0] for action, args in self.actions.get(robot, ()) if action == "unload" and args]


@dataclass(frozen=True)
class PlanChanges:
    constraint_replans: int = 0
    spanning: int = 0  # constraint replans whose plan replaced was for an earlier world version
    plans_changed: int = 0
    deliveries_reordered: int = 0
    door_wait_time: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return {
            "constraint_replans": self.constraint_replans,
            "spanning_world_versions": self.spanning,
            "plans_changed": self.plans_changed,
            "deliveries_reordered": self.deliveries_reordered,
            "door_wait_time": round(self.door_wait_time, 6),
        }


def _latest(plans: Iterable[PlanRecord]) -> dict[tuple[int, int], PlanRecord]:
    """The last plan published for each (world version, constraints version)."""
    out: dict[tuple[int, int], PlanRecord] = {}
    for plan in sorted(plans, key=lambda p: p.plan_id):
        out[(plan.world, plan.constraints)] = plan
    return out


def reordered(old: PlanRecord, new: PlanRecord) -> int:
    """Robots whose order of the deliveries both plans still make differs between them."""
    count = 0
    for robot in sorted(set(old.actions) | set(new.actions)):
        after = new.deliveries(robot)
        before = [o for o in old.deliveries(robot) if o in set(after)]
        count += before != [o for o in after if o in set(before)]
    return count


def replans(plans: Iterable[PlanRecord]) -> list[tuple[PlanRecord, PlanRecord]]:
    """(plan replaced, plan answering the constraint) for each constraints version above 0 (docstring)."""
    latest = _latest(plans)
    pairs = []
    for version in sorted({c for _, c in latest if c > 0}):
        new = latest[min((w, c) for w, c in latest if c == version)]
        earlier = [k for k in latest if k[1] < version and k[0] <= new.world]
        if earlier:
            pairs.append((latest[max(earlier, key=lambda k: (k[0], latest[k].plan_id))], new))
    return pairs


def door_wait(events: Iterable[Mapping[str, Any]], doors: Sequence[str]) -> float:
    """Seconds robots waited at ``doors`` for them to open (module docstring)."""
    waiting: dict[str, tuple[str, float]] = {}  # robot -> (door, since)
    total = 0.0
    for e in events:
        kind, robot, t = e.get("kind"), str(e.get("robot") or ""), float(e.get("time") or 0.0)
        ended = []
        if kind == "door_opened":
            ended = [r for r, (door, _) in waiting.items() if door == e.get("door")]
        elif kind in ("action_done", "action_failed") and robot in waiting:
            ended = [robot]
        elif kind == "mission_done":
            ended = list(waiting)
        for r in ended:
            total += t - waiting.pop(r)[1]
        data = e.get("data") or {}
        if kind == "waiting_at_door" and e.get("door") in doors and data.get("action") == "opendoor":
            waiting.setdefault(robot, (str(e.get("door")), t))
    return total


def plan_changes(plans: Iterable[PlanRecord], events: Iterable[Mapping[str, Any]], doors: Sequence[str]) -> PlanChanges:
    pairs = replans(plans)
    return PlanChanges(
        constraint_replans=len(pairs),
        spanning=sum(old.world != new.world for old, new in pairs),
        plans_changed=sum(old.actions != new.actions for old, new in pairs),
        deliveries_reordered=sum(reordered(old, new) for old, new in pairs),
        door_wait_time=door_wait(events, doors),
    )
