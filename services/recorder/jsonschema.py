"""JSON Schemas of ARROCH's messages for MCAP channels: msgspec's own schema of each Struct
(``msgspec.json.schema``, so it follows the type and its limits), narrowed to what Foxglove reads.

Foxglove and Lichtblick read a channel's JSON Schema with ``parseJsonSchema``
(``packages/mcap-support/src/parseJsonSchema.ts`` in Lichtblick, inherited from Foxglove Studio) and
refuse the whole channel when a property is not one they can type: the root and every nested record
must be ``"type": "object"``; a property needs a ``type`` of boolean, string (``contentEncoding``
base64 allowed), number, integer, object or array, an array's items one of these but not an array;
``$ref``, ``anyOf`` and ``null`` are refused. So, from msgspec's schema:

- ``$ref``s are replaced by the definitions they name;
- an optional field (``anyOf`` of a type and ``null``) takes that type;
- an ``enum`` without a type (the message's ``type`` tag, a choice) gets the type of its values;
- a field of no such type (a free JSON tree such as ``Event.data``, a choice of scalars, rows of
  numbers such as a trajectory) is left out of ``properties`` and named in the schema's
  ``description``: its values are still in every message, Foxglove shows them untyped.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import msgspec

_TYPES = {"boolean", "string", "number", "integer", "object", "array"}
_ENUM_TYPES = {bool: "boolean", str: "string", int: "integer", float: "number"}


def _resolve(node: Any, defs: dict[str, Any]) -> Any:
    """``node`` with every ``$ref`` to ``#/$defs/...`` replaced by what it names (the types are not recursive)."""
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            return _resolve(defs[ref.removeprefix("#/$defs/")], defs)
        return {k: _resolve(v, defs) for k, v in node.items() if k != "$defs"}
    if isinstance(node, list):
        return [_resolve(v, defs) for v in node]
    return node


def _typed(schema: dict[str, Any], path: str, untyped: list[str]) -> dict[str, Any] | None:
    """``schema`` in the form Foxglove types, or None (its path noted in ``untyped``)."""
    alternatives = schema.get("anyOf")
    if alternatives is not None:
        concrete = [a for a in alternatives if a.get("type") != "null"]
        if len(concrete) != 1:
            untyped.append(path)
            return None
        return _typed({**{k: v for k, v in schema.items() if k != "anyOf"}, **concrete[0]}, path, untyped)
    out = dict(schema)
    if "type" not in out and "enum" in out:
        kinds = {_ENUM_TYPES.get(type(value)) for value in out["enum"]}
        if len(kinds) == 1 and None not in kinds:
            out["type"] = kinds.pop()
    kind = out.get("type")
    if kind not in _TYPES:
        untyped.append(path)
        return None
    if kind == "object":
        props = {}
        for name, sub in out.get("properties", {}).items():
            typed = _typed(sub, f"{path}.{name}" if path else name, untyped)
            if typed is not None:
                props[name] = typed
        if "properties" in out:
            out["properties"] = props
            out["required"] = [name for name in out.get("required", []) if name in props]
    elif kind == "array":
        items = out.get("items", {})
        typed = _typed(items, f"{path}[]", untyped) if items.get("type") != "array" else None
        if typed is None:
            if items.get("type") == "array":
                untyped.append(path)
            return None
        out["items"] = typed
    return out


@cache
def record_schema(cls: type[msgspec.Struct]) -> dict[str, Any]:
    """The JSON Schema of a message (or record) type, as Foxglove reads it (see the module's docstring)."""
    full = msgspec.json.schema(cls)
    root = _resolve(full, full.get("$defs", {}))
    untyped: list[str] = []
    schema = _typed(root, "", untyped)
    if schema is None:  # every Struct is an object
        raise TypeError(f"{cls.__name__}: not a record type")
    if untyped:
        note = f"Untyped here (in every message, shown as they are): {', '.join(untyped)}."
        schema["description"] = f"{schema.get('description', '').strip()}\n\n{note}".strip()
    return schema
