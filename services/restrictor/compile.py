"""Templates → ASP: a validated choice and the time "now" become one constraint's ASP and window.

Only :class:`validate.Validated` values reach a template, and the result is checked again with
:func:`runtime.asp_check.read_program` (defence in depth: a library template was checked at load with
sample values, this checks the real text), which also gives what the text states as fields
(:class:`protocol.asp_terms.ConstraintTerms`). No client text is ever substituted.

Windows are absolute integer seconds on the site clock. The human means "from now on, for N
minutes", i.e. the real interval [now, now + 60·N). ASP needs integers, so the window is
widened to whole seconds: ``t0 = floor(now)``, ``t1 = ceil(now + 60·N)``. Widening (never
narrowing) keeps the promise: no instant the human asked for falls outside the constraint.
The constraint expires when the clock reaches ``t1``.
"""

from __future__ import annotations

import logging
import math
import string
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

from protocol.asp_terms import ConstraintTerms
from protocol.asp_vocabulary import ASP_INT_MAX, ASP_INT_MIN, UnsafeProgram
from runtime.asp_check import read_program

from .library import ADD, INT, Library, SiteLike
from .validate import Refusal, Validated, validate

log = logging.getLogger("arroch.restrictor")


@dataclass(frozen=True)
class Compiled:
    """One constraint ready for the active set: its validated choice, window, ASP and what the ASP
    states (the planner reads these fields, not the text)."""

    validated: Validated
    start: int
    end: int
    asp: str
    terms: ConstraintTerms

    @property
    def kind(self) -> str:
        return self.validated.entry.id

    @property
    def values(self) -> dict[str, int | str]:
        return self.validated.values


def window(now: float, minutes: int) -> tuple[int, int]:
    """[floor(now), ceil(now + 60·minutes)): integer seconds covering the asked interval."""
    if not math.isfinite(now):
        raise Refusal("the site clock does not give a usable time")
    start, end = math.floor(now), math.ceil(now + 60 * minutes)
    if start < ASP_INT_MIN or end > ASP_INT_MAX:
        raise Refusal(f"the window [{start}, {end}) does not fit ASP integers (clock time {now:.0f})")
    return start, end


def render(validated: Validated, now: float) -> Compiled:
    """Fill an add entry's template; raises :class:`Refusal` if the window does not fit."""
    entry = validated.entry
    if entry.effect != ADD:
        raise ValueError(f"{entry.id} is a {entry.effect} entry: it has no ASP")
    minutes = validated.values[entry.window_param] if entry.window_param else entry.window_minutes
    start, end = window(now, int(minutes))  # type: ignore[arg-type]
    mapping: dict[str, str] = {"t0": str(start), "t1": str(end)}
    for param in entry.params:
        value = validated.values[param.name]
        # Integers are formatted by int.__str__, symbols were checked to be ASP constants.
        mapping[param.name] = str(int(value)) if param.type == INT else str(value)
    text = string.Template(entry.asp).substitute(mapping)
    asp = "".join(line.strip() + "\n" for line in text.splitlines() if line.strip())
    try:
        _, terms = read_program(asp)
    except UnsafeProgram as exc:
        # Cannot happen with a library that loaded; if it does, nothing unchecked goes out.
        log.error("compiled %s failed the ASP check: %s", entry.id, exc)
        raise Refusal(f"{entry.id}: the compiled constraint failed the ASP safety check") from None
    return Compiled(validated=validated, start=start, end=end, asp=asp, terms=terms)


def compile_feedback(
    kind: Any, params: Any, library: Library, site: SiteLike, now: float, active_ids: Collection[str] | None = None
) -> Validated | Compiled:
    """Validate then render: a :class:`Compiled` for add entries, the :class:`Validated` cancel otherwise."""
    validated = validate(kind, params, library, site, active_ids)
    if validated.entry.effect != ADD:
        return validated
    return render(validated, now)


def describe(kind: str, values: dict[str, Any]) -> str:
    """``door_unavailable(door=d_storage, minutes=4)``: a constraint in one line for logs and acks."""
    return f"{kind}({', '.join(f'{name}={value}' for name, value in values.items())})"
