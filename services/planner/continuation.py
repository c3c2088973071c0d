"""Keeping the plan being executed when the news does not call for solving again.

Most triggers are a robot ending its front action. When it ends no more than CONTINUE_TOLERANCE
after the plan's time for it, re-solving would retime the plans by little and start the IIDP rounds
from the same team, so the plan is kept as it is (Algorithm 1's P^t call on an unchanged problem),
moved past those actions. An action often ends well before its planned end: robots start their next
action as soon as the last one ends, without the waits the plan allows for, so they run ahead of the
plan; the plan still holds for them - their stops, orders and the openings they use - and what
running ahead changes shows as news of its own (a robot waiting at a closed door). A world version
with none of this (a robot-operated door opening) changes nothing the planner reads. Anything else -
constraints, a human-operated door opening or closing, a failure, a robot waiting at a door or off
its trajectory, an action ending late - is solved anew.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace

from .dispatcher import Dispatched
from .plan import TeamResult
from .triggers import ActionEnded, Trigger

CONTINUE_TOLERANCE = 2.0  # s: an action that ends at most this late keeps the plan (no re-solve)


def continued(
    kept: TeamResult | None,
    triggers: Iterable[Trigger],
    *,
    finished: set[str],
    force: set[str],
    sent: Mapping[str, Dispatched],
    front_index: Mapping[str, int],
    now: float,
    existing: Callable[[int], frozenset],
) -> TeamResult | None:
    """The plan ``kept``, moved past the actions that just ended, when that is all that happened;
    None when the task planner must run.

    ``finished``: robots whose sent action is reported over; ``force``: robots to command anew;
    ``sent``/``front_index``: the dispatcher's commands and their steps' indices in the plans;
    ``existing(base)``: the door openings under way at the new base (they keep their windows)."""
    if kept is None or kept.status not in ("ok", "timeout") or kept.conflicts:
        return None
    ended: set[str] = set()
    for trigger in triggers:
        if isinstance(trigger, ActionEnded) and not trigger.failed:
            ended.add(trigger.robot)
        elif not trigger.keeps_plan():
            return None
    if not ended <= finished or force:
        return None  # an end of an action not the one sent, or a robot to re-command
    plans = dict(kept.plans)
    for rid in sorted(finished):
        command = sent.get(rid)
        index = front_index.get(rid)
        plan = plans.get(rid)
        if command is None or index is None or plan is None or index >= len(plan.steps):
            return None
        step = plan.steps[index]
        if (step.action, step.args) != (command.action, command.args):
            return None
        if now - kept.absolute(step.end) > CONTINUE_TOLERANCE:
            return None  # late: the others' plans may count on it
        plans[rid] = replace(plan, steps=plan.steps[index + 1 :])
    base = int(math.floor(now))
    delta = kept.base - base
    return replace(
        kept,
        base=base,
        plans={rid: plan.shifted(delta) for rid, plan in plans.items()},
        existing=existing(base),
        iterations=0,
        solve_time=0.0,
        solves=0,
        diagnostic="",
    )
