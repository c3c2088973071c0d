"""Where a plan puts the team at a given time, if executed exactly as planned.

Replanning happens mid-mission, from robots that are part-way through their plans; this gives such
worlds without a simulator (benchmarks, tests): every step that ended by ``t`` is done, a gothrough
or a load/unload under way at ``t`` is in progress (it must be finished first), a robot approaching
an opening is part-way there, one waiting stands where its last step left it, and doors the human
opened for the plan are open while their hold window lasts.
"""

from __future__ import annotations

from dataclasses import replace

from protocol.actions import STEPS, Action, EndsAt, Fluents

from .motion import Point
from .plan import RobotPlan, Step, TeamResult
from .problem import ProblemBuilder
from .world import InProgress, RobotState, World


def world_at(builder: ProblemBuilder, world: World, result: TeamResult, t: float) -> World:
    """The world ``result`` (planned from ``world``) leads to at site-clock time ``t``."""
    robots: dict[str, RobotState] = {}
    for rid, state in world.robots.items():
        plan = result.plans.get(rid)
        robots[rid] = state if plan is None else _robot_at(builder, state, plan, result, t)
    open_doors = {
        o.door: float(result.absolute(o.start))
        for o in result.openings
        if result.absolute(o.start) <= t < result.absolute(o.end)
    }
    return replace(world, now=float(t), robots=robots, open_doors=open_doors)


def _robot_at(builder: ProblemBuilder, state: RobotState, plan: RobotPlan, result: TeamResult, t: float) -> RobotState:
    fluents = Fluents(builder.robot_room(state), state.beside, set(state.carrying), set(state.delivered))
    x, y = state.pose[0], state.pose[1]
    in_progress = None
    for step in plan.steps:
        start, end = result.absolute(step.start), result.absolute(step.end)
        if start > t:
            break
        action, arg = Action(step.action), step.args[0] if step.args else ""
        rule = STEPS[action]
        room_after = _entered(builder, state, plan, result, step, fluents.room) if action is Action.GOTHROUGH else ""
        if end > t and action is Action.APPROACH:
            # part-way along the (straight, within one room) drive
            bx, by = builder.wait_point(arg, fluents.room)
            f = (t - start) / (end - start)
            x, y = x + f * (bx - x), y + f * (by - y)
            break
        if end > t and action is Action.GOTHROUGH:
            (x, y) = builder.site.opening(arg).center
            fluents.room, fluents.beside = room_after, ""
            in_progress = InProgress(action.value, (arg,), float(end), room_after)
            break
        (x, y) = _point(builder, rule.ends_at, arg, fluents.room, room_after) or (x, y)
        if end > t and rule.in_place:
            fluents.beside = ""
            in_progress = InProgress(action.value, (arg,), float(end))
            break
        fluents.apply(action, arg, room_after)
    return RobotState(
        state.id,
        (x, y, state.pose[2]),
        frozenset(fluents.carrying),
        frozenset(fluents.delivered),
        fluents.beside,
        in_progress,
    )


def _entered(
    builder: ProblemBuilder, state: RobotState, plan: RobotPlan, result: TeamResult, step: Step, room: str
) -> str:
    """The room a gothrough step taken from ``room`` enters: the one the robot is already entering,
    the plan's pass, or the opening's other side."""
    arg = step.args[0]
    ip = state.in_progress
    if (
        ip is not None
        and ip.action == Action.GOTHROUGH
        and ip.args[:1] == (arg,)
        and step is plan.steps[0]
        and ip.target
    ):
        return ip.target
    start = result.absolute(step.start)
    passed = next((p.dst for p in plan.passes if p.opening == arg and result.absolute(p.start) == start and p.dst), "")
    if passed:
        return passed
    opening = builder.site.opening(arg)
    return opening.other(room) if room in opening.rooms else opening.rooms[1]


def _point(builder: ProblemBuilder, ends_at: EndsAt, arg: str, room: str, room_after: str) -> Point | None:
    """Where a step that ends at ``ends_at`` leaves the robot (None: where it was)."""
    match ends_at:
        case EndsAt.NEAR_SIDE:
            return builder.wait_point(arg, room)
        case EndsAt.FAR_SIDE:
            return builder.beside(arg, room_after)
        case EndsAt.OBJECT:
            return builder.object_point(arg)
        case EndsAt.DROP:
            return builder.drop_point(arg)
    return None
