"""Feedback validation: a client's choice checked against the library and the site, before any ASP.

Everything a client sends is untrusted. :func:`validate` either returns a :class:`Validated`
choice, whose values are site ids that are ASP constants, integers within the entry's range, or
ids of active constraints, or raises :class:`Refusal` with a reason for the tablet. Reasons quote
client text only through :func:`quote` (ASCII-escaped, truncated), so a reason is safe to log
and show.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

from protocol.asp_vocabulary import is_asp_constant

from .library import CONSTRAINT, DOOR, INT, OPENING, ROOM, Entry, Library, Param, SiteLike, site_choices

# Ids the restrictor gives constraints ("c17"); a cancel must name one of that shape.
CONSTRAINT_ID = re.compile(r"^c[0-9]{1,18}$")
_MAX_LISTED = 12  # choices listed in a refusal, so a big site does not flood the tablet


class Refusal(ValueError):
    """Feedback that cannot be applied; ``reason`` is meant for the human who gave it."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class Validated:
    """A library entry with checked values: ASP-safe symbols and in-range integers only."""

    entry: Entry
    values: dict[str, int | str]


def quote(value: Any, limit: int = 40) -> str:
    """Client text for a reason or a log line: ASCII-escaped repr, cut to ``limit`` characters."""
    text = ascii(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _listing(names: Collection[str]) -> str:
    names = list(names)
    shown = ", ".join(names[:_MAX_LISTED])
    return shown + (f", ... ({len(names)} in all)" if len(names) > _MAX_LISTED else "") if names else "none"


def validate(
    kind: Any, params: Any, library: Library, site: SiteLike, active_ids: Collection[str] | None = None
) -> Validated:
    """Check a choice; ``active_ids`` None means "no live set" (offline), so a cancel is only shape-checked."""
    if not isinstance(kind, str):
        raise Refusal(f"kind must name a library entry, got {type(kind).__name__}")
    entry = library.get(kind)
    if entry is None:
        raise Refusal(f"unknown constraint kind {quote(kind)}; the library has: {_listing(library.entries)}")
    if not isinstance(params, Mapping):
        raise Refusal(f"{entry.id}: parameters must be a map, got {type(params).__name__}")
    extra = [name for name in params if not isinstance(name, str) or entry.param(name) is None]
    if extra:
        shown = ", ".join(quote(name) for name in extra[:5])
        raise Refusal(f"{entry.id}: unknown parameter(s) {shown}; it takes: {_listing(entry.param_names)}")
    values: dict[str, int | str] = {}
    for param in entry.params:
        if param.name not in params:
            raise Refusal(f"{entry.id}: missing parameter {param.name} ({param.label})")
        values[param.name] = _check_value(entry, param, params[param.name], site, active_ids)
    return Validated(entry=entry, values=values)


def _check_value(
    entry: Entry, param: Param, value: Any, site: SiteLike, active_ids: Collection[str] | None
) -> int | str:
    where = f"{entry.id}: {param.name}"  # e.g. "door_unavailable: minutes 0 is below the minimum 1"
    if param.type == INT:
        # bool is an int subclass in Python, and 4.0 is not an integer choice: both are refused.
        if isinstance(value, bool) or not isinstance(value, int):
            raise Refusal(f"{where} must be an integer, got {_describe(value)}")
        if value < param.min:
            raise Refusal(f"{where} {value} is below the minimum {param.min}")
        if value > param.max:
            raise Refusal(f"{where} {value} is above the maximum {param.max}")
        return value
    if not isinstance(value, str):
        raise Refusal(f"{where} must be a {param.type} id, got {_describe(value)}")
    if param.type == CONSTRAINT:
        if not CONSTRAINT_ID.match(value):
            raise Refusal(f"{where} {quote(value)} is not a constraint id (like c12)")
        if active_ids is not None and value not in active_ids:
            raise Refusal(f"{entry.id}: no active constraint {value} (it may have expired or been withdrawn)")
        return value
    return _check_site_symbol(entry.id, param, value, site)


def _check_site_symbol(entry_id: str, param: Param, value: str, site: SiteLike) -> str:
    choices = site_choices(param, site) or []
    if param.type == OPENING and value not in site.openings:
        value = _canonical_opening(site, value)
    if value in choices:
        return value
    # Not a valid choice: say why as precisely as the site allows.
    if param.type == DOOR and value in site.doors and not site.doors[value].human_operated and param.human_operated:
        raise Refusal(
            f"{entry_id}: door {value} is not human-operated (robots open it themselves); choices: {_listing(choices)}"
        )
    known = {DOOR: site.doors, ROOM: site.rooms, OPENING: site.openings}[param.type]
    if value in known and not is_asp_constant(value):
        raise Refusal(
            f"{entry_id}: {param.type} {quote(value)} is not an ASP constant, so it cannot be used in a constraint"
        )
    raise Refusal(f"{entry_id}: site {site.name} has no {param.type} {quote(value)}; choices: {_listing(choices)}")


def _canonical_opening(site: SiteLike, value: str) -> str:
    """Passages may be named p_<b>_<a> for p_<a>_<b>; the site resolves that alias."""
    try:
        return site.opening(value).id  # type: ignore[attr-defined]
    except (KeyError, ValueError, AttributeError):
        return value


def _describe(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return f"the number {quote(value)}"
    if isinstance(value, str):
        return f"the text {quote(value)}"
    return f"a {type(value).__name__}"


def split_tablet_feedback(data: Any) -> tuple[Any, dict[str, Any]]:
    """The tablet's JSON form ``{"kind": "<entry>", "<param>": value, ...}`` -> (kind, params).

    Only the form is checked here; the values are checked by :func:`validate`.
    """
    if not isinstance(data, dict):
        raise Refusal(f"feedback must be a JSON object, got {type(data).__name__}")
    if "kind" not in data:
        raise Refusal('feedback needs a "kind" (the library entry id)')
    params = {key: value for key, value in data.items() if key != "kind"}
    for key, value in params.items():
        if value is None or not isinstance(value, (bool, int, float, str)):
            raise Refusal(f"parameter {quote(key)} must be a number or an id, got {type(value).__name__}")
    return data["kind"], params
