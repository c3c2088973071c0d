"""msgspec's validation errors, told the ARROCH way: which field, and what is wrong with it.

msgspec says ``Expected `float` <= 10000.0 - at `$.poses[0].x``` and stops at the first problem.
:func:`field_error` turns that into a :class:`ProtocolError` with the field path as the rest of
the project writes it (``poses[0].x``; map entries as ``robots.r1``) and the problem in words
that name the value (``100000.0 is above the maximum 10000.0``). It reads the offending value in
the plain data that was being validated and the field's declared type, so the words can say what
was found and what was allowed. The same formatter serves messages off the wire, site files, the
constraint library and the tablet's messages.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import typing
from functools import cache
from typing import Any, Literal

import msgspec

from .errors import ProtocolError
from .schema import Row, Says

_SUFFIX = re.compile(r"^(?P<what>.*?)(?: - at (?P<key>`key` in )?`(?P<path>\$[^`]*)`)?$", re.S)
_TOKEN = re.compile(r"\.([^.\[]+)|\[(\d+|\.\.\.)\]")
_MISSING = re.compile(r"^Object missing required field `(?P<name>[^`]+)`$")
_TYPE = re.compile(r"^Expected `(?P<want>[^`]+)`, got `(?P<got>[^`]+)`$")
_BOUND = re.compile(r"^Expected `(?P<kind>int|float)` (?P<op>>=|<=|>|<) (?P<bound>\S+)$")
_LENGTH = re.compile(r"^Expected `(?P<kind>str|bytes|array|object)` of length (?P<op>>=|<=) (?P<n>\d+)$")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<name>[^`]+)`$")
_WIRE_NAMES = {"array": "list", "object": "map", "None": "NoneType", "null": "NoneType"}
_NOTHING = object()


class Words:
    """How problems are worded: for messages off the wire, in the terms of the wire (``expected
    float, got str``). :class:`FileWords` words them for people editing a TOML file."""

    def value(self, value: Any) -> str:
        return type(value).__name__

    def type_mismatch(self, want: list[str], value: Any, hint: Any, name: str) -> str:
        return f"expected {' or '.join(_WIRE_NAMES.get(w, w) for w in want)}, got {self.value(value)}"

    def bound(self, kind: str, op: str, bound: str, value: Any) -> str:
        if isinstance(value, float) and not math.isfinite(value):
            return f"must be finite, got {value}"
        shown = float(value) if kind == "float" else value
        side = "below the minimum" if op in (">=", ">") else "above the maximum"
        return f"{shown} is {side} {bound}"

    def length(self, kind: str, op: str, n: str, value: Any, name: str) -> str:
        size = len(value)
        if op == ">=":  # only fixed lengths have a minimum
            return f"expected {n} items, got {size}"
        return {
            "str": f"string of {size} characters exceeds the limit {n}",
            "bytes": f"{size} bytes exceeds the limit {n}",
            "array": f"list of {size} items exceeds the limit {n}",
            "object": f"map of {size} entries exceeds the limit {n}",
        }[kind]

    def choice(self, value: Any, choices: tuple[Any, ...]) -> str:
        return f"{value!r} is not one of {', '.join(map(str, choices))}"

    def missing(self, parent: str, name: str, hint: Any) -> tuple[str, str]:
        return _join(parent, name), "required field is missing"

    def unknown(self, parent: str, name: str, allowed: tuple[str, ...]) -> tuple[str, str]:
        return _join(parent, name), "unknown field"


class FileWords(Words):
    """Problems worded for a TOML file: values as they are written there, tables and keys.
    ``tables_at_top``: the top level holds tables (a site file), not keys (a config's one table)."""

    def __init__(self, *, tables_at_top: bool = True) -> None:
        self.tables_at_top = tables_at_top

    _WANT = {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false", "object": "a table"}

    def value(self, value: Any) -> str:
        if isinstance(value, dict):
            return "a table"
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, str):
            return json.dumps(value) if len(value) < 60 else "a long string"
        if isinstance(value, list):
            text = "[" + ", ".join(self.value(x) for x in value) + "]"
            return f"an array {text}" if len(text) < 60 else "an array"
        return repr(value)

    def type_mismatch(self, want: list[str], value: Any, hint: Any, name: str) -> str:
        if want == ["array"] and _records_listed(hint):
            return f"expected an array of tables [[{name}]], got {self.value(value)}"
        return f"expected {' or '.join(self._WANT.get(w, 'an ' + w) for w in want)}, got {self.value(value)}"

    def bound(self, kind: str, op: str, bound: str, value: Any) -> str:
        if isinstance(value, float) and not math.isfinite(value):
            return f"must be a finite number, got {value!r}"
        limit = float(bound)
        if op == ">":
            return f"must be greater than {limit:g}, got {value:g}"
        if op == ">=":
            return f"must not be negative, got {value:g}" if limit == 0 else f"must be at least {bound}, got {value}"
        return f"must be at most {bound}, got {value}"

    def length(self, kind: str, op: str, n: str, value: Any, name: str) -> str:
        if kind == "array" and op == ">=" and n == "1":
            return f"at least one [[{name}]] entry is required"
        return super().length(kind, op, n, value, name)

    def choice(self, value: Any, choices: tuple[Any, ...]) -> str:
        return f"{self.value(value)} is not one of {', '.join(map(str, choices))}"

    def missing(self, parent: str, name: str, hint: Any) -> tuple[str, str]:
        if parent or not self.tables_at_top:
            return parent, f"missing required key {name!r}"
        if _records_listed(hint):
            return name, f"missing required [[{name}]] entries"
        return name, f"missing required table [{name}]"

    def unknown(self, parent: str, name: str, allowed: tuple[str, ...]) -> tuple[str, str]:
        what = "key" if parent or not self.tables_at_top else "table"
        return (parent or name), f"unknown {what} {name!r} (expected {', '.join(allowed)})"


WIRE = Words()
FILE = FileWords()
CONFIG = FileWords(tables_at_top=False)


@cache
def fields_struct(cls: type) -> type[msgspec.Struct]:
    """A Struct with the fields of dataclass ``cls`` (their annotated types and defaults) and no
    other: what :func:`check_fields` converts with, so a dataclass states its limits once."""
    hints = typing.get_type_hints(cls, include_extras=True)
    fields = []
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default: Any = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = msgspec.field(default_factory=f.default_factory)
        else:
            default = msgspec.NODEFAULT
        fields.append((f.name, hints[f.name], default))
    return msgspec.defstruct(f"{cls.__name__}Fields", fields, kw_only=True, forbid_unknown_fields=True)


def check_fields(cls: type, data: Any, words: Words = CONFIG) -> dict[str, Any]:
    """``data`` (a mapping, e.g. a TOML table) checked against the annotated fields of dataclass
    ``cls``: the given keys' values, converted (an int where a float is asked becomes a float).
    Unknown keys, wrong types and values out of their limits raise :class:`ProtocolError`."""
    struct = fields_struct(cls)
    try:
        checked = msgspec.convert(data, struct)
    except msgspec.ValidationError as exc:
        raise field_error(exc, struct, data, words=words) from None
    return {name: getattr(checked, name) for name in data}


def field_error(
    exc: msgspec.ValidationError, root: Any, data: Any, prefix: str = "", words: Words = WIRE
) -> ProtocolError:
    """The :class:`ProtocolError` for msgspec's ``exc``, raised validating ``data`` as ``root``.

    ``prefix`` goes before the field path (e.g. a table's name in a file); ``words`` says how the
    problem is worded (:data:`WIRE` or :data:`FILE`)."""
    text = str(exc)
    match = _SUFFIX.match(text)
    what, path = (match["what"], match["path"] or "$") if match else (text, "$")
    steps = _resolve(root, data, _TOKEN.findall(path[1:]))
    field = _join(prefix, _format(steps))
    value, hint = (steps[-1][1], steps[-1][2]) if steps else (data, root)
    cause = exc.__cause__
    if isinstance(cause, ProtocolError):  # raised by a record's own check, already in words
        return ProtocolError(_join(field, cause.field), cause.problem)
    if match and match["key"]:
        return _key_error(what, field, value)
    if (missing := _MISSING.match(what)) is not None:
        return ProtocolError(*words.missing(field, missing["name"], _field_type(hint, missing["name"])))
    if (unknown := _UNKNOWN.match(what)) is not None:
        allowed = tuple(_strip(hint).__struct_fields__) if _is_record(hint) else ()
        return ProtocolError(*words.unknown(field, unknown["name"], allowed))
    says = next((m for m in getattr(hint, "__metadata__", ()) if isinstance(m, Says)), None)
    if says is not None and value is not _NOTHING:
        return ProtocolError(field, says.words(value))
    if len(steps) >= 2 and _has_mark(steps[-2][2], Row) and _TYPE.match(what):
        # A wrong element in a row of numbers: the row is what is wrong.
        return ProtocolError(_format(steps[:-1], prefix), f"expected numbers, got {_name(value)}")
    if _has_mark(hint, Row) and (_LENGTH.match(what) or _TYPE.match(what)):
        width = _fixed_length(hint)
        found = f"{len(value)} values" if isinstance(value, list) else _name(value)
        return ProtocolError(field, f"expected a row of {width} numbers, got {found}")
    name = steps[-1][0].lstrip(".") if steps else ""
    return ProtocolError(field, _problem(what, value, hint, name, words))


def _problem(what: str, value: Any, hint: Any, name: str, words: Words) -> str:
    if (m := _TYPE.match(what)) is not None:
        if value is _NOTHING:
            return f"expected {m['want']}, got {m['got']}"
        want = m["want"].split(" | ")
        # "or null" says a key may be left out, which is not what is wrong with the value given.
        return words.type_mismatch([w for w in want if w not in ("null", "None")] or want, value, hint, name)
    if (m := _BOUND.match(what)) is not None and value is not _NOTHING:
        return words.bound(m["kind"], m["op"], m["bound"], value)
    if (m := _LENGTH.match(what)) is not None and value is not _NOTHING:
        return words.length(m["kind"], m["op"], m["n"], value, name)
    if what.startswith("Expected `str` matching regex") and isinstance(value, str):
        if "A-Za-z" in what:
            return f"{value[:40]!r} is not an identifier (letter first, then letters, digits, _ or -; 64 at most)"
        return f"{value[:40]!r} does not have the expected form"
    if what.startswith("Invalid enum value"):
        choices = _choices(hint)
        if choices:
            return words.choice(value, choices)
    return what[:1].lower() + what[1:]


def _key_error(what: str, field: str, mapping: Any) -> ProtocolError:
    """A problem with a key of the map at ``field``."""
    keys = list(mapping) if isinstance(mapping, dict) else []
    bad = next((k for k in keys if not isinstance(k, str)), None)
    if bad is not None:
        return ProtocolError(field, f"map key {bad!r} is not a string")
    if (m := _LENGTH.match(what)) is not None:
        if m["op"] == ">=":
            return ProtocolError(
                field, "map key must not be empty" if m["n"] == "1" else f"map key under {m['n']} characters"
            )
        return ProtocolError(field, f"map key longer than {m['n']} characters")
    return ProtocolError(field, f"map key: {what[:1].lower() + what[1:]}")


# ---------------------------------------------------------------------------- walking the path


def _resolve(root: Any, data: Any, tokens: list[tuple[str, str]]) -> list[tuple[str, Any, Any]]:
    """``(step, value, declared type)`` along msgspec's path; ``step`` is ``.name`` or ``[i]``.

    msgspec writes a map entry as ``[...]``: the entry is found again as the first whose value
    does not validate against the map's value type."""
    steps: list[tuple[str, Any, Any]] = []
    value, hint = data, root
    for name, index in tokens:
        if name:
            hint = _field_type(hint, name)
            value = value.get(name, _NOTHING) if isinstance(value, dict) else _NOTHING
            steps.append((f".{name}", value, hint))
        elif index == "...":
            item = _args(hint)[1] if len(_args(hint)) == 2 else Any
            key = _failing_key(value, item)
            value = value.get(key, _NOTHING) if isinstance(value, dict) else _NOTHING
            steps.append((f".{key}" if key is not None else "[...]", value, item))
            hint = item
        else:
            i = int(index)
            hint = _args(hint)[0] if _args(hint) else Any
            value = value[i] if isinstance(value, list) and i < len(value) else _NOTHING
            steps.append((f"[{i}]", value, hint))
    return steps


def _failing_key(mapping: Any, item: Any) -> Any:
    if not isinstance(mapping, dict):
        return None
    for key, value in mapping.items():
        try:
            msgspec.convert(value, item)
        except (msgspec.ValidationError, TypeError):
            return key
    return None


def _format(steps: list[tuple[str, Any, Any]], prefix: str = "") -> str:
    return _join(prefix, "".join(step for step, _, _ in steps).lstrip("."))


def _join(prefix: str, field: str) -> str:
    if not prefix:
        return field
    if not field:
        return prefix
    return f"{prefix}{field}" if field.startswith("[") else f"{prefix}.{field}"


# ---------------------------------------------------------------------------- declared types


def _strip(hint: Any) -> Any:
    """The type without ``Annotated`` and ``| None``."""
    while True:
        if typing.get_origin(hint) is typing.Annotated:
            hint = typing.get_args(hint)[0]
            continue
        args = typing.get_args(hint)
        if type(None) in args and len(args) == 2:
            hint = next(a for a in args if a is not type(None))
            continue
        return hint


def _args(hint: Any) -> tuple[Any, ...]:
    return typing.get_args(_strip(hint))


def _field_type(hint: Any, name: str) -> Any:
    cls = _strip(hint)
    if isinstance(cls, type) and issubclass(cls, msgspec.Struct):
        return typing.get_type_hints(cls, include_extras=True).get(name, Any)
    return Any


def _is_record(hint: Any) -> bool:
    cls = _strip(hint)
    return isinstance(cls, type) and issubclass(cls, msgspec.Struct)


def _records_listed(hint: Any) -> bool:
    """True for a list of records (an array of tables, in a file)."""
    base = _strip(hint)
    return typing.get_origin(base) is list and _is_record(typing.get_args(base)[0])


def _has_mark(hint: Any, mark: type) -> bool:
    return any(isinstance(m, mark) for m in getattr(hint, "__metadata__", ()))


def _fixed_length(hint: Any) -> int | None:
    for meta in getattr(hint, "__metadata__", ()):
        if isinstance(meta, msgspec.Meta) and meta.min_length is not None and meta.min_length == meta.max_length:
            return meta.min_length
    return None


def _choices(hint: Any) -> tuple[Any, ...]:
    base = _strip(hint)
    return typing.get_args(base) if typing.get_origin(base) is Literal else ()


def _name(value: Any) -> str:
    return type(value).__name__
