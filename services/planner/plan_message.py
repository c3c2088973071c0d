"""A planner result as the TeamPlan message published on ``plan``."""

from __future__ import annotations

from protocol.messages import PlannedOpening, PlanStep, TeamPlan

from .plan import TeamResult


def to_message(
    result: TeamResult,
    plan_id: int,
    world_version: int,
    constraints_version: int,
    front: dict[str, int],
    diagnostic: str,
    skip: dict[str, int] | None = None,
) -> TeamPlan:
    """``skip``: leading steps of a robot's plan that need not be executed (an opendoor of a door
    open now, see :meth:`Dispatcher.front`); the message starts at the step dispatched."""
    robots = {}
    for rid, plan in sorted(result.plans.items()):
        steps = []
        for i, s in enumerate(plan.steps[(skip or {}).get(rid, 0) :]):
            steps.append(
                PlanStep(
                    action=s.action,
                    args=list(s.args),
                    start=float(result.absolute(s.start)),
                    end=float(result.absolute(s.end)),
                    action_id=front.get(rid, 0) if i == 0 else 0,
                )
            )
        robots[rid] = steps
    openings = [
        PlannedOpening(
            door=o.door, start=float(result.absolute(o.start)), end=float(result.absolute(o.end)), robots=list(o.robots)
        )
        for o in result.openings
    ]
    return TeamPlan(
        plan_id=plan_id,
        world_version=world_version,
        constraints_version=constraints_version,
        method=result.method,
        makespan=float(result.makespan),
        door_openings=result.door_openings,
        solve_time=round(result.solve_time, 4),
        iterations=result.iterations,
        robots=robots,
        openings=openings,
        diagnostic=diagnostic[:4096],
    )
