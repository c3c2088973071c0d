"""An independent check that a team plan can be executed, written without the ASP encoding.

It replays every robot's steps from the world the plan was made for, tracking the fluents the
domain talks about (room, the opening the robot stands beside, what it carries, what is delivered),
and checks:

- actions are well formed and in time order (a step never starts before the previous one ended);
- preconditions: approach an opening of the current room; opendoor only for a human-operated door
  the robot stands beside; gothrough only right after approaching that opening (or in progress),
  and through a human-operated door only after opendoor and inside a planned opening window;
  load an object of this robot, in its room, within capacity; unload a carried object in its
  destination room;
- every object reaches its destination, carried by its own robot;
- the openings: human-operated doors only, windows of one door never overlap, none starts inside a
  window in which the human said she is unavailable;
- no two robots in one doorway at once; no robot in a room while it is forbidden;
- each step lasts at least as long as driving its straight-line distance (a lower bound).

Returns the violations as readable strings; an empty list means the plan is valid.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import pairwise

from protocol.actions import STEPS, Action, EndsAt, Fluents
from protocol.asp_terms import InterpretedFact
from protocol.site import Opening, Site

from .key_points import BESIDE_MARGIN, wait_offset
from .plan import TeamResult
from .problem import ProblemBuilder
from .world import World

TIME_TOLERANCE = 1.0  # s: plan times are whole seconds


@dataclass(frozen=True)
class StepView:
    action: str
    args: tuple[str, ...]
    start: float
    end: float


@dataclass
class Windows:
    """Time windows stated by constraints (absolute site-clock seconds)."""

    unavailable: list[tuple[str, int, int]] = field(default_factory=list)  # (door, t0, t1)
    forbidden: list[tuple[str, int, int]] = field(default_factory=list)  # (room, t0, t1)

    @classmethod
    def of(cls, facts: Iterable[InterpretedFact]) -> Windows:
        """The windows the ``human_unavailable`` and ``room_forbidden`` facts of constraints state
        (:meth:`services.planner.constraints.ConstraintProgram.facts`)."""
        out = cls()
        for fact in facts:
            if fact.predicate == "human_unavailable":
                out.unavailable.append((fact.subject, fact.start, fact.end))
            elif fact.predicate == "room_forbidden":
                out.forbidden.append((fact.subject, fact.start, fact.end))
        return out


def validate_result(site: Site, world: World, result: TeamResult, windows: Windows | None = None) -> list[str]:
    robots = {
        rid: [StepView(s.action, s.args, result.absolute(s.start), result.absolute(s.end)) for s in plan.steps]
        for rid, plan in result.plans.items()
    }
    openings = [(o.door, result.absolute(o.start), result.absolute(o.end)) for o in result.openings]
    existing = {(d, result.absolute(t)) for d, t in result.existing}
    return validate(site, world, robots, openings, windows or Windows(), existing=existing)


def validate(
    site: Site,
    world: World,
    robots: dict[str, Sequence[StepView]],
    openings: Sequence[tuple[str, float, float]],
    windows: Windows,
    *,
    existing: set[tuple[str, float]] = frozenset(),  # type: ignore[assignment]
    builder: ProblemBuilder | None = None,
) -> list[str]:
    errors: list[str] = []
    hold = site.params.door_hold_time
    speed = site.params.robot_speed
    delivered_before = world.delivered
    passes: dict[str, list[tuple[float, float, str]]] = {}
    stays: list[tuple[str, str, float, float]] = []  # robot, room, S, E
    for rid in sorted(site.robots):
        steps = list(robots.get(rid, []))
        state = world.robots.get(rid)
        if state is None:
            errors.append(f"{rid}: not in the world")
            continue
        fl = Fluents(_room_of(site, state, builder), state.beside, set(state.carrying), set(state.delivered))
        pos: tuple[float, float] | None = (state.pose[0], state.pose[1])
        in_progress = state.in_progress
        t = world.now - TIME_TOLERANCE
        since = world.now
        prev = None
        for i, step in enumerate(steps):
            where = f"{rid} step {i} {step.action}({','.join(step.args)}) [{step.start:g},{step.end:g}]"
            if step.end < step.start:
                errors.append(f"{where}: ends before it starts")
            if step.start < t - 1e-6:
                errors.append(f"{where}: starts before the previous step ends ({t:g})")
            t = max(t, step.end)
            if step.action not in STEPS:
                errors.append(f"{where}: unknown action")
                prev = step
                continue
            action, arg = Action(step.action), step.args[0] if step.args else ""
            # the robot is in the middle of this step (it must finish it first)
            first_in_progress = i == 0 and in_progress is not None
            continuing = first_in_progress and in_progress.action == action and in_progress.args[:1] == (arg,)
            room_after = ""
            if action is Action.APPROACH:
                opening = _opening(site, arg)
                if opening is None or fl.room not in opening.rooms:
                    errors.append(f"{where}: {arg} is not an opening of room {fl.room}")
                    fl.apply(action, arg)
                    prev = step
                    continue
            elif action is Action.OPENDOOR:
                opening = _opening(site, arg)
                if opening is None or opening.kind != "door" or not opening.human_operated:
                    errors.append(f"{where}: {arg} is not a human-operated door")
                if fl.beside != arg:
                    errors.append(f"{where}: the robot is not beside {arg} (beside {fl.beside or 'nothing'})")
            elif action is Action.GOTHROUGH:
                opening = _opening(site, arg)
                if opening is None:
                    errors.append(f"{where}: unknown opening {arg}")
                    continue
                if continuing:
                    fl.room = opening.other(in_progress.target)  # it is leaving this room
                elif fl.room not in opening.rooms:
                    errors.append(f"{where}: {arg} is not an opening of room {fl.room}")
                    continue
                if not continuing:
                    _check_entry(errors, where, opening, fl.beside, prev, step, openings)
                room_after = opening.other(fl.room)
                stays.append((rid, fl.room, since, step.end))
                passes.setdefault(arg, []).append((step.start, step.end, rid))
                since = step.start
            else:
                spec = site.objects.get(arg)
                if spec is None:
                    errors.append(f"{where}: unknown object {arg}")
                    continue
                under_way = in_progress.action if first_in_progress else ""
                _check_handling(errors, where, site, rid, fl, step, delivered_before, under_way)
            target = _end_point(site, STEPS[action].ends_at, arg, fl.room, room_after)
            if STEPS[action].straight_line and pos is not None and not continuing:
                _check_duration(errors, where, pos, target, speed, step)
            if STEPS[action].ends_at is not EndsAt.STAYS:
                pos = target
            fl.apply(action, arg, room_after)
            prev = step
        stays.append((rid, fl.room, since, max(t, since)))
        for obj, spec in site.objects.items():
            if spec.robot == rid and obj not in fl.delivered and obj not in delivered_before:
                errors.append(f"{rid}: object {obj} is never delivered")
    _check_openings(errors, site, openings, windows, existing, hold)
    for opening, items in passes.items():
        items.sort()
        for (_s1, e1, r1), (s2, _e2, r2) in pairwise(items):
            if r1 != r2 and s2 < e1 - 1e-6:
                errors.append(f"{r1} and {r2} are both in the doorway of {opening} at {s2:g}")
    for room, t0, t1 in windows.forbidden:
        for rid, r, s, e in stays:
            if r == room and s < t1 and e > t0:
                errors.append(f"{rid} is in forbidden room {room} during [{max(s, t0):g}, {min(e, t1):g})")
    return errors


def _check_entry(
    errors: list[str],
    where: str,
    opening: Opening,
    beside: str,
    prev: StepView | None,
    step: StepView,
    openings: Sequence[tuple[str, float, float]],
) -> None:
    """A gothrough not under way: after approaching the opening, and through a human-operated door
    only after opendoor and inside a planned opening window."""
    arg = opening.id
    if beside != arg:
        errors.append(f"{where}: not preceded by approach({arg})")
    if opening.kind == "door" and opening.human_operated:
        if prev is None or prev.action != Action.OPENDOOR or prev.args[:1] != (arg,):
            errors.append(f"{where}: a human-operated door without opendoor first")
        if not any(d == arg and s - 1e-6 <= step.start and step.end <= e + 1e-6 for d, s, e in openings):
            errors.append(f"{where}: the door is not open then (no planned opening covers it)")


def _check_handling(
    errors: list[str],
    where: str,
    site: Site,
    rid: str,
    fl: Fluents,
    step: StepView,
    delivered_before: frozenset[str],
    under_way: str,
) -> None:
    """A load or unload: the robot's own object, in the right room, within capacity; it lasts
    load_time unless the robot is in the middle of an action (``under_way``: its name) at the start."""
    arg = step.args[0]
    spec = site.objects[arg]
    if spec.robot != rid:
        errors.append(f"{where}: {arg} belongs to {spec.robot}")
    if step.action == Action.LOAD:
        if arg in fl.carrying or arg in fl.delivered or arg in delivered_before:
            errors.append(f"{where}: {arg} is already carried or delivered")
        if fl.room != spec.room and under_way != Action.LOAD:
            errors.append(f"{where}: {arg} is in {spec.room}, the robot in {fl.room}")
        if len(fl.carrying) >= site.params.robot_capacity:
            errors.append(f"{where}: capacity {site.params.robot_capacity} exceeded")
    else:
        if arg not in fl.carrying:
            errors.append(f"{where}: {arg} is not carried")
        if fl.room != spec.deliver_to:
            errors.append(f"{where}: {arg} goes to {spec.deliver_to}, the robot is in {fl.room}")
    if step.end - step.start < site.params.load_time - TIME_TOLERANCE and not under_way:
        errors.append(f"{where}: shorter than load_time")


def _end_point(site: Site, ends_at: EndsAt, arg: str, room: str, room_after: str) -> tuple[float, float] | None:
    """Where a step leaves the robot, in the site's own geometry (None: not known here - the drop
    point is the planner's choice - or where it was)."""
    margin = site.params.robot_radius + BESIDE_MARGIN
    match ends_at:
        case EndsAt.NEAR_SIDE:
            opening = site.opening(arg)
            return opening.aside(room, margin, wait_offset(site.params.robot_radius, opening.width))
        case EndsAt.FAR_SIDE:
            return site.opening(arg).beside(room_after, margin)
        case EndsAt.OBJECT:
            return site.objects[arg].position
    return None


def _check_openings(
    errors: list[str],
    site: Site,
    openings: Sequence[tuple[str, float, float]],
    windows: Windows,
    existing: set,
    hold: float,
) -> None:
    by_door: dict[str, list[float]] = {}
    for door, start, _end in openings:
        opening = site.openings.get(door)
        if opening is None or opening.kind != "door" or not opening.human_operated:
            errors.append(f"opening of {door} at {start:g}: not a human-operated door")
        by_door.setdefault(door, []).append(start)
        if (door, start) in existing:
            continue
        for d, t0, t1 in windows.unavailable:
            if d == door and t0 <= start < t1:
                errors.append(f"opening of {door} at {start:g}: the human is unavailable in [{t0}, {t1})")
    for door, starts in by_door.items():
        starts.sort()
        for a, b in pairwise(starts):
            if b < a + math.floor(hold) - 1e-6:
                errors.append(f"openings of {door} at {a:g} and {b:g} overlap (hold {hold:g} s)")


def _check_duration(
    errors: list[str], where: str, a: tuple[float, float], b: tuple[float, float], speed: float, step: StepView
) -> None:
    need = math.dist(a, b) / speed
    if step.end - step.start < need - TIME_TOLERANCE - 1e-6:
        errors.append(f"{where}: {step.end - step.start:g} s is less than the {need:.1f} s the straight line takes")


def _opening(site: Site, opening_id: str):
    try:
        return site.opening(opening_id)
    except KeyError:
        return None


def _room_of(site: Site, state, builder: ProblemBuilder | None) -> str:
    if builder is not None:
        return builder.robot_room(state)
    room = site.room_at(state.pose[0], state.pose[1])
    if room is not None:
        return room.id
    x, y = state.pose[0], state.pose[1]
    return min(
        site.rooms.values(),
        key=lambda r: math.hypot(max(r.rect[0] - x, 0, x - r.rect[2]), max(r.rect[1] - y, 0, y - r.rect[3])),
    ).id
