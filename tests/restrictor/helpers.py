"""Helpers of the restrictor tests: valid parameters for an entry, and running clingo on programs."""

from __future__ import annotations

from collections.abc import Iterable

import clingo

from services.restrictor.library import CONSTRAINT, INT, Entry, site_choices


def valid_params(entry: Entry, site, active_ids: Iterable[str] = ("c1",)) -> dict:
    """One valid choice for every parameter of ``entry`` on ``site`` (the first choice, the minimum)."""
    params = {}
    for param in entry.params:
        if param.type == INT:
            params[param.name] = param.min
        elif param.type == CONSTRAINT:
            params[param.name] = next(iter(active_ids))
        else:
            params[param.name] = site_choices(param, site)[0]
    return params


def answer_sets(*programs: str, optimal: bool = False) -> list[set[str]]:
    """Every answer set (or, with ``optimal``, the optimal ones) of the programs, as sets of atom strings."""
    ctl = _control(programs, ["0", "--opt-mode=optN"] if optimal else ["0"])
    models: list[set[str]] = []

    def on_model(model: clingo.Model) -> None:
        if not optimal or model.optimality_proven:
            models.append({str(atom) for atom in model.symbols(shown=True)})

    ctl.solve(on_model=on_model)
    return models


def possible(*programs: str) -> set[str] | None:
    """The atoms true in at least one answer set (clingo's brave consequences); None if unsatisfiable."""
    ctl = _control(programs, ["0", "--enum-mode=brave"])
    last: set[str] = set()

    def on_model(model: clingo.Model) -> None:
        last.clear()
        last.update(str(atom) for atom in model.symbols(shown=True))

    result = ctl.solve(on_model=on_model)
    return last if result.satisfiable else None


def _control(programs, arguments: list[str]) -> clingo.Control:
    ctl = clingo.Control(arguments, logger=lambda *_: None)
    for program in programs:
        ctl.add("base", [], program)
    ctl.ground([("base", [])])
    return ctl


def values_of(atoms: set[str] | list[set[str]], predicate: str) -> set[tuple[str, ...]]:
    """The argument tuples of ``predicate`` atoms in a set of atoms (or in any of several models)."""
    models = [atoms] if isinstance(atoms, set) else atoms
    out = set()
    for model in models:
        for atom in model:
            symbol = clingo.parse_term(atom)
            if symbol.name == predicate:
                out.add(tuple(str(a) for a in symbol.arguments))
    return out
