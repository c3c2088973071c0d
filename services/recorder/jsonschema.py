"""JSON Schemas of ARROCH's wire records, from their dataclass type hints (for MCAP channel schemas)."""

from __future__ import annotations

import dataclasses
import types
import typing
from functools import cache
from typing import Any

from protocol.messages import Message
from protocol.schema import Json

_SCALARS = {bool: "boolean", int: "integer", float: "number", str: "string"}


def _schema_of(hint: Any) -> dict[str, Any]:
    if hint in _SCALARS:
        return {"type": _SCALARS[hint]}
    if hint is bytes:
        return {"type": "string", "contentEncoding": "base64"}
    if hint is Json or hint is Any:
        return {}
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is list:
        return {"type": "array", "items": _schema_of(args[0])}
    if origin is dict:
        return {"type": "object", "additionalProperties": _schema_of(args[1])}
    if origin in (typing.Union, types.UnionType):
        return {"anyOf": [{"type": "null"} if a is type(None) else _schema_of(a) for a in args]}
    if dataclasses.is_dataclass(hint):
        return record_schema(hint)
    return {}


@cache
def record_schema(cls: type) -> dict[str, Any]:
    """``{"type": "object", "title": ..., "properties": {...}}`` for a message or nested record."""
    hints = typing.get_type_hints(cls, include_extras=False)
    props = {f.name: _schema_of(hints[f.name]) for f in dataclasses.fields(cls)}
    schema: dict[str, Any] = {"type": "object", "title": getattr(cls, "TYPE", "") or cls.__name__, "properties": props}
    if issubclass(cls, Message):
        props["v"] = {"type": "integer"}
        props["type"] = {"type": "string", "const": cls.TYPE}
    return schema
