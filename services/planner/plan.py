"""Plans as the planner handles them: one timed action sequence per robot, and the team's figures.

Times inside are integer seconds relative to ``base`` (the whole site-clock second the plan
starts from); :meth:`TeamResult.absolute` and the message/JSON builders add ``base``.

Team figures, in the objective's priority order:

- ``conflicts``: pairs of robots in one doorway at once, or two openings of one door whose hold
  windows overlap (a door that is open cannot be opened again). Valid plans have none; IIDP's
  first, independent plans may, and its rounds remove them.
- ``makespan``: when the slowest robot finishes (relative to ``base``).
- ``door_openings``: distinct openings the human is asked for. Every robot going through within
  one opening's hold window shares it, so this counts windows, not crossings; doors already open
  when planning starts are not counted.
- ``unoffered``: openings outside the windows the human offered (``human_available``).
- ``total_time``: the sum of the robots' finishing times.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace


@dataclass(frozen=True)
class Step:
    action: str
    args: tuple[str, ...]
    start: int
    end: int


@dataclass(frozen=True)
class Pass:
    """A gothrough: the robot occupies the doorway of ``opening`` during [start, end)."""

    opening: str
    start: int
    end: int
    src: str
    dst: str
    human: bool


@dataclass(frozen=True)
class RobotPlan:
    robot: str
    steps: tuple[Step, ...]
    finish: int
    passes: tuple[Pass, ...]
    uses: frozenset[tuple[str, int]] = frozenset()  # opening windows (door, start) its passes rely on
    unoffered: frozenset[tuple[str, int]] = frozenset()  # of those it asked for, the ones outside offers
    visits: tuple[tuple[str, int, int], ...] = ()  # (room, S, E)
    order: tuple[str, ...] = ()  # the stops in order (ASP terms ld(o)/ul(o))
    legs: tuple[str, ...] = ()  # the leg taken to each stop (ids of the problem it was solved for)
    routes: tuple[tuple[str, ...], ...] = ()  # the openings of each leg, to find the same legs again

    @property
    def empty(self) -> bool:
        return not self.steps

    def shifted(self, delta: int) -> RobotPlan:
        """The same plan with times moved by ``delta`` (to re-express it against a new base);
        windows and passes that then lie in the past are dropped (they happened or they won't), and
        a finish in the past is now (the robot is done: nothing finishes before the base)."""
        return replace(
            self,
            steps=tuple(Step(s.action, s.args, s.start + delta, s.end + delta) for s in self.steps),
            finish=max(self.finish + delta, 0),
            passes=tuple(
                replace(p, start=p.start + delta, end=p.end + delta) for p in self.passes if p.end + delta > 0
            ),
            uses=frozenset((d, t + delta) for d, t in self.uses if t + delta >= 0),
            unoffered=frozenset((d, t + delta) for d, t in self.unoffered if t + delta >= 0),
            visits=tuple((r, a + delta, b + delta) for r, a, b in self.visits),
        )


@dataclass(frozen=True)
class Opening:
    door: str
    start: int
    end: int
    robots: tuple[str, ...]


@dataclass
class TeamResult:
    method: str
    base: int
    hold: int
    plans: dict[str, RobotPlan]
    existing: frozenset[tuple[str, int]] = frozenset()  # windows open before planning (not counted)
    iterations: int = 0
    solve_time: float = 0.0
    status: str = "ok"  # "ok" | "timeout" (best so far) | "conflict" | "failed"
    diagnostic: str = ""
    conflict_ids: list[str] = field(default_factory=list)
    optimal: bool = False
    converged: bool = False  # IIDP stopped because no robot could improve the team
    solves: int = 0  # clingo programs solved
    out_of_time: bool = False  # "failed" only because a solve found no model within its limits

    # ------------------------------------------------------------------ figures

    @property
    def windows(self) -> set[tuple[str, int]]:
        out: set[tuple[str, int]] = set()
        for plan in self.plans.values():
            out |= plan.uses
        return out

    @property
    def openings(self) -> list[Opening]:
        by_window: dict[tuple[str, int], set[str]] = {w: set() for w in self.windows}
        for plan in self.plans.values():
            for p in plan.passes:
                if not p.human:
                    continue
                for door, t in plan.uses:
                    if door == p.opening and t <= p.start and p.end <= t + self.hold:
                        by_window[(door, t)].add(plan.robot)
        return [
            Opening(d, t, t + self.hold, tuple(sorted(rs)))
            for (d, t), rs in sorted(by_window.items(), key=lambda kv: (kv[0][1], kv[0][0]))
        ]

    @property
    def door_openings(self) -> int:
        return len(self.windows - self.existing)

    @property
    def makespan(self) -> int:
        return max((p.finish for p in self.plans.values()), default=0)

    @property
    def total_time(self) -> int:
        return sum(p.finish for p in self.plans.values())

    @property
    def unoffered(self) -> int:
        out: set[tuple[str, int]] = set()
        for plan in self.plans.values():
            out |= plan.unoffered
        return len(out & (self.windows - self.existing))

    @property
    def conflicts(self) -> int:
        return count_conflicts(self.plans.values(), self.hold)

    def cost(self) -> tuple[int, int, int, int, int]:
        """The team objective, lexicographic: smaller is better."""
        return (self.conflicts, self.makespan, self.door_openings, self.unoffered, self.total_time)

    def absolute(self, t: int) -> int:
        return self.base + t

    # ------------------------------------------------------------------ output

    def as_json(self) -> dict:
        """The one-shot CLI's shape: method, makespan, door_openings, solve_time, iterations, robots."""
        return {
            "method": self.method,
            "makespan": self.makespan,
            "door_openings": self.door_openings,
            "solve_time": round(self.solve_time, 4),
            "iterations": self.iterations,
            "robots": {
                rid: [
                    {"action": s.action, "args": list(s.args), "start": self.base + s.start, "end": self.base + s.end}
                    for s in plan.steps
                ]
                for rid, plan in sorted(self.plans.items())
            },
        }


def share_windows(plans: dict[str, RobotPlan], hold: int, existing: frozenset = frozenset()) -> dict[str, RobotPlan]:
    """Let every pass through a human-operated door use the fewest openings the plans already ask for.

    Plans made apart (IIDP's first step) each ask for their own openings although one may serve
    several robots: the human opens once and every robot that goes through within the hold window
    uses it. Per door, passes are taken in time order; a pass the last chosen window does not cover
    gets the latest-starting window (doors already open first) that covers it and does not overlap
    the last chosen one. Only windows some plan asked for are used, so no new opening appears and
    every pass stays inside an opening; a pass no such window covers keeps its own (and shows up as
    a conflict)."""
    candidates: dict[str, set[int]] = {}
    for plan in plans.values():
        for door, t in plan.uses:
            candidates.setdefault(door, set()).add(t)
    for door, t in existing:
        candidates.setdefault(door, set()).add(t)
    passes: dict[str, list[tuple[int, int, str]]] = {}
    for rid, plan in plans.items():
        for p in plan.passes:
            if p.human:
                passes.setdefault(p.opening, []).append((p.start, p.end, rid))
    uses: dict[str, set[tuple[str, int]]] = {rid: set() for rid in plans}
    for door, items in passes.items():
        starts = sorted(candidates.get(door, ()))
        last: int | None = None
        for start, end, rid in sorted(items):
            if last is not None and last <= start and end <= last + hold:
                uses[rid].add((door, last))
                continue
            fits = [t for t in starts if t <= start and end <= t + hold and (last is None or t > last + hold)]
            if fits:
                free = [t for t in fits if (door, t) in existing]
                last = (free or fits)[-1]
                uses[rid].add((door, last))
            else:
                own = [w for w in plans[rid].uses if w[0] == door and w[1] <= start and end <= w[1] + hold]
                uses[rid] |= set(own[:1])
    out: dict[str, RobotPlan] = {}
    for rid, plan in plans.items():
        new = frozenset(uses[rid])
        out[rid] = plan if new == plan.uses else replace(plan, uses=new, unoffered=plan.unoffered & new)
    return out


def contested(windows: set[tuple[str, int]], hold: int) -> set[tuple[str, int]]:
    """Windows that overlap an earlier kept window of the same door (a door cannot be opened while open).

    Windows are kept greedily by start time: the earliest stays, any window overlapping the last
    kept one (or starting the second it closes) is contested. Robots may share the kept windows and must
    move off contested ones."""
    out: set[tuple[str, int]] = set()
    by_door: dict[str, list[int]] = {}
    for door, t in windows:
        by_door.setdefault(door, []).append(t)
    for door, starts in by_door.items():
        starts.sort()
        kept = None
        for t in starts:
            if kept is not None and t <= kept + hold:  # openings need a closed second between them
                out.add((door, t))
            else:
                kept = t
    return out


def count_conflicts(plans, hold: int) -> int:
    """Pairs of robots in one doorway at once, plus each robot's use of a window that overlaps another.

    Counting window conflicts per robot using them (not per pair of windows) lets every robot that
    moves off a contested window show as an improvement, so IIDP's rounds drive the count to zero."""
    plans = list(plans)
    passes: dict[str, list[tuple[int, int, str]]] = {}
    windows: set[tuple[str, int]] = set()
    for plan in plans:
        for p in plan.passes:
            passes.setdefault(p.opening, []).append((p.start, p.end, plan.robot))
        windows |= plan.uses
    n = 0
    for items in passes.values():
        items.sort()
        for i, (_s1, e1, r1) in enumerate(items):
            for s2, _e2, r2 in items[i + 1 :]:
                if s2 >= e1:
                    break
                if r1 != r2:
                    n += 1
    bad = contested(windows, hold)
    if bad:
        n += sum(len(plan.uses & bad) for plan in plans)
    return n
