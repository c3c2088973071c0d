"""Field types with their limits, for wire records (msgspec Structs).

A wire record is a ``msgspec.Struct``; each field's type carries its limits as ``msgspec.Meta``
constraints, which msgspec checks while it decodes. The helpers here spell the limits the
messages use (``Float(lo, hi)``, ``Ident``, ``Rows(4, ...)``), so a declaration reads like its
contract. Two limits msgspec cannot express are kept as markers in the ``Annotated`` type and
checked after decoding by :func:`extra_checks`: a list allowed several exact lengths
(:class:`Lengths`, e.g. an empty or a 3-element position) and a JSON-like tree (:data:`Json`).

:func:`record_to_wire` and :func:`record_from_wire` turn records into plain data and back (JSON
files, logs); every problem raises :class:`ProtocolError` naming the field.
"""

from __future__ import annotations

import math
import re
import sys
import typing
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Annotated, Any, Literal

import msgspec
import numpy as np
from msgspec import Meta

from .errors import ProtocolError

# Default limits: generous for real use, small enough that one message cannot exhaust memory.
MAX_STR = 4096
MAX_LIST = 100_000
MAX_MAP = 4096
MAX_BYTES = 8 * 1024 * 1024
MAX_KEY = 256
MAX_JSON_DEPTH = 6
_FLOAT_MAX = sys.float_info.max  # a float bounded by ±this is finite: NaN and the infinities fail

# An identifier: a letter, then letters, digits, "_" or "-", 64 characters at most ("" allowed).
ID_FIRST, ID_REST, MAX_ID = "[A-Za-z]", r"[A-Za-z0-9_\-]", 64
ID_PATTERN = re.compile(f"^{ID_FIRST}{ID_REST}{{0,{MAX_ID - 1}}}$")
ID_REGEX = rf"^(?:{ID_FIRST}{ID_REST}{{0,{MAX_ID - 1}}})?\Z"


@dataclass(frozen=True)
class Lengths:
    """Marker: the list must have one of these lengths (``Lengths(0, 3)``: empty or three)."""

    allowed: tuple[int, ...]

    def __init__(self, *allowed: int) -> None:
        object.__setattr__(self, "allowed", allowed)


class Row:
    """Marker: a fixed-length row of numbers inside a list (trajectories, points). A wrong element
    type is reported on the row, as a row of numbers is what is expected there."""


class JsonTree:
    """Marker: a JSON-like tree (maps with string keys, lists, finite numbers, strings, ``None``)."""


@dataclass(frozen=True)
class Says:
    """Marker: how to word any refusal of this value itself (``words(value) -> problem``), where the
    generic words would be vaguer (``"tag id 600 is not in family 36h11"``)."""

    words: Callable[[Any], str]


# ---------------------------------------------------------------------------- field types


def Float(lo: float = -_FLOAT_MAX, hi: float = _FLOAT_MAX) -> Any:  # noqa: N802 - reads as a type
    """A finite float in [lo, hi] (ints are accepted and become floats)."""
    return Annotated[float, Meta(ge=lo, le=hi)]


def Int(lo: int | None = None, hi: int | None = None) -> Any:  # noqa: N802
    """An int in [lo, hi] (bools are refused)."""
    return Annotated[int, Meta(ge=lo, le=hi)]


def Str(max_len: int = MAX_STR) -> Any:  # noqa: N802
    """A string of at most ``max_len`` characters."""
    return Annotated[str, Meta(max_length=max_len)]


Ident = Annotated[str, Meta(max_length=MAX_STR, pattern=ID_REGEX)]
"""An identifier (see :data:`ID_PATTERN`) or ``""``; ids become Zenoh key chunks."""


def Choice(*choices: str) -> Any:  # noqa: N802
    """One of the given strings."""
    return Literal[choices]  # type: ignore[valid-type]


def List(item: Any, max_len: int = MAX_LIST, lengths: tuple[int, ...] | None = None) -> Any:  # noqa: N802
    """A list of at most ``max_len`` items; with ``lengths``, of exactly one of those lengths."""
    if lengths is None:
        return Annotated[list[item], Meta(max_length=max_len)]
    if len(lengths) == 1:
        return Annotated[list[item], Meta(min_length=lengths[0], max_length=lengths[0])]
    return Annotated[list[item], Meta(max_length=max_len), Lengths(*lengths)]


def Rows(width: int, max_len: int, lo: float, hi: float) -> Any:  # noqa: N802
    """A list of rows of exactly ``width`` floats in [lo, hi]."""
    row = Annotated[list[Float(lo, hi)], Meta(min_length=width, max_length=width), Row()]
    return Annotated[list[row], Meta(max_length=max_len)]


Key = Annotated[str, Meta(max_length=MAX_KEY)]


def Map(value: Any, max_len: int = MAX_MAP) -> Any:  # noqa: N802
    """A map with string keys (at most 256 characters) and at most ``max_len`` entries."""
    return Annotated[dict[Key, value], Meta(max_length=max_len)]


Bytes = Annotated[bytes, Meta(max_length=MAX_BYTES)]
Scalar = bool | int | Float() | Str()
"""A parameter value: a bool, an int, a finite float or a string."""
Json = Annotated[Any, JsonTree()]


# ---------------------------------------------------------------------------- checks msgspec cannot do


def check_json(value: Any, path: str, depth: int = 0) -> None:
    """Raise :class:`ProtocolError` unless ``value`` is a bounded JSON-like tree."""
    if depth > MAX_JSON_DEPTH:
        raise ProtocolError(path, f"nested deeper than {MAX_JSON_DEPTH} levels")
    if value is None or isinstance(value, (bool, int)):
        return
    if isinstance(value, str):
        if len(value) > MAX_STR:
            raise ProtocolError(path, f"string exceeds the limit {MAX_STR}")
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise ProtocolError(path, f"must be finite, got {value}")
    elif isinstance(value, list):
        if len(value) > MAX_LIST:
            raise ProtocolError(path, f"list exceeds the limit {MAX_LIST}")
        for i, item in enumerate(value):
            check_json(item, f"{path}[{i}]", depth + 1)
    elif isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise ProtocolError(path, f"map key {key!r} is not a string")
            check_json(item, f"{path}.{key}", depth + 1)
    else:
        raise ProtocolError(path, f"unsupported value of type {type(value).__name__}")


def _lengths_check(allowed: tuple[int, ...]) -> Callable[[Any, str], None]:
    def check(value: list, path: str) -> None:
        if len(value) not in allowed:
            raise ProtocolError(path, f"expected {' or '.join(map(str, allowed))} items, got {len(value)}")

    return check


@cache
def extra_checks(cls: type) -> tuple[tuple[str, Callable[[Any, str], None]], ...]:
    """``(field, check)`` for the fields of ``cls`` whose limits msgspec does not check itself
    (:class:`Lengths`, :data:`Json`). Only top-level fields may have them: a nested record with
    one is refused when its message is first used."""
    out = []
    for name, hint in typing.get_type_hints(cls, include_extras=True).items():
        for mark in getattr(hint, "__metadata__", ()):
            if isinstance(mark, Lengths):
                out.append((name, _lengths_check(mark.allowed)))
            elif isinstance(mark, JsonTree):
                out.append((name, check_json))
        for nested in _records_in(hint):
            if extra_checks(nested):
                raise TypeError(f"{cls.__name__}.{name}: nested records cannot have Lengths or Json fields")
    return tuple(out)


def _records_in(hint: Any) -> list[type]:
    """The Struct classes a type hint contains."""
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return [hint]
    return [r for arg in typing.get_args(hint) for r in _records_in(arg)]


def run_extra_checks(record: Any) -> None:
    for name, check in extra_checks(type(record)):
        check(getattr(record, name), name)


# ---------------------------------------------------------------------------- records as plain data


def plain_value(value: Any) -> Any:
    """A value msgspec does not encode itself, as one it does: numpy numbers and arrays (poses and
    camera parameters are often computed with numpy) become Python numbers and lists. msgspec asks
    only for such values, so messages of plain Python values pay nothing for it."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot put a {type(value).__name__} on the wire")


def record_to_wire(record: msgspec.Struct) -> dict[str, Any]:
    """The record as plain data (maps, lists, scalars; bytes kept as bytes), as it goes on the wire."""
    return msgspec.to_builtins(record, builtin_types=(bytes,), enc_hook=plain_value)


def record_from_wire(cls: type, data: Any) -> Any:
    """Check plain data (e.g. from JSON) against ``cls`` and build the record; unknown keys are
    ignored. Raises :class:`ProtocolError` naming the field."""
    from .validation import field_error  # late: validation reads this module's markers

    try:
        record = msgspec.convert(data, cls)
    except msgspec.ValidationError as exc:
        raise field_error(exc, cls, data) from None
    run_extra_checks(record)
    return record
