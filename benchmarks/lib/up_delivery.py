"""The delivery problem as a ``unified-planning`` problem, and engines' plans read back as the
project's steps. ``benchmarks/peers.md`` explains the encoding and what it simplifies.

One site, one world and optionally one window in which the human opens no door, encoded three ways:

- ``temporal`` (:func:`encode`, TAMER, Aries): durative actions ``approach``, ``opendoor`` (the
  human's opening, asked for by a robot beside the door, lasting the door's hold time), ``gothrough``
  (``gothrough_open`` through a human-operated door: it must lie inside an opening, so robots wait
  for one and share it), ``load`` and ``unload``; the window as timed initial literals.
- ``unshared`` (LPG, which has no required concurrency: no action can be made to fit inside
  another's interval): a human-operated door is crossed by one action, ``pass_door``, that asks for
  the door, goes through and lasts the door's hold time; no robot shares another's opening.
- ``clock`` (ENHSP, which takes no durative actions): instantaneous actions, each robot with a clock
  (a numeric fluent) that every action moves by its duration; a doorway keeps the time it is next
  free and a human-operated door the start of its last opening; ``wait_*`` actions move a clock up to
  such a time. Passes of a doorway and openings of a door happen in plan order.

Durations are the planner's own (:class:`services.planner.problem.ProblemBuilder`): the motion
planner's path lengths between the key points at ``robot_speed``, ``load_time`` for a load or
unload, rounded up to whole seconds, so a peer's plan and IIDP's are timed by the same clock.
:meth:`Encoding.steps` reads a plan back into what :func:`services.planner.validator.validate`
checks: every robot's timed steps and the human's openings.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from fractions import Fraction

from unified_planning.engines.sequential_simulator import UPSequentialSimulator
from unified_planning.model import FNode, Type
from unified_planning.plans import ActionInstance, Plan, SequentialPlan, TimeTriggeredPlan
from unified_planning.shortcuts import (
    GE,
    LE,
    LT,
    And,
    BoolType,
    ClosedTimeInterval,
    DurativeAction,
    EndTiming,
    Equals,
    Fluent,
    GlobalStartTiming,
    InstantaneousAction,
    IntType,
    Not,
    Object,
    Or,
    Plus,
    Problem,
    RealType,
    StartTiming,
    UserType,
)

from protocol.actions import Action
from protocol.site import Site
from services.planner.facts import hold_seconds
from services.planner.motion import Point
from services.planner.problem import ProblemBuilder
from services.planner.validator import StepView
from services.planner.world import World

Window = tuple[str, int, int]  # door, t0, t1: the human opens no door D in [t0, t1) (site seconds)
ENCODINGS = ("temporal", "unshared", "clock")
NEVER = -1_000_000  # s: the start of a door's "last opening" before any (long closed at time 0)
MAX_DURATION = 100_000  # s: an upper bound for a duration fluent (Aries takes only bounded integers)


@dataclass(frozen=True)
class Place:
    """A point a robot can be at, as the planner's key points define it."""

    name: str  # the object's name in the problem
    room: str
    point: Point
    kind: str  # "start" | "object" | "drop" | "wait" (beside an opening, to cross it) | "far" (crossed)
    owner: str = ""  # the robot whose start, object or drop point it is
    opening: str = ""  # for "wait" and "far": the opening
    obj: str = ""  # for "object" and "drop": the object


@dataclass
class Encoding:
    """A problem and what its names mean in the site."""

    problem: Problem
    kind: str  # one of ENCODINGS
    hold: int  # s a human-operated door stays open
    places: dict[str, Place]
    human_doors: frozenset[str]
    durations: dict[tuple[str, str, str], int] = field(default_factory=dict)  # (fluent, a, b) -> s
    now: float = 0.0  # the world's site-clock time: the problem's time 0

    @property
    def robots(self) -> list[str]:
        return sorted(o.name for o in self.problem.objects(self.problem.user_type("robot")))

    # ------------------------------------------------------------------ plans back into steps

    def steps(self, plan: Plan) -> tuple[dict[str, list[StepView]], list[tuple[str, float, float]]]:
        """Each robot's steps and the human's openings ``(door, start, end)`` in a plan of this problem.

        The wait beside a human-operated door before going through becomes the ``opendoor`` step the
        project's plans have there (the robot has asked and waits for the human)."""
        if isinstance(plan, TimeTriggeredPlan):
            timed = [(Fraction(s), a, Fraction(d or 0)) for s, a, d in plan.timed_actions]
        elif isinstance(plan, SequentialPlan):
            timed = self.clock_times(plan)
        else:
            raise TypeError(f"cannot read a {type(plan).__name__}")
        robots: dict[str, list[StepView]] = {r: [] for r in self.robots}
        openings: list[tuple[str, float, float]] = []
        for start, ai, dur in sorted(timed, key=lambda t: (t[0], t[1].action.name != "opendoor")):
            name = ai.action.name
            args = [str(p) for p in ai.actual_parameters]
            rid, s, e = args[0], self.now + float(start), self.now + float(start + dur)
            out = robots[rid]
            if name == "approach":
                out.append(StepView(Action.APPROACH.value, (self.places[args[2]].opening,), s, e))
            elif name == "opendoor":
                openings.append((args[2], s, s + self.hold))
            elif name in ("gothrough", "gothrough_open", "pass_door"):
                door = args[2]
                through = self.durations[("through", args[1], args[3])]
                if name == "pass_door":
                    openings.append((door, s, s + self.hold))
                if door in self.human_doors:
                    out.append(StepView(Action.OPENDOOR.value, (door,), out[-1].end if out else s, s))
                out.append(StepView(Action.GOTHROUGH.value, (door,), s, s + through))
            elif name in ("load", "unload"):
                out.append(StepView(name, (self.places[args[3]].obj,), s, e))
            elif not name.startswith("wait_"):
                raise ValueError(f"unknown action {name}")
        return robots, openings

    def clock_times(self, plan: SequentialPlan) -> list[tuple[Fraction, ActionInstance, Fraction]]:
        """Start and duration of each action of a ``clock`` plan, replayed with unified-planning's
        own simulator: an action ends where it leaves its robot's clock."""
        sim = UPSequentialSimulator(self.problem)
        state = sim.get_initial_state()
        clock = self.problem.fluent("clock")
        out: list[tuple[Fraction, ActionInstance, Fraction]] = []
        for ai in plan.actions:
            nxt = sim.apply(state, ai)
            if nxt is None:
                raise ValueError(f"{ai} cannot be applied when replaying the plan")
            state = nxt
            robot = ai.actual_parameters[0]
            end = Fraction(str(state.get_value(clock(robot)).constant_value()))
            dur = Fraction(self.duration(ai))
            out.append((end - dur, ai, dur))
        return out

    def duration(self, ai: ActionInstance) -> int:
        """How long an action instance of this problem takes (0 for the clock encoding's waits and
        openings, which only move a clock or mark a time)."""
        name, args = ai.action.name, [str(p) for p in ai.actual_parameters]
        if name == "opendoor":
            return self.hold if self.kind != "clock" else 0
        if name.startswith("wait_"):
            return 0
        if name == "pass_door":
            return self.hold
        fluent = {"approach": "drive", "load": "work", "unload": "work"}.get(name, "through")
        return self.durations[(fluent, args[1], args[3] if name != "approach" else args[2])]

    def finish(self, robots: dict[str, list[StepView]]) -> float:
        """When the slowest robot ends its last step, from the world's time: the project's makespan."""
        return max((s[-1].end for s in robots.values() if s), default=self.now) - self.now


# ---------------------------------------------------------------------- the site's places


def site_places(site: Site, builder: ProblemBuilder, world: World) -> dict[str, Place]:
    """Every point a robot of ``world`` may be at: its start, its objects' pick-up and drop points,
    and the points beside every opening (where a robot waits to cross, and where a crossing ends)."""
    out: list[Place] = []
    for rid, state in sorted(world.robots.items()):
        out.append(Place(f"start_{rid}", builder.robot_room(state), state.pose[:2], "start", owner=rid))
    for oid, spec in sorted(site.objects.items()):
        if spec.robot in world.robots and oid not in world.delivered:
            out.append(Place(f"obj_{oid}", spec.room, builder.object_point(oid), "object", spec.robot, obj=oid))
            out.append(Place(f"drop_{oid}", spec.deliver_to, builder.drop_point(oid), "drop", spec.robot, obj=oid))
    for xid, opening in sorted(site.openings.items()):
        for room in opening.rooms:
            out.append(Place(f"wait_{xid}_{room}", room, builder.wait_point(xid, room), "wait", opening=xid))
            out.append(Place(f"far_{xid}_{room}", room, builder.beside(xid, room), "far", opening=xid))
    return {p.name: p for p in out}


def drives(builder: ProblemBuilder, places: Iterable[Place]) -> dict[tuple[str, str], float]:
    """Metres along the motion planner's path between two places of one room a robot may drive
    between: to a wait point (approach), to an object or a drop point (load, unload; its own), as the
    planner's legs do (:meth:`services.planner.problem.ProblemBuilder._leg`)."""
    by_room: dict[str, list[Place]] = {}
    for p in places:
        by_room.setdefault(p.room, []).append(p)
    out: dict[tuple[str, str], float] = {}
    for room, items in by_room.items():
        for a in items:
            for b in items:
                if (
                    a is b
                    or a.kind == "wait"
                    or b.kind in ("start", "far")
                    or (a.owner and b.owner and a.owner != b.owner)
                ):
                    # From beside an opening a robot only crosses it (driving on from there is never
                    # shorter than driving from where it came), never back to a start, a far point is
                    # reached by crossing, and another robot's points are of no use.
                    continue
                out[(a.name, b.name)] = builder.motion.distance(a.point, b.point, (room,))
    return out


# ---------------------------------------------------------------------- the problems


class _Builder:
    """What the three encodings share: types, objects, the static facts and the delivery state."""

    def __init__(self, site: Site, builder: ProblemBuilder, world: World, name: str, bounded: bool) -> None:
        self.site, self.builder, self.world = site, builder, world
        self.hold = hold_seconds(site)
        self.places = site_places(site, builder, world)
        self.pb = Problem(name)
        self.robot_t, self.place_t = UserType("robot"), UserType("place")
        self.opening_t, self.item_t = UserType("opening"), UserType("item")
        self.human_doors = frozenset(builder.human_doors)
        self.durations: dict[tuple[str, str, str], int] = {}
        pb = self.pb
        self.robots = {r: Object(r, self.robot_t) for r in sorted(world.robots)}
        self.place = {n: Object(n, self.place_t) for n in self.places}
        self.openings = {x: Object(x, self.opening_t) for x in sorted(site.openings)}
        self.items = {p.obj: Object(p.obj, self.item_t) for p in self.places.values() if p.kind == "object"}
        for group in (self.robots, self.place, self.openings, self.items):
            pb.add_objects(group.values())

        def fluent(name: str, kind: Type | None = None, default: bool | int = False, **params: Type) -> Fluent:
            f = Fluent(name, kind or BoolType(), **params)
            pb.add_fluent(f, default_initial_value=default)
            return f

        r, p, q, x, o = self.robot_t, self.place_t, self.place_t, self.opening_t, self.item_t
        self.at = fluent("at", r=r, p=p)
        self.waiting = fluent("waiting", o=o)  # in its room, not loaded yet
        self.carrying = fluent("carrying", r=r, o=o)
        self.delivered = fluent("delivered", o=o)
        self.owns = fluent("owns", r=r, o=o)
        self.object_at = fluent("object_at", o=o, p=p)
        self.drop_at = fluent("drop_at", o=o, p=p)
        self.link = fluent("link", a=p, b=q)  # a robot may drive from a to b (one room)
        self.is_wait = fluent("is_wait", p=p)
        self.wait_of = fluent("wait_of", p=p, x=x)
        self.crossing = fluent("crossing", a=p, x=x, b=q)  # through x from the wait point a to b
        self.human = fluent("human", x=x)
        self.self_open = fluent("self_open", x=x)  # a passage, or a door robots open themselves
        count, seconds = (
            (IntType(0, site.params.robot_capacity), IntType(0, MAX_DURATION)) if bounded else (IntType(),) * 2
        )
        self.load_count = fluent("load_count", count, 0, r=r)
        for name in ("drive", "work", "through"):
            setattr(self, name, fluent(name, seconds, 0, a=p, b=q))
        self._static()

    def _static(self) -> None:
        pb, b, params = self.pb, self.builder, self.site.params
        for rid, robot in self.robots.items():
            pb.set_initial_value(self.at(robot, self.place[f"start_{rid}"]), True)
        for oid, item in self.items.items():
            spec = self.site.objects[oid]
            pb.set_initial_value(self.owns(self.robots[spec.robot], item), True)
            pb.set_initial_value(self.object_at(item, self.place[f"obj_{oid}"]), True)
            pb.set_initial_value(self.drop_at(item, self.place[f"drop_{oid}"]), True)
            pb.set_initial_value(self.waiting(item), True)
            pb.add_goal(self.delivered(item))
        for (a, c), metres in drives(b, self.places.values()).items():
            target = self.places[c]
            pb.set_initial_value(self.link(self.place[a], self.place[c]), True)
            if target.kind == "wait":
                self._duration("drive", a, c, b.seconds(metres))
            else:  # drive there, then load or unload
                self._duration("work", a, c, b.seconds(metres, params.load_time))
        for xid, opening in self.site.openings.items():
            x = self.openings[xid]
            pb.set_initial_value(self.human(x) if xid in self.human_doors else self.self_open(x), True)
            for room in opening.rooms:
                other = opening.other(room)
                w, f = f"wait_{xid}_{room}", f"far_{xid}_{other}"
                pb.set_initial_value(self.is_wait(self.place[w]), True)
                pb.set_initial_value(self.wait_of(self.place[w], x), True)
                pb.set_initial_value(self.crossing(self.place[w], x, self.place[f]), True)
                # the planner's gothrough: at least one second (problem.ProblemBuilder._leg)
                metres = b.motion.distance(self.places[w].point, self.places[f].point, (room, other))
                self._duration("through", w, f, max(b.seconds(metres), 1))

    def _duration(self, name: str, a: str, c: str, seconds: int) -> None:
        self.durations[(name, a, c)] = seconds
        self.pb.set_initial_value(getattr(self, name)(self.place[a], self.place[c]), seconds)

    def encoding(self, kind: str) -> Encoding:
        return Encoding(self.pb, kind, self.hold, self.places, self.human_doors, self.durations, self.world.now)


def encode(
    site: Site, builder: ProblemBuilder, world: World, window: Window | None, kind: str, *, bounded: bool = False
) -> Encoding:
    """The delivery problem of ``world`` in encoding ``kind`` (one of :data:`ENCODINGS`), with the
    human unavailable to open ``window``'s door in its interval (site seconds). ``bounded``: integer
    fluents with bounds (Aries takes no others; LPG and ENHSP take no bounded ones)."""
    if kind not in ENCODINGS:
        raise ValueError(f"unknown encoding {kind!r}")
    if any(s.carrying or s.in_progress or s.beside for s in world.robots.values()) or world.open_doors:
        # a first plan, as the benchmark makes; a mid-mission world would need more initial state
        raise ValueError("only a world where no robot carries, is doing or stands beside anything, all doors shut")
    b = _Builder(site, builder, world, f"delivery_{kind}", bounded)
    if kind == "clock":
        _clock_actions(b, window)
    else:
        _durative_actions(b, window, shared=kind == "temporal")
    return b.encoding(kind)


def _durative_actions(b: _Builder, window: Window | None, shared: bool) -> None:
    pb = b.pb
    S, E = StartTiming(), EndTiming()
    closed = _add(pb, Fluent("closed", BoolType(), x=b.opening_t), True)  # a human-operated door, shut
    is_open = _add(pb, Fluent("is_open", BoolType(), x=b.opening_t), False)
    clear = _add(pb, Fluent("clear", BoolType(), x=b.opening_t), True)  # nobody in the doorway
    available = _add(pb, Fluent("available", BoolType(), x=b.opening_t), True)  # the human may open it now
    if window is not None:
        door, t0, t1 = window
        t0, t1 = t0 - b.world.now, t1 - b.world.now
        if t0 > 0:
            pb.add_timed_effect(GlobalStartTiming(t0), available(b.openings[door]), False)
        else:
            pb.set_initial_value(available(b.openings[door]), False)
        pb.add_timed_effect(GlobalStartTiming(max(t1, 0)), available(b.openings[door]), True)
    r, p, o, x = b.robot_t, b.place_t, b.item_t, b.opening_t

    def action(name: str, **params) -> DurativeAction:
        act = DurativeAction(name, **params)
        pb.add_action(act)
        return act

    def moving(act: DurativeAction, duration, conditions: list) -> None:
        """The robot leaves place ``a`` as the action starts and is at ``c`` when it ends."""
        act.set_fixed_duration(duration)
        for cond in (b.at(act.r, act.a), *conditions):
            act.add_condition(S, cond)
        act.add_effect(S, b.at(act.r, act.a), False)
        act.add_effect(E, b.at(act.r, act.c), True)

    approach = action("approach", r=r, a=p, c=p)
    moving(approach, b.drive(approach.a, approach.c), [b.link(approach.a, approach.c), b.is_wait(approach.c)])

    load = action("load", r=r, a=p, o=o, c=p)
    moving(
        load,
        b.work(load.a, load.c),
        [b.link(load.a, load.c), b.owns(load.r, load.o), b.waiting(load.o), b.object_at(load.o, load.c)],
    )
    load.add_condition(S, LT(b.load_count(load.r), b.site.params.robot_capacity))
    load.add_effect(S, b.waiting(load.o), False)
    load.add_effect(E, b.carrying(load.r, load.o), True)
    load.add_increase_effect(E, b.load_count(load.r), 1)

    unload = action("unload", r=r, a=p, o=o, c=p)
    moving(unload, b.work(unload.a, unload.c), [b.link(unload.a, unload.c), b.carrying(unload.r, unload.o)])
    unload.add_condition(S, b.drop_at(unload.o, unload.c))
    unload.add_effect(E, b.carrying(unload.r, unload.o), False)
    unload.add_effect(E, b.delivered(unload.o), True)
    unload.add_decrease_effect(E, b.load_count(unload.r), 1)

    def crossing(name: str, kind: FNode | None = None) -> DurativeAction:
        act = action(name, r=r, a=p, x=x, c=p)
        duration = b.through(act.a, act.c) if name != "pass_door" else b.hold
        moving(act, duration, [b.crossing(act.a, act.x, act.c), (kind or b.human)(act.x)])
        return act

    # One robot at a time in a doorway: it is not clear while someone crosses it.
    names = ("gothrough", "gothrough_open") if shared else ("gothrough",)
    for name in names:
        act = crossing(name, b.self_open if name == "gothrough" else b.human)
        act.add_condition(S, clear(act.x))
        act.add_effect(S, clear(act.x), False)
        act.add_effect(E, clear(act.x), True)
    if shared:
        # The human opens the door when a robot beside it asks; it stays open for the hold time,
        # and every crossing of it lies inside one opening (required concurrency).
        through = pb.action("gothrough_open")
        through.add_condition(ClosedTimeInterval(S, E), is_open(through.x))
        opendoor = action("opendoor", r=r, a=p, x=x)
        opendoor.set_fixed_duration(b.hold)
        for cond in (
            b.at(opendoor.r, opendoor.a),
            b.wait_of(opendoor.a, opendoor.x),
            b.human(opendoor.x),
            closed(opendoor.x),
            available(opendoor.x),
        ):
            opendoor.add_condition(S, cond)
        opendoor.add_effect(S, closed(opendoor.x), False)
        opendoor.add_effect(S, is_open(opendoor.x), True)
        opendoor.add_effect(E, is_open(opendoor.x), False)
        opendoor.add_effect(E, closed(opendoor.x), True)
    else:
        # Asks for the door, goes through and stays on the far side while the door is open: the
        # door's next opening starts after this one has ended; no robot shares it.
        act = crossing("pass_door")
        act.add_condition(S, closed(act.x))
        act.add_condition(S, available(act.x))
        act.add_effect(S, closed(act.x), False)
        act.add_effect(E, closed(act.x), True)


def _add(pb: Problem, fluent: Fluent, default) -> Fluent:
    pb.add_fluent(fluent, default_initial_value=default)
    return fluent


def _clock_actions(b: _Builder, window: Window | None) -> None:
    pb = b.pb
    clock = _add(pb, Fluent("clock", RealType(), r=b.robot_t), 0)  # the robot's time (s after world.now)
    free_at = _add(pb, Fluent("free_at", RealType(), x=b.opening_t), 0)  # the doorway's last crossing ends
    opened = _add(pb, Fluent("opened", RealType(), x=b.opening_t), NEVER)  # the door's last opening starts
    r, p, o, x = b.robot_t, b.place_t, b.item_t, b.opening_t
    hold = b.hold

    def action(name: str, **params) -> InstantaneousAction:
        act = InstantaneousAction(name, **params)
        pb.add_action(act)
        return act

    def moving(act: InstantaneousAction, duration, conditions: list) -> None:
        for cond in (b.at(act.r, act.a), *conditions):
            act.add_precondition(cond)
        act.add_effect(b.at(act.r, act.a), False)
        act.add_effect(b.at(act.r, act.c), True)
        act.add_increase_effect(clock(act.r), duration)

    approach = action("approach", r=r, a=p, c=p)
    moving(approach, b.drive(approach.a, approach.c), [b.link(approach.a, approach.c), b.is_wait(approach.c)])
    load = action("load", r=r, a=p, o=o, c=p)
    moving(
        load,
        b.work(load.a, load.c),
        [b.link(load.a, load.c), b.owns(load.r, load.o), b.waiting(load.o), b.object_at(load.o, load.c)],
    )
    load.add_precondition(LT(b.load_count(load.r), b.site.params.robot_capacity))
    load.add_effect(b.waiting(load.o), False)
    load.add_effect(b.carrying(load.r, load.o), True)
    load.add_increase_effect(b.load_count(load.r), 1)
    unload = action("unload", r=r, a=p, o=o, c=p)
    moving(
        unload,
        b.work(unload.a, unload.c),
        [b.link(unload.a, unload.c), b.carrying(unload.r, unload.o), b.drop_at(unload.o, unload.c)],
    )
    unload.add_effect(b.carrying(unload.r, unload.o), False)
    unload.add_effect(b.delivered(unload.o), True)
    unload.add_decrease_effect(b.load_count(unload.r), 1)

    # A crossing starts once the doorway's last crossing (in plan order) has ended, and holds it.
    for name, kind in (("gothrough", b.self_open), ("gothrough_open", b.human)):
        act = action(name, r=r, a=p, x=x, c=p)
        through = b.through(act.a, act.c)
        moving(act, through, [b.crossing(act.a, act.x, act.c), kind(act.x), GE(clock(act.r), free_at(act.x))])
        act.add_effect(free_at(act.x), Plus(clock(act.r), through))
        if name == "gothrough_open":  # inside the door's last opening
            act.add_precondition(GE(clock(act.r), opened(act.x)))
            act.add_precondition(LE(Plus(clock(act.r), through), Plus(opened(act.x), hold)))

    def beside_door(act: InstantaneousAction) -> None:
        for cond in (b.at(act.r, act.a), b.wait_of(act.a, act.x), b.human(act.x)):
            act.add_precondition(cond)

    # The human opens the door for a robot beside it, once its last opening has ended, outside the window.
    opendoor = action("opendoor", r=r, a=p, x=x)
    beside_door(opendoor)
    opendoor.add_precondition(GE(clock(opendoor.r), Plus(opened(opendoor.x), hold)))
    opendoor.add_effect(opened(opendoor.x), clock(opendoor.r))
    # Waits: a robot beside an opening moves its clock up to a time that lets it go on.
    waits = {
        "wait_clear": (b.wait_of, free_at, 0),  # the doorway is free
        "wait_open": (b.wait_of, opened, 0),  # the door's last opening has started (to share it)
        "wait_closed": (b.wait_of, opened, hold),  # it has ended (to ask for a new one)
    }
    for name, (near, until, plus) in waits.items():
        act = action(name, r=r, a=p, x=x)
        act.add_precondition(b.at(act.r, act.a))
        act.add_precondition(near(act.a, act.x))
        act.add_precondition(LT(clock(act.r), Plus(until(act.x), plus)))
        act.add_effect(clock(act.r), Plus(until(act.x), plus))
    if window is not None:
        door, t0, t1 = window
        t0, t1 = t0 - b.world.now, t1 - b.world.now
        d = b.openings[door]
        opendoor.add_precondition(Or(Not(Equals(opendoor.x, d)), LT(clock(opendoor.r), t0), GE(clock(opendoor.r), t1)))
        wait = action("wait_available", r=r, a=p, x=x)
        beside_door(wait)
        wait.add_precondition(Equals(wait.x, d))
        wait.add_precondition(And(GE(clock(wait.r), t0), LT(clock(wait.r), t1)))
        wait.add_effect(clock(wait.r), t1)
