"""Writing site documents as TOML text (the subset site files use: tables, arrays of tables, scalars, flat arrays)."""

from __future__ import annotations

import json
import math
from typing import Any


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write non-finite number {v!r} to a site file")
        text = repr(v)
        return text if any(ch in text for ch in ".en") else text + ".0"
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to a site file")


def _table(values: dict[str, Any]) -> list[str]:
    return [f"{key} = {_value(v)}" for key, v in values.items() if v is not None]


def dump_site(doc: dict[str, Any], header: str = "") -> str:
    """TOML text for ``doc``: dict values become ``[table]``, lists of dicts ``[[array]]`` entries."""
    lines: list[str] = [f"# {line}" if line else "#" for line in header.splitlines()]
    for key, value in doc.items():
        if isinstance(value, dict):
            lines += ["", f"[{key}]", *_table(value)]
        elif isinstance(value, list):
            for entry in value:
                lines += ["", f"[[{key}]]", *_table(entry)]
        else:
            raise TypeError(f"top-level {key!r} must be a table or an array of tables")
    return "\n".join(lines).lstrip("\n") + "\n"
