"""Where a plan puts the team at a given time, if executed exactly as planned.

Replanning happens mid-mission, from robots that are part-way through their plans; this gives such
worlds without a simulator (benchmarks, tests): every step that ended by ``t`` is done, a gothrough
or a load/unload under way at ``t`` is in progress (it must be finished first), a robot approaching
an opening is part-way there, one waiting stands where its last step left it, and doors the human
opened for the plan are open while their hold window lasts.
"""

from __future__ import annotations

from dataclasses import replace

from .plan import TeamResult
from .problem import ProblemBuilder
from .world import InProgress, RobotState, World


def world_at(builder: ProblemBuilder, world: World, result: TeamResult, t: float) -> World:
    """The world ``result`` (planned from ``world``) leads to at site-clock time ``t``."""
    site = builder.site
    robots: dict[str, RobotState] = {}
    for rid, state in world.robots.items():
        plan = result.plans.get(rid)
        if plan is None:
            robots[rid] = state
            continue
        room = builder.robot_room(state)
        x, y, theta = state.pose
        carrying, delivered = set(state.carrying), set(state.delivered)
        beside = state.beside
        in_progress = None
        for step in plan.steps:
            start, end = result.absolute(step.start), result.absolute(step.end)
            arg = step.args[0] if step.args else ""
            if start > t:
                break
            if step.action == "gothrough":
                opening = site.opening(arg)
                ip = state.in_progress
                dst = (
                    ip.target
                    if ip is not None and ip.action == "gothrough" and ip.args[:1] == (arg,) and step is plan.steps[0]
                    else ""
                )
                dst = dst or next(
                    (p.dst for p in plan.passes if p.opening == arg and result.absolute(p.start) == start and p.dst),
                    opening.other(room) if room in opening.rooms else opening.rooms[1],
                )
                if end > t:
                    (x, y), beside = opening.center, ""
                    in_progress = InProgress("gothrough", (arg,), float(end), dst)
                    room = dst
                    break
                (x, y), room, beside = builder.beside(arg, dst), dst, ""
            elif step.action in ("approach", "opendoor"):
                bx, by = builder.beside(arg, room)
                if end > t and step.action == "approach":
                    # part-way along the (straight, within one room) drive
                    f = (t - start) / (end - start)
                    x, y = x + f * (bx - x), y + f * (by - y)
                    break
                (x, y), beside = (bx, by), arg
            elif step.action in ("load", "unload"):
                (x, y) = builder.object_point(arg) if step.action == "load" else builder.drop_point(arg)
                beside = ""
                if end > t:
                    in_progress = InProgress(step.action, (arg,), float(end))
                    break
                if step.action == "load":
                    carrying.add(arg)
                else:
                    carrying.discard(arg)
                    delivered.add(arg)
        robots[rid] = RobotState(rid, (x, y, theta), frozenset(carrying), frozenset(delivered), beside, in_progress)
    open_doors = {
        o.door: float(result.absolute(o.start))
        for o in result.openings
        if result.absolute(o.start) <= t < result.absolute(o.end)
    }
    return replace(world, now=float(t), robots=robots, open_doors=open_doors)
