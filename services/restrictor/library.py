"""The constraint library F (paper §III-B) as data: loading, validating, and resolving against a site.

The library is a TOML file (the packaged ``library.toml``, or a site-specific one given with
``--library``). Loading checks the whole file and refuses it with a :class:`LibraryError` whose
message names the file, the entry and the field, e.g.
``lab.toml: entry[1] (id "forbid_room"): params[1] (name "minutes"): min 5 is above max 3``.
Templates are checked at load time too: their placeholders must be parameters (or ``t0``/``t1``),
and a rendering with sample values must pass :func:`runtime.asp_check.check_program`, so a library that
loads can only ever produce ASP over the shared vocabulary.

:func:`library_for_site` gives the library with the site's choices filled in: what the running
restrictor serves on ``constraints/library`` for the tablet's and the AR client's buttons
(``arroch constraints library --json`` prints it).
"""

from __future__ import annotations

import functools
import re
import string
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Protocol

import msgspec
from msgspec import Meta, Struct

from protocol.asp_vocabulary import ASP_INT_MAX, ASP_INT_MIN, UnsafeProgram, is_asp_constant

# The limits of a library as the wire carries it: a file the restrictor loads must fit in one.
from protocol.constraint_library import (
    MAX_ENTRIES,
    MAX_HELP,
    MAX_LABEL,
    MAX_PARAMS,
    LibraryEntry,
    LibraryParam,
    LibraryWindow,
)
from protocol.errors import ProtocolError
from protocol.schema import Says
from protocol.validation import Words, field_error
from runtime.asp_check import check_program

PACKAGED = "<packaged library>"

# Parameter types. Symbol types take their choices from the site; "constraint" from the live set.
INT = "int"
DOOR = "door"
ROOM = "room"
OPENING = "opening"
CONSTRAINT = "constraint"
SYMBOL_TYPES = (DOOR, ROOM, OPENING)
PARAM_TYPES = (INT, *SYMBOL_TYPES, CONSTRAINT)

ADD = "add"
CANCEL = "cancel"
EFFECTS = (ADD, CANCEL)

# The window placeholders every "add" template may use.
WINDOW_NAMES = ("t0", "t1")
# A window longer than a week is not "feedback" any more; this also keeps t1 well inside ASP ints.
MAX_WINDOW_MINUTES = 7 * 24 * 60

_ID = re.compile(r"^[a-z][a-z0-9_]{0,63}$")
_MAX_TEMPLATE = 4096


class LibraryError(ValueError):
    """A library file that cannot be used; the message names the file, entry and field."""


class SiteLike(Protocol):
    """What the library needs of a :class:`protocol.site.Site`."""

    name: str
    rooms: dict[str, Any]
    doors: dict[str, Any]
    openings: dict[str, Any]


@dataclass(frozen=True)
class Param:
    name: str
    type: str
    label: str
    help: str = ""
    min: int | None = None  # int parameters only
    max: int | None = None
    human_operated: bool = True  # door parameters: offer only doors the human must open


@dataclass(frozen=True)
class Cancels:
    """Adding the entry removes active constraints of ``kind`` whose ``same`` parameters are equal."""

    kind: str
    same: tuple[str, ...]


@dataclass(frozen=True)
class Entry:
    id: str
    label: str
    help: str
    effect: str
    params: tuple[Param, ...]
    asp: str = ""
    window_param: str | None = None
    window_minutes: int | None = None
    cancels: tuple[Cancels, ...] = ()

    def param(self, name: str) -> Param | None:
        return next((p for p in self.params if p.name == name), None)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)


@dataclass(frozen=True)
class Library:
    entries: dict[str, Entry]
    source: str

    def get(self, kind: str) -> Entry | None:
        return self.entries.get(kind)


# --------------------------------------------------------------------------- loading


def load_library(path: str | Path | None = None) -> Library:
    """Load and validate a library file; ``None`` loads the packaged one."""
    if path is None:
        return _packaged()
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"constraint library {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LibraryError(f"{path.name}: cannot be read: {exc}") from None
    return parse_library(text, path.name, source=str(path))


@functools.lru_cache(maxsize=1)
def _packaged() -> Library:
    text = resources.files(__package__).joinpath("library.toml").read_text(encoding="utf-8")
    return parse_library(text, "library.toml", source=PACKAGED)


# --------------------------------------------------------------------------- the file format

# The file as msgspec Structs: keys, types and sizes are checked while converting; what the keys
# mean together (ranges, windows, templates, references between entries) is checked below.


class _LibraryWords(Words):
    """Refusals worded as this file's readers know them (``label: 81 characters, more than 80``)."""

    _WANT = {"str": "a string", "int": "an integer", "bool": "true or false", "object": "a table"}

    def type_mismatch(self, want: list[str], value: Any, hint: Any, name: str) -> str:
        if want == ["array"]:
            return f"expected a list of tables, got {self.value(value)}"
        return f"expected {' or '.join(self._WANT.get(w, w) for w in want)}, got {self.value(value)}"

    def length(self, kind: str, op: str, n: str, value: Any, name: str) -> str:
        if name == "entry":
            return "needs at least one [[entry]]" if op == ">=" else f"has {len(value)} entries, more than {n}"
        if name == "params":
            return f"{len(value)} parameters, more than {n}"
        return f"{len(value)} characters, more than {n}"

    def missing(self, parent: str, name: str, hint: Any) -> tuple[str, str]:
        if not parent and name == "entry":
            return "", "needs at least one [[entry]]"
        return _join(parent, name), "required"

    def unknown(self, parent: str, name: str, allowed: tuple[str, ...]) -> tuple[str, str]:
        return parent, f"unknown field(s) {name} (known: {', '.join(sorted(allowed))})"


_WORDS = _LibraryWords()


def _join(parent: str, name: str) -> str:
    return f"{parent}.{name}" if parent else name


def _says_identifier(value: Any) -> str:
    return f"{value!r} is not an identifier (lower-case letter first, then a-z, 0-9, _; 64 at most)"


def _text(limit: int, *, required: bool) -> Any:
    def says(value: Any) -> str:
        if not isinstance(value, str):
            return f"expected a string, got {type(value).__name__}"
        if len(value) > limit:
            return f"{len(value)} characters, more than {limit}"
        return "must not be empty"

    return Annotated[str, Meta(max_length=limit, pattern=r"\S" if required else None), Says(says)]


Identifier = Annotated[str, Meta(pattern=_ID.pattern), Says(_says_identifier)]


class _Table(Struct, kw_only=True, forbid_unknown_fields=True):
    """A table of the file: its keys declared, no other allowed."""


class _CancelsTable(_Table, kw_only=True):
    kind: Identifier
    same: Annotated[list[str], Says(lambda v: "expected a list of parameter names")] = []


class _ParamTable(_Table, kw_only=True):
    name: Identifier
    type: Literal[PARAM_TYPES]  # type: ignore[valid-type]
    label: _text(MAX_LABEL, required=True)
    help: _text(MAX_HELP, required=False) = ""
    min: int | None = None
    max: int | None = None
    human_operated: bool | None = None


class _EntryTable(_Table, kw_only=True):
    id: Identifier
    label: _text(MAX_LABEL, required=True)
    help: _text(MAX_HELP, required=True)
    effect: Literal[EFFECTS] = ADD  # type: ignore[valid-type]
    params: Annotated[list[_ParamTable], Meta(max_length=MAX_PARAMS)] = []
    asp: _text(_MAX_TEMPLATE, required=True) | None = None
    window_param: str | None = None
    window_minutes: int | None = None
    cancels: list[_CancelsTable] | None = None


class _LibraryFile(_Table, kw_only=True):
    version: Any = 1
    entry: Annotated[list[_EntryTable], Meta(min_length=1, max_length=MAX_ENTRIES)]


_LABEL = re.compile(r"(?P<name>entry|params|cancels)\[(?P<i>\d+)\]")


def _library_error(name: str, data: dict[str, Any], error: ProtocolError) -> LibraryError:
    """``entry[0].params[1].min`` as ``name: entry[0] (id 'busy'): params[1] (name 'minutes'): min: ...``."""
    parts, raw, rest = [name], data, error.field
    while (m := _LABEL.match(rest)) is not None:
        items = raw.get(m["name"]) if isinstance(raw, dict) else None
        i = int(m["i"])
        raw = items[i] if isinstance(items, list) and i < len(items) else None
        key = "id" if m["name"] == "entry" else "name" if m["name"] == "params" else None
        ident = raw.get(key) if key and isinstance(raw, dict) else None
        parts.append(m.group(0) + (f" ({key} {ident!r})" if isinstance(ident, str) else ""))
        rest = rest[m.end() :].lstrip(".")
    if rest:
        parts.append(rest)
    return LibraryError(": ".join([*parts, error.problem]))


def parse_library(text: str, name: str = "library.toml", *, source: str | None = None) -> Library:
    """Validate library TOML text; ``name`` prefixes every error message."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LibraryError(f"{name}: not valid TOML: {exc}") from None
    try:
        parsed = msgspec.convert(data, _LibraryFile)
    except msgspec.ValidationError as exc:
        raise _library_error(name, data, field_error(exc, _LibraryFile, data, words=_WORDS)) from None
    where = _Where(name)
    if parsed.version != 1 or isinstance(parsed.version, bool):
        where.fail(f"version {parsed.version!r} is not supported (this restrictor reads version 1)")
    entries: dict[str, Entry] = {}
    for index, table in enumerate(parsed.entry):
        entry_where = where.entry(index, {"id": table.id})
        entry = _parse_entry(table, entry_where)
        if entry.id in entries:
            entry_where.fail(f"duplicate id {entry.id!r}")
        entries[entry.id] = entry
    # Cross-entry references are checked once every entry is known.
    for index, entry in enumerate(entries.values()):
        for ci, cancels in enumerate(entry.cancels):
            _check_cancels(entry, cancels, entries, where.entry(index, {"id": entry.id}).sub(f"cancels[{ci}]"))
    return Library(entries=entries, source=source or name)


class _Where:
    """Builds the "file: entry[i] (id ...): field" prefix of error messages."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix

    def entry(self, index: int, raw: Any) -> _Where:
        ident = raw.get("id") if isinstance(raw, dict) else None
        label = f" (id {ident!r})" if isinstance(ident, str) else ""
        return _Where(f"{self.prefix}: entry[{index}]{label}")

    def sub(self, field: str) -> _Where:
        return _Where(f"{self.prefix}: {field}")

    def fail(self, problem: str) -> Any:
        raise LibraryError(f"{self.prefix}: {problem}")


def _parse_param(raw: _ParamTable, where: _Where) -> Param:
    name, kind = raw.name, raw.type
    if name == "kind":
        where.fail("name: 'kind' is reserved (it names the entry in feedback)")
    if name in WINDOW_NAMES:
        where.fail(f"name: {name!r} is reserved for the window")
    lo, hi = raw.min, raw.max
    if kind == INT:
        if lo is None or hi is None:
            where.fail("an int parameter needs both min and max")
        if lo > hi:
            where.fail(f"min {lo} is above max {hi}")
        if lo < ASP_INT_MIN or hi > ASP_INT_MAX:
            where.fail(f"range [{lo}, {hi}] exceeds ASP integers [{ASP_INT_MIN}, {ASP_INT_MAX}]")
    elif lo is not None or hi is not None:
        where.fail(f"min/max apply to int parameters only, not {kind}")
    if raw.human_operated is not None and kind != DOOR:
        where.fail(f"human_operated applies to door parameters only, not {kind}")
    human_operated = True if raw.human_operated is None else raw.human_operated
    return Param(name=name, type=kind, label=raw.label, help=raw.help, min=lo, max=hi, human_operated=human_operated)


def _parse_entry(raw: _EntryTable, where: _Where) -> Entry:
    params: list[Param] = []
    for index, raw_param in enumerate(raw.params):
        param_where = where.sub(f"params[{index}] (name {raw_param.name!r})")
        param = _parse_param(raw_param, param_where)
        if any(p.name == param.name for p in params):
            param_where.fail(f"duplicate parameter name {param.name!r}")
        params.append(param)
    entry_params = tuple(params)
    cancels = tuple(Cancels(kind=c.kind, same=tuple(c.same)) for c in raw.cancels or ())
    if raw.effect == CANCEL:
        return _cancel_entry(raw, where, entry_params, cancels)
    return _add_entry(raw, where, entry_params, cancels)


def _cancel_entry(raw: _EntryTable, where: _Where, params: tuple[Param, ...], cancels: tuple[Cancels, ...]) -> Entry:
    for key in ("asp", "window_param", "window_minutes", "cancels"):
        if getattr(raw, key) is not None:
            where.fail(f"{key}: a cancel entry has no {key}")
    if len(params) != 1 or params[0].type != CONSTRAINT:
        where.fail("params: a cancel entry takes exactly one parameter, of type constraint")
    return Entry(id=raw.id, label=raw.label, help=raw.help, effect=CANCEL, params=params, cancels=cancels)


def _add_entry(raw: _EntryTable, where: _Where, params: tuple[Param, ...], cancels: tuple[Cancels, ...]) -> Entry:
    for param in params:
        if param.type == CONSTRAINT:
            where.fail(f"params: {param.name} is of type constraint, which only a cancel entry takes")
    window_param, window_minutes = raw.window_param, raw.window_minutes
    if (window_param is None) == (window_minutes is None):
        where.fail("needs exactly one of window_param (a parameter in minutes) and window_minutes (fixed)")
    if window_param is not None:
        param = next((p for p in params if p.name == window_param), None)
        if param is None or param.type != INT:
            where.fail(f"window_param: {window_param!r} is not an int parameter of this entry")
        if param.min < 1 or param.max > MAX_WINDOW_MINUTES:
            where.fail(
                f"window_param: {window_param} must range within [1, {MAX_WINDOW_MINUTES}] minutes,"
                f" not [{param.min}, {param.max}]"
            )
    elif not 1 <= window_minutes <= MAX_WINDOW_MINUTES:
        where.fail(f"window_minutes: {window_minutes} is outside [1, {MAX_WINDOW_MINUTES}]")
    if raw.asp is None:
        where.fail("asp: required")
    _check_template(raw.asp, params, window_param, where.sub("asp"))
    return Entry(
        id=raw.id,
        label=raw.label,
        help=raw.help,
        effect=ADD,
        params=params,
        asp=raw.asp,
        window_param=window_param,
        window_minutes=window_minutes,
        cancels=cancels,
    )


def _check_template(asp: str, params: tuple[Param, ...], window_param: str | None, where: _Where) -> None:
    template = string.Template(asp)
    if not template.is_valid():
        where.fail("a '$' that is not a ${name} placeholder (write $$ for a literal $)")
    names = set(template.get_identifiers())
    known = {p.name for p in params} | set(WINDOW_NAMES)
    unknown = sorted(names - known)
    if unknown:
        where.fail(f"placeholder(s) {', '.join(unknown)} are neither parameters nor t0/t1")
    unused = sorted(p.name for p in params if p.name not in names and p.name != window_param)
    if unused:
        where.fail(f"parameter(s) {', '.join(unused)} are not used by the template")
    try:
        check_program(template.substitute(sample_values(params)))
    except UnsafeProgram as exc:
        where.fail(str(exc))


def sample_values(params: tuple[Param, ...]) -> dict[str, str]:
    """Placeholder values that stand for any valid ones, to check a template's shape."""
    values = {name: str(i * 60) for i, name in enumerate(WINDOW_NAMES)}
    for param in params:
        values[param.name] = str(param.min) if param.type == INT else f"sample_{param.type}"
    return values


def _check_cancels(entry: Entry, cancels: Cancels, entries: dict[str, Entry], where: _Where) -> None:
    target = entries.get(cancels.kind)
    if target is None:
        where.fail(f"kind: {cancels.kind!r} is not an entry of this library")
    if target.effect != ADD:
        where.fail(f"kind: {cancels.kind!r} is a {target.effect} entry; only added constraints can be cancelled")
    for name in cancels.same:
        mine, theirs = entry.param(name), target.param(name)
        if mine is None or theirs is None:
            where.fail(f"same: {name!r} must be a parameter of both {entry.id} and {target.id}")
        if mine.type != theirs.type:
            where.fail(f"same: {name!r} is a {mine.type} here but a {theirs.type} in {target.id}")


# --------------------------------------------------------------------------- the site's choices


def site_choices(param: Param, site: SiteLike) -> list[str] | None:
    """The values a symbol parameter may take on ``site`` (sorted); ``None`` for other types.

    Ids that are not ASP constants are left out: they could not be written into a constraint.
    """
    if param.type == DOOR:
        ids = [d for d, opening in site.doors.items() if opening.human_operated or not param.human_operated]
    elif param.type == ROOM:
        ids = list(site.rooms)
    elif param.type == OPENING:
        ids = list(site.openings)
    else:
        return None
    return sorted(i for i in ids if is_asp_constant(i))


def library_for_site(site: SiteLike, library: Library | None = None) -> list[LibraryEntry]:
    """The library with the site's choices resolved, as it goes on the wire (``constraints/library``).

    Each entry's ``window`` is ``{param: name}``, ``{minutes: n}`` or None; ``usable`` says every
    symbol parameter has at least one choice on this site; each parameter carries ``min``/``max``
    (int), ``choices`` (door/room/opening: the site's ids) with ``source`` "site", or ``choices``
    None with ``source`` "constraints" (constraint: an id from the live ConstraintSet).
    """
    library = library or load_library()
    out = []
    for entry in library.entries.values():
        params = []
        usable = True
        for param in entry.params:
            what: dict[str, Any]
            if param.type == INT:
                what = {"min": param.min, "max": param.max}
            elif param.type == CONSTRAINT:
                what = {"choices": None, "source": "constraints"}
            else:
                choices = site_choices(param, site) or []
                what = {"choices": choices, "source": "site"}
                usable = usable and bool(choices)
            params.append(LibraryParam(name=param.name, type=param.type, label=param.label, help=param.help, **what))
        if entry.window_param is not None:
            window: LibraryWindow | None = LibraryWindow(param=entry.window_param)
        elif entry.window_minutes is not None:
            window = LibraryWindow(minutes=entry.window_minutes)
        else:
            window = None
        out.append(
            LibraryEntry(
                id=entry.id,
                label=entry.label,
                help=entry.help,
                effect=entry.effect,
                window=window,
                usable=usable,
                params=params,
            )
        )
    return out
