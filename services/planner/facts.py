"""ASP facts for the encoding: the site's doors, each robot's problem, and what other robots fixed.

Times are integer seconds relative to ``base(B)``, the whole site-clock second the plan starts
from; the vocabulary atoms (``human_opens``, ``goes_through``, ``robot_in``) add ``B`` back, so the
restrictor's constraints see absolute site-clock seconds. The predicates are documented at the
top of ``domain.lp``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from protocol.site import Site

from .problem import RobotProblem


@dataclass(frozen=True)
class Busy:
    """Another robot occupies the doorway of ``opening`` during [start, end) (relative seconds)."""

    opening: str
    start: int
    end: int
    owner: str


@dataclass(frozen=True)
class Context:
    """What a robot's plan must live with.

    ``given_open``: door openings that exist anyway (a door open right now, or an opening other
    robots' fixed plans use) - free to share. ``busy``: doorway occupancy it must not overlap.
    ``others_end``: when the robots whose plans are fixed finish (None: there are none).
    ``horizon``: the robot must finish by then; IIDP sets it to the team's current completion time
    when only a plan that does not delay the team can improve it."""

    given_open: tuple[tuple[str, int], ...] = ()
    blocked_open: tuple[tuple[str, int], ...] = ()  # windows that exist but may not be shared
    busy: tuple[Busy, ...] = ()
    others_end: int | None = None
    horizon: int | None = None  # no robot may finish later (None: no bound)
    syncwait: int = 40  # s a robot may wait to share an opening or for one to end
    clearwait: int = 8  # s a robot may wait for a busy doorway to clear


def hold_seconds(site: Site) -> int:
    """``door_hold_time`` in whole seconds, rounded down so a planned crossing never outlasts the door."""
    return max(int(math.floor(site.params.door_hold_time + 1e-9)), 1)


def site_facts(site: Site, base: int) -> str:
    """Doors, rooms and the base time."""
    lines = [f"base({base}).", f"hold({hold_seconds(site)})."]
    for oid, opening in sorted(site.openings.items()):
        lines.append(f"opening({oid}).")
        if opening.kind == "door" and opening.human_operated:
            lines.append(f"human_door({oid}).")
        for room in opening.rooms:
            lines.append(f"adjacent({oid},{room}).")
    for rid in sorted(site.rooms):
        lines.append(f"room({rid}).")
    return "\n".join(lines) + "\n"


def time_point_facts(site: Site, base: int, numbers: set[int]) -> str:
    """Seconds written in the constraints become points where a wait may end, at every opening.

    The restrictor's facts say where their windows end (vocabulary.lp turns those into event
    points); this also covers a constraint written only as a rule, e.g. ``:- goes_through(r, x, T),
    T < t1.``, which a robot can only meet by waiting until ``t1``."""
    rel = sorted(n - base for n in numbers if base < n <= base + NO_HORIZON)
    return "".join(f"evt({x},{t}).\n" for x in sorted(site.openings) for t in rel)


def robot_facts(p: RobotProblem) -> str:
    r = p.robot
    lines = [f"robot({r}).", f"capacity({r},{p.capacity}).", f"start({r},{p.room},{p.ready}).", f"nstops({r},{len(p.stops)})."]
    if p.legs:
        lines.append(f"minleg({r},{min(leg_duration(leg) for leg in p.legs)}).")
    lines += [f"carrying0({r},{o})." for o in p.carrying]
    lines += [f"stop({r},{key})." for key in p.stops]
    for leg in p.legs:
        lines.append(f"leg({r},{leg.origin},{leg.stop},{leg.id}). ncross({leg.id},{len(leg.crossings)}). tail({leg.id},{leg.room},{leg.tail}).")
        rest = leg.tail
        for k in range(len(leg.crossings), 0, -1):
            c = leg.crossings[k - 1]
            rest += c.through
            lines.append(f"cross({leg.id},{k},{c.opening},{c.src},{c.dst},{c.approach},{c.through}). rest({leg.id},{k},{rest}).")
            rest += c.approach
    return "\n".join(lines) + "\n"


def leg_duration(leg) -> int:
    """Driving and working time of a leg without waits."""
    return leg.tail + sum(c.approach + c.through for c in leg.crossings)


NO_HORIZON = 10_000_000  # s; far beyond any plan, small enough that base + it fits a 32-bit ASP integer


def context_facts(ctx: Context) -> str:
    lines = [f"horizon({ctx.horizon if ctx.horizon is not None else NO_HORIZON}). syncwait({ctx.syncwait}). clearwait({ctx.clearwait})."]
    lines += [f"given_open({d},{t})." for d, t in sorted(set(ctx.given_open))]
    lines += [f"blocked_open({d},{t})." for d, t in sorted(set(ctx.blocked_open))]
    lines += [f"busy({b.opening},{b.start},{b.end},{b.owner})." for b in sorted(set(ctx.busy), key=lambda b: (b.opening, b.start, b.end, b.owner))]
    if ctx.others_end is not None:
        lines.append(f"others_end({ctx.others_end}).")
    return "\n".join(lines) + "\n"
