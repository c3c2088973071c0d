"""JSON Schemas of ARROCH's wire records, from their Struct type hints (for MCAP channel schemas)."""

from __future__ import annotations

import types
import typing
from functools import cache
from typing import Any, Literal

import msgspec

from protocol.messages import Message
from protocol.schema import JsonTree

_SCALARS = {bool: "boolean", int: "integer", float: "number", str: "string"}


def _schema_of(hint: Any) -> dict[str, Any]:
    if typing.get_origin(hint) is typing.Annotated:  # the limits are the codec's business
        if any(isinstance(m, JsonTree) for m in hint.__metadata__):
            return {}
        hint = typing.get_args(hint)[0]
    if typing.get_origin(hint) is Literal:
        return {"type": "string", "enum": list(typing.get_args(hint))}
    if hint in _SCALARS:
        return {"type": _SCALARS[hint]}
    if hint is bytes:
        return {"type": "string", "contentEncoding": "base64"}
    if hint is Any:
        return {}
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is list:
        return {"type": "array", "items": _schema_of(args[0])}
    if origin is dict:
        return {"type": "object", "additionalProperties": _schema_of(args[1])}
    if origin in (typing.Union, types.UnionType):
        return {"anyOf": [{"type": "null"} if a is type(None) else _schema_of(a) for a in args]}
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return record_schema(hint)
    return {}


@cache
def record_schema(cls: type) -> dict[str, Any]:
    """``{"type": "object", "title": ..., "properties": {...}}`` for a message or nested record."""
    hints = typing.get_type_hints(cls, include_extras=True)
    props = {name: _schema_of(hints[name]) for name in cls.__struct_fields__}
    schema: dict[str, Any] = {"type": "object", "title": getattr(cls, "TYPE", "") or cls.__name__, "properties": props}
    if issubclass(cls, Message):
        props["v"] = {"type": "integer"}
        props["type"] = {"type": "string", "const": cls.TYPE}
    return schema
