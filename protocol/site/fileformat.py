"""The site file format: which tables and keys exist, their types and ranges.

This module knows the file format (which tables, which keys, which types and ranges); what the
values mean together (rooms that overlap, doors off a shared wall, ...) is checked by
:mod:`protocol.site.build`. Either way the refusal is a :class:`SiteError` naming the file and
the entry, e.g. ``bad.toml: rooms[2] (id "lab"): rect: xmax 3.0 must be greater than xmin 5.0``.
Array entries are numbered from 0 in file order.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .errors import SiteError
from .model import TAG36H11_CODES, Params

ID_RE = re.compile(r"^[a-z][a-z0-9_]*$")
ID_MAX = 64  # ids also become Zenoh key chunks (protocol.schema allows 64 characters)
ASP_KEYWORDS = frozenset({"not"})  # a bare word clingo would not read as a constant
SITE_NAME_RE = re.compile(r"^[A-Za-z0-9_\-]+$")  # the default key namespace (protocol.keys)


class Bad(Exception):
    """A value is wrong; the caller adds the file and entry to make a SiteError.

    ``path`` locates the problem inside the value (``"[2]"`` for an array item).
    """

    def __init__(self, problem: str, path: str = "") -> None:
        super().__init__(problem)
        self.problem = problem
        self.path = path


# --- value checkers: take the raw TOML value, return the converted value or raise Bad -------------


def _describe(v: Any) -> str:
    """A value as it looks in TOML, shortened."""
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v) if len(v) < 60 else "a long string"
    if isinstance(v, list):
        text = "[" + ", ".join(_describe(x) for x in v) + "]"
        return f"an array {text}" if len(text) < 60 else "an array"
    return repr(v)


def number(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise Bad(f"expected a number, got {_describe(v)}")
    if not math.isfinite(v):
        raise Bad(f"must be a finite number, got {v!r}")
    return float(v)


def positive(v: Any) -> float:
    x = number(v)
    if x <= 0:
        raise Bad(f"must be greater than 0, got {x:g}")
    return x


def non_negative(v: Any) -> float:
    x = number(v)
    if x < 0:
        raise Bad(f"must not be negative, got {x:g}")
    return x


def integer(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise Bad(f"expected an integer, got {_describe(v)}")
    return v


def positive_int(v: Any) -> int:
    x = integer(v)
    if x < 1:
        raise Bad(f"must be at least 1, got {x}")
    return x


def tag_id(v: Any) -> int:
    x = integer(v)
    if not 0 <= x < TAG36H11_CODES:
        raise Bad(f"tag id {x} is not in family 36h11 (0..{TAG36H11_CODES - 1})")
    return x


def boolean(v: Any) -> bool:
    if not isinstance(v, bool):
        raise Bad(f"expected true or false, got {_describe(v)}")
    return v


def string(v: Any) -> str:
    if not isinstance(v, str):
        raise Bad(f"expected a string, got {_describe(v)}")
    return v


def ident(v: Any) -> str:
    """An id the planner can write into ASP as a constant (and use in a key expression)."""
    s = string(v)
    if not ID_RE.match(s) or s in ASP_KEYWORDS or len(s) > ID_MAX:
        raise Bad(
            f"{_describe(s)} is not a valid lower-case ASP constant (^[a-z][a-z0-9_]*$, at most {ID_MAX} characters, "
            "not 'not')"
        )
    return s


def site_name(v: Any) -> str:
    s = string(v)
    if not SITE_NAME_RE.match(s):
        raise Bad(f"{_describe(s)} cannot be a key namespace (letters, digits, _ and - only)")
    return s


def vector(n: int, names: str) -> Callable[[Any], tuple[float, ...]]:
    def check(v: Any) -> tuple[float, ...]:
        if not isinstance(v, list) or len(v) != n:
            raise Bad(f"expected an array of {n} numbers [{names}], got {_describe(v)}")
        out = []
        for i, item in enumerate(v):
            try:
                out.append(number(item))
            except Bad as exc:
                raise Bad(exc.problem, f"[{i}]") from None
        return tuple(out)

    return check


def rect(v: Any) -> tuple[float, float, float, float]:
    x0, y0, x1, y1 = vector(4, "xmin, ymin, xmax, ymax")(v)
    if x1 <= x0:
        raise Bad(f"xmax {x1:g} must be greater than xmin {x0:g} (zero or negative width)")
    if y1 <= y0:
        raise Bad(f"ymax {y1:g} must be greater than ymin {y0:g} (zero or negative depth)")
    return (x0, y0, x1, y1)


def room_pair(v: Any) -> tuple[str, str]:
    if not isinstance(v, list) or len(v) != 2:
        raise Bad(f"expected an array of 2 room ids, got {_describe(v)}")
    a, b = (ident(x) for x in v)
    if a == b:
        raise Bad(f"joins room {a!r} to itself")
    return (a, b)


# --- the format: tables, their keys, which are required --------------------------------------------

REQUIRED = True
OPTIONAL = False
Schema = dict[str, tuple[Callable[[Any], Any], bool]]

PARAMS: Schema = {
    "robot_speed": (positive, OPTIONAL),
    "robot_radius": (positive, OPTIONAL),
    "load_time": (non_negative, OPTIONAL),
    "door_hold_time": (non_negative, OPTIONAL),
    "robot_capacity": (positive_int, OPTIONAL),
    "wall_height": (positive, OPTIONAL),
    "wall_thickness": (positive, OPTIONAL),
}

TABLES: dict[str, Schema] = {
    "site": {"name": (site_name, REQUIRED)},
    "params": PARAMS,
    "human": {"room": (ident, REQUIRED), "position": (vector(2, "x, y"), REQUIRED)},
}

ARRAYS: dict[str, Schema] = {
    "rooms": {"id": (ident, REQUIRED), "rect": (rect, REQUIRED)},
    "doors": {
        "id": (ident, REQUIRED),
        "rooms": (room_pair, REQUIRED),
        "center": (vector(2, "x, y"), REQUIRED),
        "width": (positive, REQUIRED),
        "human_operated": (boolean, OPTIONAL),
        "swing_into": (ident, OPTIONAL),
    },
    "passages": {
        "id": (ident, OPTIONAL),
        "rooms": (room_pair, REQUIRED),
        "center": (vector(2, "x, y"), REQUIRED),
        "width": (positive, REQUIRED),
    },
    "landmarks": {
        "tag": (tag_id, REQUIRED),
        "size": (positive, REQUIRED),
        "position": (vector(3, "x, y, z"), REQUIRED),
        "yaw": (number, REQUIRED),
    },
    "robots": {"id": (ident, REQUIRED), "start": (vector(3, "x, y, theta"), REQUIRED)},
    "objects": {
        "id": (ident, REQUIRED),
        "position": (vector(2, "x, y"), REQUIRED),
        "deliver_to": (ident, REQUIRED),
        "robot": (ident, REQUIRED),
    },
}

REQUIRED_TOP = ("site", "rooms", "robots", "human")
TOP_ORDER = ("site", "params", "rooms", "doors", "passages", "landmarks", "robots", "objects", "human")


@dataclass
class Entry:
    """One checked table: ``label`` names it in messages, ``values`` holds converted values (None if absent)."""

    label: str
    values: dict[str, Any]

    def __getitem__(self, key: str) -> Any:
        return self.values[key]


def entry_label(array: str, index: int, raw: Any) -> str:
    """``rooms[2] (id "lab")``, ``landmarks[0] (tag 7)``: the index, plus the id when it is readable."""
    label = f"{array}[{index}]"
    if not isinstance(raw, dict):
        return label
    if isinstance(raw.get("id"), str):
        label += f' (id "{raw["id"]}")'
    elif array == "landmarks" and isinstance(raw.get("tag"), int) and not isinstance(raw.get("tag"), bool):
        label += f" (tag {raw['tag']})"
    return label


def check_table(file: str, label: str, raw: Any, schema: Schema) -> Entry:
    if not isinstance(raw, dict):
        raise SiteError(file, label, f"expected a table, got {_describe(raw)}")
    for key in raw:
        if key not in schema:
            raise SiteError(file, label, f"unknown key {key!r} (expected {', '.join(schema)})")
    values: dict[str, Any] = {}
    for key, (check, required) in schema.items():
        if key not in raw:
            if required:
                raise SiteError(file, label, f"missing required key {key!r}")
            values[key] = None
            continue
        try:
            values[key] = check(raw[key])
        except Bad as exc:
            raise SiteError(file, label, f"{key}{exc.path}: {exc.problem}") from None
    return Entry(label, values)


def check_document(file: str, doc: dict[str, Any]) -> dict[str, Any]:
    """Check every table's shape and types; returns ``{table: Entry}`` and ``{array: [Entry]}``."""
    for key in doc:
        if key not in TOP_ORDER:
            raise SiteError(file, key, f"unknown table {key!r} (expected {', '.join(TOP_ORDER)})")
    out: dict[str, Any] = {}
    for key, schema in TABLES.items():
        out[key] = check_table(file, key, doc[key], schema) if key in doc else None
    for key, schema in ARRAYS.items():
        raw_list = doc.get(key, [])
        if not isinstance(raw_list, list):
            raise SiteError(file, key, f"expected an array of tables [[{key}]], got {_describe(raw_list)}")
        out[key] = [check_table(file, entry_label(key, i, raw), raw, schema) for i, raw in enumerate(raw_list)]
    # What is there is checked first, so a malformed table is reported before a missing one.
    for key in REQUIRED_TOP:
        if key not in doc:
            raise SiteError(
                file, key, f"missing required table [{key}]" if key in TABLES else f"missing required [[{key}]] entries"
            )
    for key in ("rooms", "robots"):
        if not out[key]:
            raise SiteError(file, key, f"at least one [[{key}]] entry is required")
    return out


def params_from(entry: Entry | None) -> Params:
    if entry is None:
        return Params()
    return Params(**{k: v for k, v in entry.values.items() if v is not None})
