"""The human's constraints as the solver takes them: checked, and each one switchable by its id.

Constraints arrive as ASP text over the shared vocabulary (docs/architecture.md) and are added to
the program as they are, with one addition: every rule of constraint number ``i`` gets the body
literal ``cactive(i)``, an ``#external`` atom. Solving assumes all of them true; when that is
unsatisfiable, clingo's unsatisfiable core names a set of constraints that cannot hold together,
and dropping them one at a time shrinks it to a minimal conflicting set for the ``plan_conflict``
diagnostic - all without grounding the program again.

Text from the wire is untrusted: it must pass the restrictor's vocabulary check (no directives
such as ``#script``/``#include``, only rules and weak constraints, only vocabulary predicates).
A constraint that fails it is left out and reported, never added. That check and clingo's parse are
one pass (:func:`runtime.asp_check.read_program`).

What the planner needs to know of a constraint besides its rules (the rooms whose stays it
watches, the integers where a wait may end, the windows the validator checks) it reads from the
constraint's terms (:class:`protocol.asp_terms.ConstraintTerms`), which the restrictor sends beside
the text; only a text that came without them (a file given to the CLI, a recording made before
constraints carried them) has them read off its own parse.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import clingo
import clingo.ast as ast

from protocol.asp_terms import ConstraintTerms, InterpretedFact
from protocol.asp_vocabulary import UnsafeProgram
from protocol.messages import ConstraintSet
from runtime.asp_check import read_program

GUARD = "cactive"


@dataclass(frozen=True)
class ConstraintText:
    id: str
    asp: str
    terms: ConstraintTerms | None = None  # what the text states, as its sender says; None: read off the parse


@dataclass
class ConstraintProgram:
    """Parsed, guarded constraints ready to be added to any number of clingo programs."""

    items: list[ConstraintText]
    statements: dict[int, list[ast.AST]] = field(default_factory=dict)
    terms: dict[int, ConstraintTerms] = field(default_factory=dict)
    invalid: dict[str, str] = field(default_factory=dict)  # id -> why it was left out
    _admits: dict[tuple[str, int], bool] = field(default_factory=dict, repr=False)

    @classmethod
    def build(cls, items: list[ConstraintText]) -> ConstraintProgram:
        prog = cls(items=list(items))
        for index, item in enumerate(prog.items):
            try:
                stmts, read = read_program(item.asp)
            except UnsafeProgram as exc:
                prog.invalid[item.id] = str(exc) or "not valid ASP"
                continue
            prog.statements[index] = [_guard(s, index) for s in stmts]
            prog.terms[index] = item.terms if item.terms is not None else read
        return prog

    @property
    def active(self) -> list[int]:
        return sorted(self.statements)

    def ids(self, indices: list[int] | set[int]) -> list[str]:
        return [self.items[i].id for i in sorted(indices)]

    @property
    def mentions_rooms(self) -> bool:
        """True when robot_in/room_forbidden appear (the encoding then grounds rooms.lp)."""
        return any(terms.mentions_rooms for terms in self.terms.values())

    def facts(self) -> list[InterpretedFact]:
        """The interpreted facts the active constraints state."""
        return [fact for i in self.active for fact in self.terms[i].facts]

    def add_to(self, ctl: clingo.Control, only: set[int] | None = None) -> None:
        """Add the guarded statements and their ``#external`` switches to ``ctl`` (before grounding)."""
        chosen = [i for i in self.active if only is None or i in only]
        if chosen:
            ctl.add("base", [], "".join(f"#external {GUARD}({i}).\n" for i in chosen))
        with ast.ProgramBuilder(ctl) as builder:
            for i in chosen:
                for stmt in self.statements[i]:
                    builder.add(stmt)

    @staticmethod
    def guard_symbol(index: int) -> clingo.Symbol:
        return clingo.Function(GUARD, [clingo.Number(index)])

    def admits_opening(self, door: str, t: int) -> bool:
        """Whether the constraints allow the human to open ``door`` at absolute second ``t``.

        Used for openings taken from other plans (e.g. the plan being replaced, made before a new
        constraint arrived): a robot may only share an opening the constraints still allow."""
        key = (door, t)
        hit = self._admits.get(key)
        if hit is None and any(
            f.predicate == "human_unavailable" and f.subject == door and f.start <= t < f.end for f in self.facts()
        ):
            hit = self._admits[key] = False  # the encoding's reading of the fact (vocabulary.lp), not in this program
        if hit is None:
            ctl = clingo.Control(["--warn=none"])
            ctl.add("base", [], f"human_opens({door},{t}).\n")
            self.add_to(ctl)
            ctl.ground([("base", [])])
            for i in self.active:
                ctl.assign_external(self.guard_symbol(i), True)
            hit = bool(ctl.solve().satisfiable)
            self._admits[key] = hit
        return hit

    def watched_rooms(self, rooms) -> set[str]:
        """Rooms whose stays the constraints can look at (robot_in/4 with a room constant, or every
        room when one uses a variable there)."""
        out: set[str] = set()
        for i in self.active:
            if self.terms[i].any_room:
                return set(rooms)
            out.update(self.terms[i].rooms)
        return out & set(rooms)

    def numbers(self) -> set[int]:
        """The integers written in active constraints that state none of the facts the encoding
        interprets (those say themselves where a wait may end, see vocabulary.lp)."""
        out: set[int] = set()
        for i in self.active:
            if not self.terms[i].states_interpreted:
                out.update(self.terms[i].numbers)
        return out


def _guard(stmt: ast.AST, index: int) -> ast.AST:
    if stmt.ast_type not in (ast.ASTType.Rule, ast.ASTType.Minimize):
        return stmt  # check_program admits nothing else
    loc = stmt.location
    atom = ast.SymbolicAtom(ast.Function(loc, GUARD, [ast.SymbolicTerm(loc, clingo.Number(index))], 0))
    literal = ast.Literal(loc, ast.Sign.NoSign, atom)
    return stmt.update(body=list(stmt.body) + [literal])


# ---------------------------------------------------------------------- sources of constraints


def from_constraint_set(cs: ConstraintSet) -> list[ConstraintText]:
    """One item per active constraint; a set with only its combined ``asp`` becomes one item."""
    items = [ConstraintText(c.id, c.asp, c.terms) for c in cs.constraints if c.asp.strip()]
    if not items and cs.asp.strip():
        items = [ConstraintText(f"set_v{cs.version}", cs.asp)]
    return items


def unavailable(door: str, t0: int, t1: int, cid: str) -> ConstraintText:
    """The human will not open ``door`` in [t0, t1), for the one-shot CLI: the fact alone, which
    the encoding interprets (vocabulary.lp forbids the openings it covers)."""
    fact = InterpretedFact(predicate="human_unavailable", subject=door, start=t0, end=t1)
    return ConstraintText(cid, fact.asp, ConstraintTerms(predicates=[fact.predicate], facts=[fact]))


def parse_unavailable(spec: str, index: int) -> ConstraintText:
    """``DOOR:T0:T1`` (integer seconds on the site clock) -> a door_unavailable constraint."""
    parts = spec.split(":")
    if len(parts) != 3:
        raise ValueError(f"--unavailable {spec!r}: expected DOOR:T0:T1")
    door, t0, t1 = parts
    try:
        a, b = int(t0), int(t1)
    except ValueError:
        raise ValueError(f"--unavailable {spec!r}: T0 and T1 must be integer seconds") from None
    if b <= a:
        raise ValueError(f"--unavailable {spec!r}: T1 must be greater than T0")
    if not re.fullmatch(r"[a-z][a-z0-9_]*", door):
        raise ValueError(f"--unavailable {spec!r}: {door!r} is not a door id")
    return unavailable(door, a, b, f"unavailable_{index}")


def from_file(path: str | Path) -> ConstraintText:
    """A ``.lp`` file as one constraint (id ``file:<name>``); ``%`` line comments are dropped."""
    p = Path(path)
    text = p.read_text(encoding="utf-8")
    body = "\n".join(line.split("%", 1)[0] for line in text.splitlines())
    return ConstraintText(f"file_{re.sub(r'[^A-Za-z0-9_]', '_', p.stem)}", body + "\n")
