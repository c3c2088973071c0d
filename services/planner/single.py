"""Planning one robot given everything else fixed: the building block of IIDP.

The program is the shared encoding with one free robot; other robots' plans enter as facts
(:class:`.facts.Context`): their openings are free to share, their doorway occupancy is not to be
overlapped, and their finishing time bounds the team's. Results are cached per robot and context,
so an IIDP round only solves again for robots whose surroundings changed. Each robot is its own
group (``grp(R,R)``), so the programs of several robots can be grounded as one and solved one robot
at a time (:meth:`SingleRobotSolver.prefetch`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from .constraints import ConstraintProgram
from .decode import decode
from .facts import Busy, Context, closed_facts, context_facts, door_facts, robot_facts, throughs
from .plan import RobotPlan, contested
from .problem import RobotProblem
from .solver import Outcome, parts_for, solve, solve_each

RELAXED_WAIT = 100_000  # s: waits bounded only by the plan's own times


@dataclass
class SingleRobotSolver:
    """Solves one-robot programs over a fixed site, constraint set and base time."""

    site_facts: str
    hold: int
    constraints: ConstraintProgram | None
    solve_limit: float = 2.0
    existing: tuple[tuple[str, int], ...] = ()  # door windows open before planning
    syncwait: int = 40  # s a robot may wait to share an opening (or for one to end)
    clearwait: int = 8  # s a robot may wait for a busy doorway to clear
    base: int = 0  # the site-clock second relative times count from
    _cache: dict = field(default_factory=dict)
    _facts: dict = field(default_factory=dict)  # id(problem) -> (problem, its facts)
    calls: int = 0
    cache_hits: int = 0
    solve_seconds: float = 0.0

    def __post_init__(self) -> None:
        self.parts = parts_for(self.constraints)

    def context(
        self, prob: RobotProblem, others: dict[str, RobotPlan], horizon: int | None = None, *, relaxed: bool = False
    ) -> Context:
        """What ``prob``'s robot must live with, keeping only openings it may cross (better cache hits)."""
        mine = {c.opening for leg in prob.legs for c in leg.crossings}
        given = set(w for w in self.existing if w[0] in mine)
        busy: set[Busy] = set()
        end = None
        for rid, plan in others.items():
            given |= {w for w in plan.uses if w[0] in mine and (w in self.existing or self._admitted(w))}
            busy |= {Busy(p.opening, p.start, p.end, rid) for p in plan.passes if p.opening in mine}
            end = plan.finish if end is None else max(end, plan.finish)
        busy_sorted = tuple(sorted(busy, key=lambda b: (b.opening, b.start, b.end, b.owner)))
        # Windows that overlap an earlier one (left by independent first plans) may not be shared,
        # only avoided, so that their users move off them one by one.
        blocked = contested(given, self.hold) - set(self.existing)
        waits = (
            {"syncwait": RELAXED_WAIT, "clearwait": RELAXED_WAIT}
            if relaxed
            else {"syncwait": self.syncwait, "clearwait": self.clearwait}
        )
        return Context(
            given_open=tuple(sorted(given - blocked)),
            blocked_open=tuple(sorted(blocked)),
            busy=busy_sorted,
            others_end=end,
            horizon=horizon,
            **waits,
        )

    def _admitted(self, window: tuple[str, int]) -> bool:
        """An opening from another plan that the constraints allow (plans made before a constraint may not)."""
        return self.constraints is None or self.constraints.admits_opening(window[0], self.base + window[1])

    @staticmethod
    def _key(prob: RobotProblem, ctx: Context) -> tuple:
        return (prob.robot, tuple(leg.id for leg in prob.legs), ctx)

    def solve(
        self, prob: RobotProblem, ctx: Context, *, time_limit: float | None = None
    ) -> tuple[RobotPlan | None, Outcome]:
        key = self._key(prob, ctx)
        hit = self._cache.get(key)
        if hit is not None:
            self.cache_hits += 1
            return hit
        self.calls += 1
        t0 = time.perf_counter()
        if prob.done:
            plan = decode([], {prob.robot: prob}, self.hold, ctx.given_open)[prob.robot]
            result: tuple[RobotPlan | None, Outcome] = (plan, Outcome(status="optimal"))
        else:
            facts = self.site_facts + self._member(prob, ctx) + f"active({prob.robot}).\n"
            out = solve(facts, self.parts, self.constraints, time_limit=time_limit or self.solve_limit, diagnose=False)
            result = self._decoded(prob, ctx, out)
        self.solve_seconds += time.perf_counter() - t0
        self._cache[key] = result
        return result

    def prefetch(self, requests: list[tuple[RobotProblem, Context]], *, time_limit: float | None = None) -> None:
        """Solve the ``requests`` not cached yet, at most one per robot, in one program (grounded
        once, optimised once per robot, :func:`.solver.solve_each`); :meth:`solve` then finds them.
        For the robots IIDP solves side by side: every robot's retiming, every robot's response in
        a round, every robot alone."""
        todo: dict[str, tuple[RobotProblem, Context]] = {}
        for prob, ctx in requests:
            if not prob.done and prob.robot not in todo and self._key(prob, ctx) not in self._cache:
                todo[prob.robot] = (prob, ctx)
        if len(todo) < 2:
            return  # one alone costs the same when it is asked for
        t0 = time.perf_counter()
        facts = self.site_facts + "".join(self._member(prob, ctx) for prob, ctx in todo.values())
        outs = solve_each(facts, list(todo), self.parts, self.constraints, time_limit=time_limit or self.solve_limit)
        for rid, (prob, ctx) in todo.items():
            self.calls += 1
            self._cache[self._key(prob, ctx)] = self._decoded(prob, ctx, outs[rid])
        self.solve_seconds += time.perf_counter() - t0

    def _decoded(self, prob: RobotProblem, ctx: Context, out: Outcome) -> tuple[RobotPlan | None, Outcome]:
        plan = decode(out.atoms, {prob.robot: prob}, self.hold, ctx.given_open)[prob.robot] if out.ok else None
        return plan, out

    def _member(self, prob: RobotProblem, ctx: Context) -> str:
        """The robot's problem and its context; the robot is its own group."""
        r = prob.robot
        return (
            self.robot_facts(prob)
            + f"grp({r},{r}).\n"
            + context_facts(ctx, r)
            + door_facts(ctx, r, throughs([prob]), self.hold)
            + closed_facts(prob, ctx, self.hold)
        )

    def robot_facts(self, prob: RobotProblem) -> str:
        """The problem's facts, written once per problem (a robot is solved many times in one plan)."""
        hit = self._facts.get(id(prob))
        if hit is None or hit[0] is not prob:
            hit = self._facts[id(prob)] = (prob, robot_facts(prob))
        return hit[1]

    def diagnose(self, prob: RobotProblem, ctx: Context) -> Outcome:
        """Solve again with conflict diagnosis (for a robot that has no plan at all)."""
        facts = self.site_facts + self._member(prob, ctx) + f"active({prob.robot}).\n"
        return solve(facts, self.parts, self.constraints, time_limit=self.solve_limit * 4, diagnose=True)
