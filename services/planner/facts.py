"""ASP facts for the encoding: the site's doors, each robot's problem, and what other robots fixed.

Times are integer seconds relative to ``base(B)``, the whole site-clock second the plan starts
from; the vocabulary atoms (``human_opens``, ``goes_through``, ``robot_in``) add ``B`` back, so the
restrictor's constraints see absolute site-clock seconds. The predicates are documented at the
top of ``domain.lp``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
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
    lines = [
        f"robot({r}).",
        f"capacity({r},{p.capacity}).",
        f"start({r},{p.room},{p.ready}).",
        f"nstops({r},{len(p.stops)}).",
    ]
    lines += [f"carrying0({r},{o})." for o in p.carrying]
    lines += [f"stop({r},{key})." for key in p.stops]
    for leg in p.legs:
        lines.append(
            f"leg({r},{leg.origin},{leg.stop},{leg.id}). ncross({leg.id},{len(leg.crossings)}). "
            f"tail({leg.id},{leg.room},{leg.tail})."
        )
        rest = leg.tail
        for k in range(len(leg.crossings), 0, -1):
            c = leg.crossings[k - 1]
            rest += c.through
            lines.append(
                f"cross({leg.id},{k},{c.opening},{c.src},{c.dst},{c.approach},{c.through}). rest({leg.id},{k},{rest})."
            )
            rest += c.approach
    lines += after_facts(p)
    return "\n".join(lines) + "\n"


def after_facts(p: RobotProblem) -> list[str]:
    """``after(R,P,S,A)`` for every stop S that a chain of P legs from the start can reach: the stops
    left after it take at least A s (each at least its shortest leg in; the cheapest of them). The
    horizon bounds every time before S at P by it (domain.lp)."""
    r, n = p.robot, len(p.stops)
    into: dict[str, int] = {}
    leads: dict[str, set[str]] = {}
    for leg in p.legs:
        d = leg_duration(leg)
        into[leg.stop] = min(d, into.get(leg.stop, d))
        leads.setdefault(leg.origin, set()).add(leg.stop)
    lines: list[str] = []
    reach = {"start"}
    for pos in range(1, n + 1):
        reach = {s for origin in reach for s in leads.get(origin, ())}
        for stop in sorted(reach):
            left = sorted(d for s, d in into.items() if s != stop)[: n - pos]
            lines.append(f"after({r},{pos},{stop},{sum(left)}).")
    return lines


def leg_duration(leg) -> int:
    """Driving and working time of a leg without waits."""
    return leg.tail + sum(c.approach + c.through for c in leg.crossings)


NO_HORIZON = 10_000_000  # s; far beyond any plan, small enough that base + it fits a 32-bit ASP integer


def context_facts(ctx: Context, group: str) -> str:
    """The context of ``group`` (a robot planned against fixed others, or ``team`` in the joint
    program); ``grp(R,Q)`` facts put robots in it."""
    q = group
    lines = [
        f"horizon({q},{ctx.horizon if ctx.horizon is not None else NO_HORIZON}). syncwait({q},{ctx.syncwait}). "
        f"clearwait({q},{ctx.clearwait})."
    ]
    lines += [f"given_open({q},{d},{t})." for d, t in sorted(set(ctx.given_open))]
    lines += [f"blocked_open({q},{d},{t})." for d, t in sorted(set(ctx.blocked_open))]
    lines += [
        f"busy({q},{b.opening},{b.start},{b.end},{b.owner})."
        for b in sorted(set(ctx.busy), key=lambda b: (b.opening, b.start, b.end, b.owner))
    ]
    if ctx.others_end is not None:
        lines.append(f"others_end({q},{ctx.others_end}).")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- what the context alone decides
# Per second, so that grounding settles them (domain.lp, doors.lp, makespan.lp): no wait ends where
# the gothrough that follows cannot happen, and no time after such a wait is ever grounded. Written
# as spans (``blocked(r0,x,88..99,3).``) that clingo unfolds.

Span = tuple[int, int]  # inclusive seconds


def merged(spans: Iterable[Span]) -> list[Span]:
    """The spans joined where they overlap or touch."""
    out: list[Span] = []
    for a, b in sorted(s for s in spans if s[0] <= s[1]):
        if out and a <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def minus(spans: list[Span], cut: list[Span]) -> list[Span]:
    """The seconds of ``spans`` (merged) outside ``cut`` (merged)."""
    out: list[Span] = []
    for a, b in spans:
        for c, d in cut:
            if d < a or c > b:
                continue
            if c > a:
                out.append((a, c - 1))
            a = max(a, d + 1)
            if a > b:
                break
        if a <= b:
            out.append((a, b))
    return out


def _spans(name: str, head: str, spans: list[Span], tail: str = "") -> list[str]:
    return [f"{name}({head},{a}..{b}{tail})." if a < b else f"{name}({head},{a}{tail})." for a, b in spans]


def throughs(problems: Iterable[RobotProblem]) -> dict[str, set[int]]:
    """Opening -> the seconds the robots' gothroughs of it last."""
    out: dict[str, set[int]] = {}
    for p in problems:
        for leg in p.legs:
            for c in leg.crossings:
                out.setdefault(c.opening, set()).add(c.through)
    return out


def _near(ctx: Context, door: str, hold: int) -> list[Span]:
    """Seconds at which an opening of ``door`` would overlap a window that exists anyway (or leave no
    closed second between them); doors.lp forbids it."""
    windows = [t for d, t in set(ctx.given_open) | set(ctx.blocked_open) if d == door]
    return merged([(t - hold, t - 1) for t in windows] + [(t + 1, t + hold) for t in windows])


def door_facts(ctx: Context, group: str, through: dict[str, set[int]], hold: int) -> str:
    """``near(Q,D,T)``: an opening of human door D may not start at T (see :func:`_near`);
    ``blocked(Q,X,T,Dg)``: a gothrough of X lasting Dg s starting at T overlaps a fixed occupancy."""
    q = group
    lines: list[str] = []
    for door in sorted({d for d, _ in ctx.given_open} | {d for d, _ in ctx.blocked_open}):
        lines += _spans("near", f"{q},{door}", _near(ctx, door, hold))
    busy: dict[str, list[Busy]] = {}
    for b in ctx.busy:
        busy.setdefault(b.opening, []).append(b)
    for x in sorted(busy):
        for dg in sorted(through.get(x, ())):
            lines += _spans("blocked", f"{q},{x}", merged((b.start - dg + 1, b.end - 1) for b in busy[x]), f",{dg}")
    return "\n".join(lines) + "\n" if lines else ""


def recross(p: RobotProblem, door: str, hold: int) -> bool:
    """Whether the robot can come back through ``door`` (out of the room of a stop it came in
    through it) within one hold window, i.e. in the opening it asked for on its way in."""
    for l1 in p.legs:
        if not l1.crossings or l1.crossings[-1].opening != door:
            continue
        for l2 in p.legs:
            if l2.origin == l1.stop and l2.crossings and l2.crossings[0].opening == door:
                if l1.crossings[-1].through + l1.tail + l2.crossings[0].approach + l2.crossings[0].through <= hold:
                    return True
    return False


def closed_facts(p: RobotProblem, ctx: Context, hold: int) -> str:
    """For a robot planned against fixed others (makespan.lp): ``closed(R,D,T,Dg)``, a gothrough of
    human door D lasting Dg s starting at T finds the door closed for good - no given window covers
    it and one is too near for a new opening - unless the robot can come back through D in its own
    opening (``shares(R,D)``, doors.lp)."""
    r = p.robot
    lines: list[str] = []
    doors = sorted({c.opening for leg in p.legs for c in leg.crossings if c.human})
    for door in doors:
        if recross(p, door, hold):
            lines.append(f"shares({r},{door}).")
            continue
        near = _near(ctx, door, hold)
        if not near:
            continue
        given = [t for d, t in ctx.given_open if d == door]
        for dg in sorted({c.through for leg in p.legs for c in leg.crossings if c.opening == door}):
            lines += _spans("closed", f"{r},{door}", minus(near, merged((t, t + hold - dg) for t in given)), f",{dg}")
    return "\n".join(lines) + "\n" if lines else ""
