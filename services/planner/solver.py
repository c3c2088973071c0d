"""Running clingo on the encoding: ground, solve with a time cap, keep the best model, explain unsat.

One call builds one program (encoding parts, parsed once per process, + facts + the guarded
constraints), grounds it once and optimises with branch-and-bound, single-threaded so results do not
depend on thread timing (:func:`solve_each`: one program holding several robots' problems, optimised
once per robot). The solve runs asynchronously and is cancelled at the time limit; the best model
found so far is kept ("feasible" rather than "optimal"). When the program is unsatisfiable under
the constraints, the unsatisfiable core over the constraints' ``cactive/1`` switches is shrunk by
deletion to a minimal set of constraint ids that cannot hold together (see :mod:`.constraints`).
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import clingo
import clingo.ast as ast

from .constraints import ConstraintProgram
from .controls import shop

HERE = Path(__file__).resolve().parent
ENCODING = {
    "domain": "domain.lp",  # stops, order, legs, the time chain, fluents
    "doors": "doors.lp",  # human door openings, sharing them, other robots' doorway occupancy
    "vocabulary": "vocabulary.lp",  # human_opens/goes_through and the restrictor's facts
    "rooms": "rooms.lp",  # robot_in/4 and room_forbidden/3
    "joint": "joint.lp",  # interactions between robots planned together
    "objective": "objective.lp",  # openings, offers, total time
    "makespan": "makespan.lp",  # team completion time with one robot free (IIDP)
}
DIAGNOSE_LIMIT = 2.0  # s for each satisfiability check while shrinking a conflict


@dataclass
class ClingoWork:
    """Clingo work done in this process so far: read it before and after a plan to see where the
    plan's time went (``benchmarks/planner.py``). ``build``: a ``Control`` made and the encoding and
    facts added (the facts' text parsed); ``ground``: grounding; ``solve``: optimising, and the
    satisfiability checks of a diagnosis."""

    programs: int = 0
    build_seconds: float = 0.0
    ground_seconds: float = 0.0
    solve_seconds: float = 0.0

    def since(self, before: ClingoWork) -> ClingoWork:
        return ClingoWork(
            self.programs - before.programs,
            self.build_seconds - before.build_seconds,
            self.ground_seconds - before.ground_seconds,
            self.solve_seconds - before.solve_seconds,
        )

    def add(self, programs: int = 0, build: float = 0.0, ground: float = 0.0, solve: float = 0.0) -> None:
        with _WORK_LOCK:  # a plan from scratch plans on two threads (planner.py)
            self.programs += programs
            self.build_seconds += build
            self.ground_seconds += ground
            self.solve_seconds += solve


_WORK_LOCK = threading.Lock()
WORK = ClingoWork()  # the process's totals


@functools.cache
def encoding_text(part: str) -> str:
    return (HERE / ENCODING[part]).read_text(encoding="utf-8")


_PARSED = threading.local()


def encoding_statements(part: str) -> tuple[ast.AST, ...]:
    """A part of the encoding parsed once per thread: handing clingo the parsed statements of every
    program costs about a third of parsing the text again. Per thread, because clingo counts the
    references of its AST nodes without atomics (controls.py)."""
    cache: dict[str, tuple[ast.AST, ...]] = _PARSED.__dict__.setdefault("parts", {})
    hit = cache.get(part)
    if hit is None:
        out: list[ast.AST] = []
        ast.parse_string(encoding_text(part), out.append)
        comment = getattr(ast.ASTType, "Comment", None)  # comments are statements from clingo 5.7 on
        hit = cache[part] = tuple(s for s in out if s.ast_type != comment)
    return hit


CONTROLS = shop(encoding_statements)  # Controls made ahead and freed behind (controls.py)


@dataclass
class Outcome:
    status: str  # "optimal" | "feasible" (time limit hit, best so far) | "unsat" | "unknown" (no model in time)
    atoms: list[clingo.Symbol] = field(default_factory=list)
    cost: tuple[int, ...] = ()
    seconds: float = 0.0
    ground_seconds: float = 0.0
    conflict: list[str] = field(default_factory=list)  # minimal conflicting constraint ids (unsat only)
    inherent: bool = False  # unsat even without any constraint

    @property
    def ok(self) -> bool:
        return self.status in ("optimal", "feasible")


def parts_for(constraints: ConstraintProgram | None, *, joint: bool = False) -> list[str]:
    parts = ["domain", "doors", "objective"]
    if constraints is not None and constraints.active:
        parts.append("vocabulary")  # only constraints read its atoms or state the facts it interprets
        if constraints.mentions_rooms:
            parts.append("rooms")
    parts.append("joint" if joint else "makespan")
    return parts


def _grounded(
    facts: str, parts: Sequence[str], constraints: ConstraintProgram | None, args: list[str], extra: str = ""
) -> clingo.Control:
    t0 = time.perf_counter()
    ctl = CONTROLS.take(args, parts)  # options and encoding already in, most of the time
    ctl.add("base", [], facts)
    if extra:
        ctl.add("base", [], extra)
    if constraints is not None:
        constraints.add_to(ctl)
    t1 = time.perf_counter()
    ctl.ground([("base", [])])
    WORK.add(programs=1, build=t1 - t0, ground=time.perf_counter() - t1)
    # An #external atom is false unless released; free ones can then be assumed true or false per solve.
    for i in constraints.active if constraints else []:
        ctl.assign_external(ConstraintProgram.guard_symbol(i), None)  # None: free
    return ctl


def _guards(constraints: ConstraintProgram | None) -> list[tuple[clingo.Symbol, bool]]:
    return [(ConstraintProgram.guard_symbol(i), True) for i in (constraints.active if constraints else [])]


def _optimise(
    ctl: clingo.Control, assumptions: list, limit: float, t0: float, ground: float, core: list[int] | None = None
) -> Outcome:
    """Branch-and-bound under ``assumptions`` for at most ``limit`` s; the best model found."""
    best: list = []

    def on_model(model: clingo.Model) -> None:
        best[:] = [model.symbols(shown=True), tuple(model.cost)]

    on_core = core.extend if core is not None else None
    t1 = time.perf_counter()
    with ctl.solve(assumptions=assumptions, on_model=on_model, on_core=on_core, async_=True) as handle:
        finished = handle.wait(limit)
        if not finished:
            handle.cancel()
        result = handle.get()
    WORK.add(solve=time.perf_counter() - t1)
    out = Outcome(status="unknown", seconds=time.perf_counter() - t0, ground_seconds=ground)
    if best:
        out.atoms, out.cost = best[0], best[1]
        out.status = "optimal" if finished and result.exhausted else "feasible"
    elif finished and result.unsatisfiable:
        out.status = "unsat"
    return out


def _options(options: Sequence[str] = (), consts: dict[str, int] | None = None) -> list[str]:
    args = ["--opt-strategy=bb", "--warn=none", "--parallel-mode=1", *options]
    for name, value in (consts or {}).items():
        args += ["-c", f"{name}={int(value)}"]
    return args


def solve(
    facts: str,
    parts: Sequence[str],
    constraints: ConstraintProgram | None = None,
    *,
    time_limit: float = 5.0,
    consts: dict[str, int] | None = None,
    diagnose: bool = True,
    extra: str = "",
    options: Sequence[str] = (),
) -> Outcome:
    """Ground and optimise; on unsat (and ``diagnose``) name the conflicting constraints."""
    t0 = time.perf_counter()
    ctl = _grounded(facts, parts, constraints, _options(options, consts), extra)
    ground = time.perf_counter() - t0
    core: list[int] = []
    # Grounding cannot be interrupted; whatever it took, leave the search some time for a first model.
    out = _optimise(ctl, _guards(constraints), max(time_limit - ground, min(1.0, time_limit)), t0, ground, core)
    if out.status == "unsat" and diagnose:
        _explain(ctl, constraints, core, out)
        out.seconds = time.perf_counter() - t0
    CONTROLS.give_back(ctl)
    return out


def solve_each(
    facts: str,
    robots: Sequence[str],
    parts: Sequence[str],
    constraints: ConstraintProgram | None = None,
    *,
    time_limit: float = 2.0,
) -> dict[str, Outcome]:
    """Several robots' single-robot programs in one: grounded once, then optimised once per robot
    with only that robot active (``active/1``, domain.lp). The programs are independent (each robot
    is its own group), so each optimum is that of the robot's program alone; grounding once saves
    the fixed cost of a grounding (about 2 ms) for every robot but the first."""
    t0 = time.perf_counter()
    switches = "".join(f"#external active({r}).\n" for r in robots)
    ctl = _grounded(facts + switches, parts, constraints, _options())
    ground = time.perf_counter() - t0
    for r in robots:
        ctl.assign_external(clingo.Function("active", [clingo.Function(r)]), None)
    guards = _guards(constraints)
    out: dict[str, Outcome] = {}
    for r in robots:
        t1 = time.perf_counter()
        on = [(clingo.Function("active", [clingo.Function(o)]), o == r) for o in robots]
        out[r] = _optimise(ctl, on + guards, time_limit, t1, ground)
    CONTROLS.give_back(ctl)
    return out


def _check(ctl: clingo.Control, constraints: ConstraintProgram, on: set[int]) -> bool | None:
    """Satisfiable with exactly the constraints ``on``? None when the check runs out of time."""
    assumptions = [(ConstraintProgram.guard_symbol(i), i in on) for i in constraints.active]
    t0 = time.perf_counter()
    try:
        with ctl.solve(assumptions=assumptions, async_=True) as handle:
            if not handle.wait(DIAGNOSE_LIMIT):
                handle.cancel()
                return None
            return bool(handle.get().satisfiable)
    finally:
        WORK.add(solve=time.perf_counter() - t0)


def _explain(ctl: clingo.Control, constraints: ConstraintProgram | None, core: list[int], out: Outcome) -> None:
    if constraints is None or not constraints.active:
        out.inherent = True
        return
    ctl.configuration.solve.opt_mode = "ignore"  # satisfiability is all the checks need
    ctl.configuration.solve.models = 1
    literal_of = {}
    for i in constraints.active:
        atom = ctl.symbolic_atoms[ConstraintProgram.guard_symbol(i)]
        if atom is not None:
            literal_of[atom.literal] = i
    suspects = {literal_of[lit] for lit in core if lit in literal_of}
    if not suspects:
        if _check(ctl, constraints, set()) is False:
            out.inherent = True
            return
        suspects = set(constraints.active)
    if _check(ctl, constraints, set()) is False:
        out.inherent = True
        return
    # Deletion: drop each suspect whose absence keeps the rest unsatisfiable.
    for i in sorted(suspects):
        trial = suspects - {i}
        if _check(ctl, constraints, trial) is False:
            suspects = trial
    out.conflict = constraints.ids(suspects)
