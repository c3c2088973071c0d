"""Reading an answer set back into timed robot plans.

The model says, per robot, which stop comes at each position (``at/3``), which leg leads there
(``use/3``), when it is beside each opening (``arr/5``), when it goes through (``go/5``) and when
each stop is done (``done/4``); together with the leg facts from :mod:`.problem` that fixes every
action and its times. Openings (``opens/3``) are matched to the passes they cover here.
"""

from __future__ import annotations

from collections.abc import Iterable

import clingo

from protocol.actions import Action

from .plan import Pass, RobotPlan, Step
from .problem import RobotProblem


def _arguments(name: str, text: str) -> list[str]:
    """The arguments of a shown atom, from the text inside its parentheses. Only a leg (l(r0,2), the
    third argument of use, arr and go) or a stop (ld(o3), the third of at and done) holds a comma or
    parentheses, so splitting on the first two commas and, after a leg or stop in the middle, on the
    last ones gives the arguments (a regular expression did the same at four times the cost)."""
    if name in ("arr", "go"):  # R,P,L,K,X with L = l(r,n)
        r, p, rest = text.split(",", 2)
        leg, k, x = rest.rsplit(",", 2)
        return [r, p, leg, k, x]
    if name == "done":  # R,P,S,T with S = ld(o) or ul(o)
        r, p, rest = text.split(",", 2)
        return [r, p, *rest.rsplit(",", 1)]
    if name in ("at", "use"):  # R,P,S or R,P,L
        return text.split(",", 2)
    return text.split(",")


def decode(
    atoms: Iterable[clingo.Symbol],
    problems: dict[str, RobotProblem],
    hold: int,
    given: Iterable[tuple[str, int]] = (),
) -> dict[str, RobotPlan]:
    at: dict[tuple[str, int], str] = {}
    use: dict[tuple[str, int], str] = {}
    arr: dict[tuple[str, int, int], int] = {}
    go: dict[tuple[str, int, int], int] = {}
    done: dict[tuple[str, int], int] = {}
    fin: dict[str, int] = {}
    opens: set[tuple[str, int]] = set()
    unoffered: set[tuple[str, int]] = set()
    for a in atoms:
        # one call into clingo per atom (its text) instead of one per argument: decoding runs for
        # every program solved
        name, _, rest = str(a).partition("(")
        args = _arguments(name, rest[:-1])
        if name == "at":
            at[(args[0], int(args[1]))] = args[2]
        elif name == "use":
            use[(args[0], int(args[1]))] = args[2]
        elif name == "arr":
            arr[(args[0], int(args[1]), int(args[3]))] = int(args[4])
        elif name == "go":
            go[(args[0], int(args[1]), int(args[3]))] = int(args[4])
        elif name == "done":
            done[(args[0], int(args[1]))] = int(args[3])
        elif name == "fin":
            fin[args[0]] = int(args[1])
        elif name == "opens":  # opens(Q,D,T): Q is the group the robot was planned in
            opens.add((args[1], int(args[2])))
        elif name == "unoffered":
            unoffered.add((args[1], int(args[2])))
    given_windows = set(given)
    windows = opens | given_windows
    plans: dict[str, RobotPlan] = {}
    for rid, prob in problems.items():
        legs = {leg.id: leg for leg in prob.legs}
        steps = [Step(p.action, p.args, p.start, p.end) for p in prob.prefix]
        passes = [Pass(p.opening, p.start, p.end, "", "", False) for p in prob.prefix if p.action == Action.GOTHROUGH]
        uses: set[tuple[str, int]] = set()
        t = prob.ready
        for pos in range(1, len(prob.stops) + 1):
            leg = legs[use[(rid, pos)]]
            for k, c in enumerate(leg.crossings, start=1):
                a, g = arr[(rid, pos, k)], go[(rid, pos, k)]
                if not (c.approach == 0 and k == 1 and leg.origin == "start" and prob.beside == c.opening):
                    steps.append(Step(Action.APPROACH.value, (c.opening,), t, a))
                if c.human:
                    steps.append(Step(Action.OPENDOOR.value, (c.opening,), a, g))
                steps.append(Step(Action.GOTHROUGH.value, (c.opening,), g, g + c.through))
                passes.append(Pass(c.opening, g, g + c.through, c.src, c.dst, c.human))
                if c.human:
                    cover = _cover(windows, opens, c.opening, g, g + c.through, hold)
                    if cover is not None:
                        uses.add(cover)
                t = g + c.through
            stop = prob.stops[leg.stop]
            end = done[(rid, pos)]
            steps.append(Step(stop.action, (stop.obj,), t, end))
            t = end
        finish = fin.get(rid, prob.ready if not prob.stops else t)
        own = {w for w in uses if w in opens and w not in given_windows}
        plans[rid] = RobotPlan(
            robot=rid,
            steps=tuple(steps),
            finish=finish if prob.stops else (steps[-1].end if steps else 0),
            passes=tuple(passes),
            uses=frozenset(uses),
            unoffered=frozenset(own & unoffered),
            visits=tuple(visits(prob, passes, finish)),
            order=tuple(at[(rid, pos)] for pos in range(1, len(prob.stops) + 1)),
            legs=tuple(use[(rid, pos)] for pos in range(1, len(prob.stops) + 1)),
            routes=tuple(
                tuple(c.opening for c in legs[use[(rid, pos)]].crossings) for pos in range(1, len(prob.stops) + 1)
            ),
        )
    return plans


def _cover(
    windows: set[tuple[str, int]], opens: set[tuple[str, int]], door: str, start: int, end: int, hold: int
) -> tuple[str, int] | None:
    """The opening window of ``door`` that a pass [start, end) lies in (own openings first)."""
    covering = sorted((d, t) for d, t in windows if d == door and t <= start and end <= t + hold)
    own = [w for w in covering if w in opens]
    return (own or covering or [None])[0]


def visits(prob: RobotProblem, passes: list[Pass], finish: int) -> list[tuple[str, int, int]]:
    """(room, S, E) stays of the robot; during a gothrough it is in both rooms."""
    out = list(prob.rooms_at_start)
    room = prob.room
    since = prob.prefix[0].start if prob.prefix else prob.ready
    for p in passes:
        if not p.src:  # the prefix's pass: already in rooms_at_start
            continue
        out.append((room, since, p.end))
        room, since = p.dst, p.start
    out.append((room, since, max(finish, since)))
    return out
