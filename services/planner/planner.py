"""The task planner P^t as one call: world + constraints -> a timed plan for every robot.

Builds each robot's problem (:mod:`.problem`), then runs IIDP (:mod:`.iidp`) or the joint program
(:mod:`.joint`, which first runs IIDP for its horizon and hints). A plan from scratch runs IIDP
twice, breaking ties between a robot's equally good plans two ways, and keeps the better team (the
two runs are independent: they run side by side on two threads, clingo's work in parallel). When
the constraints leave a robot no plan at all, the result says which constraints conflict (status
``conflict``) instead of a plan.
"""

from __future__ import annotations

import logging
import math
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

from protocol.site import Site

from .constraints import ConstraintProgram
from .facts import hold_seconds, site_facts, time_point_facts
from .iidp import NoPlan, iidp
from .joint import joint
from .motion import MotionPlanner, NoPath
from .plan import TeamResult
from .problem import PlanningError, ProblemBuilder, RobotProblem
from .single import SingleRobotSolver
from .world import World

log = logging.getLogger("arroch.planner")

METHODS = ("iidp", "joint")
OUT_OF_TIME_RETRIES = 2  # plans made again when a solve found no model in time (chosen: 4x, then 16x)
LIMIT_GROWTH = 4.0  # each retry's time limits over the last one's


@dataclass
class PlannerSettings:
    time_limit: float = 10.0  # s for a whole IIDP plan; past it the best plan so far is used
    solve_limit: float = 2.0  # s for one clingo call inside IIDP
    joint_time_limit: float = 60.0  # s for the joint program
    routes_per_leg: int = 1  # candidate routes per leg; 2 when constraints mention rooms
    max_rounds: int | None = None  # IIDP rounds (default 2·N)
    threads: int = 2  # 2: a plan from scratch makes its two tie-breaking runs side by side; 1: one after the other


class TaskPlanner:
    def __init__(self, site: Site, settings: PlannerSettings | None = None) -> None:
        self.site = site
        self.settings = settings or PlannerSettings()
        self.motion = MotionPlanner(site)
        self.builder = ProblemBuilder(site, self.motion, routes_per_leg=self.settings.routes_per_leg)
        self.hold = hold_seconds(site)
        self._beside: ThreadPoolExecutor | None = None  # the second tie-breaking run of a plan from scratch
        self._beside_pid = 0

    def problems(
        self, world: World, base: int, constraints: ConstraintProgram | None = None
    ) -> dict[str, RobotProblem]:
        routes = (
            max(self.settings.routes_per_leg, 2) if constraints is not None and constraints.mentions_rooms else None
        )
        return {
            rid: self.builder.problem(world, rid, base, routes)
            for rid in sorted(world.robots)
            if rid in self.site.robots
        }

    def existing_windows(self, world: World, base: int) -> tuple[tuple[str, int], ...]:
        """Doors the human opened that are still open: windows every robot may use, not counted."""
        return tuple(
            sorted((d, int(math.floor(t)) - base) for d, t in world.open_doors.items() if d in self.builder.human_doors)
        )

    def plan(
        self,
        world: World,
        constraints: ConstraintProgram | None = None,
        method: str = "iidp",
        *,
        time_limit: float | None = None,
        warm: TeamResult | None = None,
    ) -> TeamResult:
        """Plan for every robot of ``world``. ``warm``: the plan being executed, to start IIDP from.

        A plan that fails only because a solve found no model within its limits (a loaded machine,
        not an impossible problem) is made again with the limits ``LIMIT_GROWTH`` times longer, up to
        ``OUT_OF_TIME_RETRIES`` times: a slow plan beats none, and nothing else would ask again."""
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r} (use {' or '.join(METHODS)})")
        t0 = time.perf_counter()
        scale = 1.0
        result = self._plan(world, constraints, method, time_limit, warm, scale)
        for _ in range(OUT_OF_TIME_RETRIES):
            if not result.out_of_time:
                break
            scale *= LIMIT_GROWTH
            log.warning("%s; planning again with %g times the time limits", result.diagnostic, scale)
            result = self._plan(world, constraints, method, time_limit, warm, scale)
        result.solve_time = time.perf_counter() - t0
        return result

    def _plan(
        self,
        world: World,
        constraints: ConstraintProgram | None,
        method: str,
        time_limit: float | None,
        warm: TeamResult | None,
        scale: float,
    ) -> TeamResult:
        """One attempt at :meth:`plan`, with every time limit multiplied by ``scale``."""
        t0 = time.perf_counter()
        base = int(math.floor(world.now))
        result = TeamResult(method=method, base=base, hold=self.hold, plans={})
        try:
            problems = self.problems(world, base, constraints)
        except (PlanningError, NoPath) as exc:
            result.status, result.diagnostic = "failed", str(exc)
            return result
        existing = self.existing_windows(world, base)
        result.existing = frozenset(existing)
        common = site_facts(self.site, base)
        if constraints is not None:
            common += time_point_facts(self.site, base, constraints.numbers())
            common += "".join(f"watched({room}).\n" for room in sorted(constraints.watched_rooms(self.site.rooms)))
        solve_limit = self.settings.solve_limit * scale
        single = SingleRobotSolver(common, self.hold, constraints, solve_limit, existing, base=base)
        limit = (self.settings.time_limit if time_limit is None else time_limit) * scale
        warm_plans = self._warm(warm, base)
        # From scratch, the run breaking ties the other way starts now, beside this one, with the
        # deadline it has when it runs after it.
        deadline = t0 + limit
        other = self._start_other_ties(single, problems, deadline) if warm_plans is None else None
        try:
            plans, stats = iidp(
                single, problems, time_limit=limit, max_rounds=self.settings.max_rounds, warm=warm_plans
            )
        except NoPlan as exc:
            if other is not None:
                other.result()  # never left running into the next plan
            return self._no_plan(result, single, problems, exc, t0)
        solves = single.calls
        if warm_plans is None:
            plans, stats, solves = self._other_ties(single, problems, plans, stats, other, deadline)
        result.plans, result.iterations = plans, stats.rounds
        cap = self.settings.max_rounds if self.settings.max_rounds is not None else 2 * len(problems)
        result.status = "ok" if stats.converged or stats.rounds >= cap else "timeout"
        result.converged = stats.converged
        if result.conflicts:
            result.diagnostic = f"{result.conflicts} conflicts left after the time limit"
        if method == "joint":
            jplans, out = joint(
                single.site_facts,
                problems,
                self.hold,
                constraints,
                existing=existing,
                horizon=result.makespan,
                hints=plans,
                time_limit=self.settings.joint_time_limit * scale,
            )
            if jplans is not None:
                result.plans = jplans
                result.optimal = out.status == "optimal"
                result.status = "ok" if result.optimal else "timeout"
            else:
                result.diagnostic = f"joint program gave no plan ({out.status}); IIDP's plan kept"
        result.solve_time = time.perf_counter() - t0
        log.debug(
            "%s plan: makespan %d, openings %d, %d rounds, %d solves (%d cached), %.3f s",
            method,
            result.makespan,
            result.door_openings,
            result.iterations,
            single.calls,
            single.cache_hits,
            result.solve_time,
        )
        result.solves = solves
        return result

    def _tie_breaker(self, single: SingleRobotSolver, own_constraints: bool) -> SingleRobotSolver:
        """The solver breaking ties between a robot's equally good plans the other way (every
        gothrough as early as it can be, objective.lp), with nothing cached; ``own_constraints``: the
        constraints parsed again for it (a thread adds only clingo AST nodes it made, controls.py)."""
        constraints = single.constraints
        if own_constraints and constraints is not None:
            constraints = ConstraintProgram.build(constraints.items)
        return replace(
            single,
            site_facts=single.site_facts + "early.\n",
            constraints=constraints,
            _cache={},
            _facts={},
            calls=0,
            cache_hits=0,
            solve_seconds=0.0,
        )

    def _start_other_ties(
        self, single: SingleRobotSolver, problems: dict[str, RobotProblem], deadline: float
    ) -> Future | None:
        """The other tie-breaking run of a plan from scratch, started on a second thread, to end by
        ``deadline`` (``time.perf_counter``) as when it runs after the first (None with ``threads`` = 1
        or no time left: it then runs after the first, or not). Its result: (plans, IIDP figures,
        solver), or (None, None, solver) when it finds no plan."""
        remaining = deadline - time.perf_counter()
        if self.settings.threads < 2 or remaining <= 0:
            return None
        if self._beside is None or self._beside_pid != os.getpid():  # a forked child has no such thread
            self._beside = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner-ties")
            self._beside_pid = os.getpid()
        return self._beside.submit(self._run_other_ties, self._tie_breaker(single, True), problems, remaining)

    def _run_other_ties(self, other: SingleRobotSolver, problems: dict[str, RobotProblem], limit: float):
        try:
            plans, stats = iidp(other, problems, time_limit=limit, max_rounds=self.settings.max_rounds)
        except NoPlan:
            return None, None, other
        return plans, stats, other

    def _other_ties(
        self,
        single: SingleRobotSolver,
        problems: dict[str, RobotProblem],
        plans,
        stats,
        started: Future | None,
        deadline: float,
    ):
        """A plan from scratch, made again with ties between a robot's equally good plans broken the
        other way; the better team is kept (the first on a tie). Each robot placed depends on how
        those before it broke their ties, so either way can be the better one by a whole opening or
        more; planning twice from scratch is cheap next to a mission's replans. ``started``: that run,
        already going on a second thread (else it runs now, until ``deadline``). Returns plans, IIDP
        figures and the programs solved."""
        remaining = deadline - time.perf_counter()
        if started is not None:
            plans2, stats2, other = started.result()
        elif remaining <= 0:
            return plans, stats, single.calls
        else:
            plans2, stats2, other = self._run_other_ties(self._tie_breaker(single, False), problems, remaining)
        if plans2 is None:
            return plans, stats, single.calls + other.calls
        existing = frozenset(single.existing)
        first = TeamResult("iidp", 0, self.hold, plans, existing=existing).cost()
        second = TeamResult("iidp", 0, self.hold, plans2, existing=existing).cost()
        if second < first:
            return plans2, stats2, single.calls + other.calls
        return plans, stats, single.calls + other.calls

    @staticmethod
    def _warm(previous: TeamResult | None, base: int) -> dict | None:
        if previous is None or not previous.plans or previous.status not in ("ok", "timeout"):
            return None
        delta = previous.base - base
        return {rid: plan.shifted(delta) for rid, plan in previous.plans.items()}

    def _no_plan(
        self, result: TeamResult, single: SingleRobotSolver, problems: dict[str, RobotProblem], exc: NoPlan, t0: float
    ) -> TeamResult:
        prob = problems[exc.robot]
        out = exc.outcome
        if out.status == "unsat":
            out = single.diagnose(prob, single.context(prob, {}))
        if out.conflict:
            result.status = "conflict"
            result.conflict_ids = list(out.conflict)
            result.diagnostic = f"constraints {', '.join(out.conflict)} leave robot {exc.robot} no plan"
        elif out.status == "unsat":
            result.status = "failed"
            result.diagnostic = f"robot {exc.robot} has no plan even without constraints"
        else:
            result.status = "failed"
            result.diagnostic = f"no plan for robot {exc.robot} within the time limit ({out.status})"
            result.out_of_time = True
        result.solve_time = time.perf_counter() - t0
        return result
