"""The check that holds ASP text to the shared vocabulary (:mod:`protocol.asp_vocabulary`).

The restrictor checks every ASP text it emits with it, and the planner re-checks what it receives.

``docs/architecture.md`` ("ASP vocabulary shared by restrictor and planner") fixes the atoms the
planner's encoding defines and the facts the restrictor may state. Every piece of ASP the
restrictor hands to the solver, library templates at load time and each compiled constraint
before it joins the active set, passes :func:`check_program`: it must parse, consist only of
rules (integrity constraints and facts included) and weak constraints, and mention no predicate
outside :data:`VOCABULARY`. No directives (``#include``, ``#script``, ``#program``, ``#const``,
``#show``, ``#external`` ...), no strings, no comments, no external ``@`` calls, no theory atoms.

The directive screen is lexical and runs *before* clingo sees the text, because clingo's parser
acts on ``#include`` while parsing (it opens the file), so the AST check alone would be too late.
"""

from __future__ import annotations

import re
from typing import Any

import clingo
import clingo.ast as ast

from protocol.asp_terms import ASP_INT_MAX, ASP_INT_MIN, INTERPRETED_NAMES, VOCABULARY, ConstraintTerms, InterpretedFact
from protocol.asp_vocabulary import UnsafeProgram, is_asp_constant

__all__ = [
    "ASP_INT_MAX",
    "ASP_INT_MIN",
    "VOCABULARY",
    "UnsafeProgram",
    "check_program",
    "is_asp_constant",
    "read_program",
]


# Hash words that are part of ordinary rule bodies; every other ``#word`` is a directive.
_ALLOWED_HASH_WORDS = frozenset({"count", "sum", "min", "max", "false", "true", "inf", "sup"})
_HASH_WORD = re.compile(r"#\s*([A-Za-z_]\w*\+?)")

# Statement kinds a constraint may consist of.
_STATEMENTS = frozenset({ast.ASTType.Rule, ast.ASTType.Minimize})
# AST nodes that never belong in a constraint, wherever they appear.
_FORBIDDEN_NODES = frozenset({ast.ASTType.TheoryAtom, ast.ASTType.TheoryAtomDefinition, ast.ASTType.TheoryDefinition})


def check_program(text: str) -> set[tuple[str, int]]:
    """Raise :class:`UnsafeProgram` unless ``text`` is a plain program over :data:`VOCABULARY`.

    Returns the predicate signatures it uses.
    """
    return _checked(text)[1]


def read_program(text: str) -> tuple[list[ast.AST], ConstraintTerms]:
    """Check ``text`` as :func:`check_program` does (raising :class:`UnsafeProgram`) and return its
    statements (the implicit ``#program base.`` left out) and what it states, as fields."""
    statements, used = _checked(text)
    return statements, _terms(statements, used)


def _checked(text: str) -> tuple[list[ast.AST], set[tuple[str, int]]]:
    """The statements of a checked program and the predicate signatures it uses."""
    _lexical_screen(text)
    statements: list[ast.AST] = []
    messages: list[str] = []
    try:
        ast.parse_string(text, statements.append, logger=lambda _code, message: messages.append(message.strip()))
    except RuntimeError:
        detail = "; ".join(m.replace("<string>:", "line ") for m in messages) or "syntax error"
        raise UnsafeProgram(f"not valid ASP: {detail}") from None
    used: set[tuple[str, int]] = set()
    for statement in statements:
        kind = statement.ast_type
        if kind == ast.ASTType.Program:
            # parse_string opens every text with an implicit "#program base."; an explicit one is
            # caught by the lexical screen, so only that implicit one can reach here.
            if statement.name != "base" or len(statement.parameters):
                raise UnsafeProgram("#program sections are not allowed")
            continue
        if kind not in _STATEMENTS:
            raise UnsafeProgram(
                f"only rules and weak constraints are allowed, found {kind.name}: {str(statement)[:80]}"
            )
        _collect_atoms(statement, used)
    unknown = sorted(sig for sig in used if sig not in VOCABULARY)
    if unknown:
        names = ", ".join(f"{name}/{arity}" for name, arity in unknown)
        allowed = ", ".join(f"{name}/{arity}" for name, arity in VOCABULARY)
        raise UnsafeProgram(f"predicate(s) {names} are not in the shared vocabulary ({allowed})")
    return [s for s in statements if s.ast_type != ast.ASTType.Program], used


# ---------------------------------------------------------------------------- a program's terms


def _terms(statements: list[ast.AST], used: set[tuple[str, int]]) -> ConstraintTerms:
    """The interpreted facts, watched rooms and integers of checked ``statements``."""
    terms = ConstraintTerms(predicates=sorted({name for name, _ in used}))
    rooms: set[str] = set()
    numbers: set[int] = set()
    for statement in statements:
        fact = _interpreted_fact(statement)
        if fact is not None:
            terms.facts.append(fact)
        _walk_terms(statement, rooms, numbers, terms)
    terms.rooms, terms.numbers = sorted(rooms), sorted(numbers)
    return terms


def _interpreted_fact(statement: ast.AST) -> InterpretedFact | None:
    """``human_unavailable(d, 10, 70).`` as a fact, for a bodiless rule stating one with constant arguments."""
    if statement.ast_type != ast.ASTType.Rule or len(statement.body):
        return None
    head = statement.head
    if head.ast_type != ast.ASTType.Literal or head.sign != ast.Sign.NoSign:
        return None
    atom = head.atom.symbol if head.atom.ast_type == ast.ASTType.SymbolicAtom else None
    if atom is None or atom.ast_type != ast.ASTType.Function or atom.name not in INTERPRETED_NAMES:
        return None
    values = [_constant(arg) for arg in atom.arguments]
    if len(values) != 3 or not isinstance(values[0], str) or not all(isinstance(v, int) for v in values[1:]):
        return None
    return InterpretedFact(predicate=atom.name, subject=values[0], start=values[1], end=values[2])


def _constant(term: ast.AST) -> str | int | None:
    """A constant (name) or an integer written in place; None for anything else."""
    if term.ast_type != ast.ASTType.SymbolicTerm:
        return None
    symbol = term.symbol
    if symbol.type == clingo.SymbolType.Number:
        return symbol.number
    if symbol.type == clingo.SymbolType.Function and not symbol.arguments and symbol.positive:
        return symbol.name
    return None


def _walk_terms(node: Any, rooms: set[str], numbers: set[int], terms: ConstraintTerms) -> None:
    """Record the room of every ``robot_in/4`` atom and every integer written."""
    if isinstance(node, ast.AST):
        kind = node.ast_type
        if kind == ast.ASTType.SymbolicTerm and node.symbol.type == clingo.SymbolType.Number:
            numbers.add(abs(node.symbol.number))  # as written: a sign is an operation on it
        if kind == ast.ASTType.Function and node.name == "robot_in" and len(node.arguments) == 4:
            room = node.arguments[1]
            if room.ast_type == ast.ASTType.Variable:
                terms.any_room = True
            elif isinstance(name := _constant(room), str):
                rooms.add(name)
        for key in node.keys():
            if key != "location":
                _walk_terms(getattr(node, key), rooms, numbers, terms)
    elif isinstance(node, ast.ASTSequence):
        for child in node:
            _walk_terms(child, rooms, numbers, terms)


def _lexical_screen(text: str) -> None:
    if not isinstance(text, str):
        raise UnsafeProgram(f"expected ASP text, got {type(text).__name__}")
    if not text.isascii():
        raise UnsafeProgram("non-ASCII characters are not allowed")
    # "@" is not screened here: weak constraints need it for priorities; the AST check refuses @calls.
    for char, what in (('"', "strings"), ("%", "comments"), ("&", "theory atoms")):
        if char in text:
            raise UnsafeProgram(f"{what} ({char!r}) are not allowed")
    for match in _HASH_WORD.finditer(text):
        if match.group(1).rstrip("+") not in _ALLOWED_HASH_WORDS:
            raise UnsafeProgram(f"directive #{match.group(1)} is not allowed")


def _collect_atoms(node: Any, used: set[tuple[str, int]]) -> None:
    """Walk an AST node, recording the signature of every symbolic atom."""
    if isinstance(node, ast.AST):
        kind = node.ast_type
        if kind in _FORBIDDEN_NODES:
            raise UnsafeProgram(f"{kind.name} is not allowed")
        if kind == ast.ASTType.Function and getattr(node, "external", 0):
            raise UnsafeProgram("external function calls are not allowed")
        if kind == ast.ASTType.SymbolicAtom:
            _record_atom(node.symbol, used)
        for key in node.keys():
            if key != "location":
                _collect_atoms(getattr(node, key), used)
    elif isinstance(node, ast.ASTSequence):
        for child in node:
            _collect_atoms(child, used)


def _record_atom(term: ast.AST, used: set[tuple[str, int]]) -> None:
    kind = term.ast_type
    if kind == ast.ASTType.Function:
        used.add((term.name, len(term.arguments)))
    elif kind == ast.ASTType.SymbolicTerm and term.symbol.type == clingo.SymbolType.Function:
        used.add((term.symbol.name, len(term.symbol.arguments)))
    elif kind == ast.ASTType.Pool:
        for option in term.arguments:
            _record_atom(option, used)
    elif kind == ast.ASTType.UnaryOperation:  # classical negation -p(x)
        _record_atom(term.argument, used)
    else:
        raise UnsafeProgram(f"unsupported atom {str(term)[:60]}")
