"""The ASP vocabulary shared by the restrictor and the planner: the predicates either side may
use, ASP's integer range and what a constant looks like.

``docs/architecture.md`` ("ASP vocabulary shared by restrictor and planner") fixes the atoms the
planner's encoding defines and the facts the restrictor may state. The check that holds every ASP
text to it (clingo's parser) is :func:`runtime.asp_check.check_program`.
"""

from __future__ import annotations

import re

# the vocabulary itself lives in asp_terms; its names are read from here too
from .asp_terms import ASP_INT_MAX, ASP_INT_MIN, VOCABULARY

__all__ = ["ASP_CONSTANT", "ASP_INT_MAX", "ASP_INT_MIN", "VOCABULARY", "UnsafeProgram", "is_asp_constant"]


# A symbol the restrictor may write: a lower-case ASP constant. ``not`` is a keyword, not a constant.
ASP_CONSTANT = re.compile(r"^[a-z][A-Za-z0-9_]{0,63}$")
_KEYWORDS = frozenset({"not"})


class UnsafeProgram(ValueError):
    """ASP text that is not a plain program over the shared vocabulary."""


def is_asp_constant(value: object) -> bool:
    """True for a string that clingo reads as a constant (lower-case first, no keyword)."""
    return isinstance(value, str) and bool(ASP_CONSTANT.match(value)) and value not in _KEYWORDS
