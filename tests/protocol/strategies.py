"""Hypothesis strategies and sample values derived from the wire records' own declarations.

Everything here reads the Struct fields, their type hints and the limits their types declare
(:mod:`protocol.schema`), so a message added to ``protocol/messages.py`` is covered without touching the tests.

- :func:`strategy_for` draws valid records (within every limit);
- :func:`minimal_wire` gives one small valid wire map per class (the base of malformed-payload tests);
- :func:`wrong_type_value`, :func:`oversized_value` give values a field must refuse.
"""

from __future__ import annotations

import functools
import operator
import types
import typing
from dataclasses import dataclass
from typing import Any, Literal

import msgpack
import msgspec
from hypothesis import strategies as st

from protocol.codec import decode
from protocol.events import EVENT_DATA
from protocol.messages import Event, Message
from protocol.schema import (
    ID_PATTERN,
    ID_REGEX,
    MAX_BYTES,
    MAX_JSON_DEPTH,
    MAX_LIST,
    MAX_MAP,
    MAX_STR,
    JsonTree,
    Lengths,
    Row,
)


class Json:
    """Stands for a JSON-like tree field (``protocol.schema.Json``) in the plain hints below."""


class KindData:
    """Stands for an Event's ``data``, whose type its ``kind`` chooses (:data:`protocol.events.EVENT_DATA`)."""


@dataclass(frozen=True)
class Field:
    """A wire field in the terms the strategies use: its name, plain type hint and limits."""

    name: str
    required: bool
    metadata: dict[str, Any]


INT_MIN, INT_MAX = -(2**63), 2**64 - 1  # what msgpack can carry
# Keep drawn collections small: limits are exercised by the dedicated oversize tests.
DRAW_LIST, DRAW_STR, DRAW_BYTES, DRAW_MAP = 4, 24, 32, 3


def describe(hint: Any) -> tuple[Any, dict[str, Any]]:
    """A declared field type as a plain hint (``list[float]``, ``str``, a record, :class:`Json`)
    and its limits: ``lo``, ``hi``, ``max_len``, ``choices``, ``ident``, ``row_len``, ``lengths``."""
    meta: dict[str, Any] = {}
    marks: tuple[Any, ...] = ()
    if typing.get_origin(hint) is typing.Annotated:
        hint, *rest = typing.get_args(hint)
        marks = tuple(rest)
    for mark in marks:
        if isinstance(mark, msgspec.Meta):
            meta["lo"], meta["hi"] = mark.ge, mark.le
            if mark.max_length is not None:
                meta["max_len"] = mark.max_length
            if mark.min_length is not None and mark.min_length == mark.max_length:
                meta["lengths"] = (mark.min_length,)
            if mark.pattern == ID_REGEX:
                meta["ident"] = True
        elif isinstance(mark, Lengths):
            meta["lengths"] = mark.allowed
        elif isinstance(mark, JsonTree):
            return Json, meta
    if typing.get_origin(hint) is Literal:
        return str, meta | {"choices": typing.get_args(hint)}
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is list:
        item, item_meta = describe(args[0])
        if typing.get_origin(args[0]) is typing.Annotated and any(isinstance(m, Row) for m in typing.get_args(args[0])):
            row_list = typing.get_args(args[0])[0]  # list[<the element's annotated type>]
            number, number_meta = describe(typing.get_args(row_list)[0])
            return list[list[number]], meta | {"row_len": item_meta["lengths"][0]} | _item_limits(number_meta)
        return list[item], meta | _item_limits(item_meta)
    if origin is dict:
        value, value_meta = describe(args[1])
        return dict[str, value], meta | _item_limits(value_meta)
    if origin in (types.UnionType, typing.Union):
        described = [describe(a) for a in args]
        present = [m for a, (_, m) in zip(args, described, strict=True) if a not in (type(None), msgspec.UnsetType)]
        if len(present) == 1:  # X | None, X | UnsetType: X's limits hold
            meta |= present[0]
        return functools.reduce(operator.or_, (plain for plain, _ in described)), meta
    return hint, meta


def _item_limits(meta: dict[str, Any]) -> dict[str, Any]:
    return {k: meta[k] for k in ("lo", "hi", "choices", "ident") if meta.get(k) is not None}


def fields_of(cls: type) -> list[tuple[Field, Any]]:
    """(field, plain type hint) of every wire field of a record class, in declaration order
    (the envelope's ``v`` aside: it is the codec's, like ``type``)."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for info in msgspec.inspect.type_info(cls).fields:
        if info.name == "v" and issubclass(cls, Message):
            continue
        if cls is Event and info.name == "data":
            out.append((Field(info.name, info.required, {}), KindData))
            continue
        plain, meta = describe(hints[info.name])
        out.append((Field(info.name, info.required, meta), plain))
    return out


def is_required(f: Field) -> bool:
    return f.required


def _optional_inner(hint: Any) -> Any | None:
    """``X`` for ``X | None`` (or ``X | UnsetType``: a field that may be absent), else None."""
    if typing.get_origin(hint) in (types.UnionType, typing.Union):
        args = typing.get_args(hint)
        members = [a for a in args if a not in (type(None), msgspec.UnsetType)]
        if len(members) == 1 and len(members) < len(args):
            return members[0]
    return None


def _json(depth: int) -> st.SearchStrategy:
    base = (
        st.none()
        | st.booleans()
        | st.integers(INT_MIN, INT_MAX)
        | st.floats(allow_nan=False, allow_infinity=False)
        | st.text(max_size=DRAW_STR)
    )
    if depth == 0:
        return base
    inner = _json(depth - 1)
    return base | st.lists(inner, max_size=DRAW_LIST) | st.dictionaries(st.text(max_size=8), inner, max_size=DRAW_MAP)


def value_strategy(hint: Any, meta: typing.Mapping[str, Any]) -> st.SearchStrategy:
    """Valid values for one field of type ``hint`` with the limits ``meta``."""
    lo, hi, max_len = meta.get("lo"), meta.get("hi"), meta.get("max_len")
    inner = _optional_inner(hint)
    if inner is not None:
        return _absent(hint) | value_strategy(inner, meta)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        return st.booleans()
    if hint is int:
        return st.integers(INT_MIN if lo is None else int(lo), INT_MAX if hi is None else int(hi))
    if hint is float:
        return st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False)
    if hint is str:
        if meta.get("choices"):
            return st.sampled_from(meta["choices"])
        if meta.get("ident"):
            return st.just("") | st.from_regex(ID_PATTERN, fullmatch=True).filter(
                lambda s: len(s) <= (max_len or MAX_STR)
            )
        return st.text(max_size=min(max_len or MAX_STR, DRAW_STR))
    if hint is bytes:
        return st.binary(max_size=min(max_len or MAX_BYTES, DRAW_BYTES))
    if hint is Json:
        return _json(min(3, MAX_JSON_DEPTH))
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return strategy_for(hint)
    if origin in (types.UnionType, typing.Union):  # a union of scalars (Scalar), perhaps None or absent
        scalars = [a for a in args if a not in (type(None), msgspec.UnsetType)]
        return _absent(hint) | st.one_of([value_strategy(a, {}) for a in scalars])
    if origin is list:
        item_meta = {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")}
        item = value_strategy(args[0], item_meta)
        row_len = meta.get("row_len")
        if row_len:  # fixed rows of numbers (trajectories, points)
            item = st.lists(value_strategy(typing.get_args(args[0])[0], item_meta), min_size=row_len, max_size=row_len)
        if meta.get("lengths"):
            return st.sampled_from(meta["lengths"]).flatmap(lambda n: st.lists(item, min_size=n, max_size=n))
        return st.lists(item, max_size=min(max_len or MAX_LIST, DRAW_LIST))
    if origin is dict:
        value_meta = {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")}
        return st.dictionaries(
            st.text(max_size=8), value_strategy(args[1], value_meta), max_size=min(max_len or MAX_MAP, DRAW_MAP)
        )
    raise TypeError(f"no strategy for {hint!r}")


def _absent(hint: Any) -> st.SearchStrategy:
    """None and UNSET when the union ``hint`` admits them."""
    args = typing.get_args(hint)
    none = st.none() if type(None) in args else st.nothing()
    return none | (st.just(msgspec.UNSET) if msgspec.UnsetType in args else st.nothing())


def strategy_for(cls: type) -> st.SearchStrategy:
    """Valid instances of a record class: every field drawn within its declared limits (an Event's
    data drawn as the type its kind chooses)."""
    fields = {f.name: value_strategy(hint, f.metadata) for f, hint in fields_of(cls) if hint is not KindData}
    if cls is Event:
        fields.pop("kind")
        return st.sampled_from(sorted(EVENT_DATA)).flatmap(
            lambda kind: st.builds(
                cls, kind=st.just(kind), data=value_strategy(describe(EVENT_DATA[kind])[0], {}), **fields
            )
        )
    return st.builds(cls, **fields)


# ---------------------------------------------------------------------------- sample values


def sample_value(hint: Any, meta: typing.Mapping[str, Any]) -> Any:
    """One small valid value for a field (wire form)."""
    lo, hi = meta.get("lo"), meta.get("hi")
    inner = _optional_inner(hint)
    if inner is not None:
        return sample_value(inner, meta)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        return True
    if hint in (int, float):
        value = 1 if lo is None else max(lo, 1)
        value = value if hi is None else min(value, hi)
        return hint(value)
    if hint is str:
        return meta["choices"][0] if meta.get("choices") else "a1"
    if hint is bytes:
        return b"\x00\x01"
    if hint is Json:
        return {"k": [1, 2.5, "x", None]}
    if hint is KindData:  # the first kind's (as the kind's sample is the first choice)
        return sample_value(describe(EVENT_DATA[next(iter(EVENT_DATA))])[0], {})
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return minimal_wire(hint, envelope=False)
    if origin in (types.UnionType, typing.Union):
        return sample_value(args[0], {})
    if origin is list:
        item_meta = {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")}
        if meta.get("row_len"):
            return [[sample_value(float, item_meta)] * meta["row_len"]]
        return [sample_value(args[0], item_meta)] * max(meta.get("lengths") or (1,))
    if origin is dict:
        return {"k": sample_value(args[1], {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")})}
    raise TypeError(f"no sample for {hint!r}")


def minimal_wire(cls: type, envelope: bool = True) -> dict[str, Any]:
    """A valid wire map of ``cls``: every field present with a small valid value, plus the envelope."""
    data = {f.name: sample_value(hint, f.metadata) for f, hint in fields_of(cls)}
    if envelope and issubclass(cls, Message):
        data.update(v=cls.VERSION, type=cls.TYPE, src="tester-1", seq=7, stamp=12.5)
    return data


def wrong_type_value(hint: Any) -> Any:
    """A value of a type the field must refuse."""
    inner = _optional_inner(hint)
    if inner is not None:
        return wrong_type_value(inner)
    origin = typing.get_origin(hint)
    if hint is str:
        return 12
    if hint in (int, float):
        return "12"
    if hint is bool:
        return 1
    if hint is bytes:
        return "not bytes"
    if hint in (Json, KindData):
        return b"bytes are not JSON"
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return 5
    if origin in (types.UnionType, typing.Union):
        return [1]
    if origin is list:
        return "not a list"
    if origin is dict:
        return ["not", "a", "map"]
    raise TypeError(f"no wrong value for {hint!r}")


def oversized_value(hint: Any, meta: typing.Mapping[str, Any]) -> Any | None:
    """A value one element (or character, or byte) over the field's size limit; None when the
    field has no size limit of its own."""
    inner = _optional_inner(hint)
    if inner is not None:
        return oversized_value(inner, meta)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is str and not meta.get("choices"):
        limit = meta.get("max_len") or MAX_STR
        return "a" * (limit + 1)
    if hint is bytes:
        return b"\x00" * ((meta.get("max_len") or MAX_BYTES) + 1)
    if origin is list:
        limit = meta.get("max_len") or MAX_LIST
        item_meta = {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")}
        item = (
            [sample_value(float, item_meta)] * meta["row_len"]
            if meta.get("row_len")
            else sample_value(args[0], item_meta)
        )
        return [item] * (limit + 1)
    if origin is dict:
        limit = meta.get("max_len") or MAX_MAP
        value = sample_value(args[1], {k: meta.get(k) for k in ("lo", "hi", "choices", "ident")})
        return {f"k{i}": value for i in range(limit + 1)}
    return None


def pack(data: Any) -> bytes:
    return msgpack.packb(data, use_bin_type=True)


def sample_message(cls: type[Message]) -> Message:
    """The minimal valid message of ``cls`` as an object."""
    return decode(pack(minimal_wire(cls)), cls)
