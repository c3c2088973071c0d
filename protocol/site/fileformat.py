"""The site file format: which tables and keys exist, their types and ranges.

The format is declared as msgspec Structs (:class:`SiteFile` and its tables): each key's type
carries its limits, and :mod:`protocol.validation` words a refusal for the file (:data:`FILE`).
This module knows the file format (which tables, which keys, which types and ranges); what the
values mean together (rooms that overlap, doors off a shared wall, ...) is checked by
:mod:`protocol.site.build`. Either way the refusal is a :class:`SiteError` naming the file and
the entry, e.g. ``bad.toml: rooms[2] (id "lab"): rect: xmax 3.0 must be greater than xmin 5.0``.
Array entries are numbered from 0 in file order.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from typing import Annotated, Any

import msgspec
from msgspec import Meta, Struct

from ..errors import ProtocolError
from ..schema import Says
from ..validation import FILE, field_error
from .errors import SiteError
from .model import TAG36H11_CODES, Params

ID_RE = re.compile(r"^[a-z][a-z0-9_]*$")
ID_MAX = 64  # ids also become Zenoh key chunks (protocol.schema allows 64 characters)
ASP_KEYWORDS = frozenset({"not"})  # a bare word clingo would not read as a constant
SITE_NAME_RE = re.compile(r"^[A-Za-z0-9_\-]+$")  # the default key namespace (protocol.keys)
_MAX = sys.float_info.max  # a number bounded by ±this is finite


# --- value types: each carries its limits (msgspec.Meta) and, where generic words would be vague,
# the words of its refusal (Says) --------------------------------------------------------------------

# Not ASP's "not" (ASP_KEYWORDS); written so a JSON Schema tool reads it too (no \Z in ECMA-262).
_ID_REGEX = rf"^(?!not$)[a-z][a-z0-9_]{{0,{ID_MAX - 1}}}$"


def _says_ident(value: Any) -> str:
    shown = FILE.value(value)
    if not isinstance(value, str):
        return f"expected a string, got {shown}"
    return f"{shown} is not a valid lower-case ASP constant (^[a-z][a-z0-9_]*$, at most {ID_MAX} characters, not 'not')"


def _says_site_name(value: Any) -> str:
    if not isinstance(value, str):
        return f"expected a string, got {FILE.value(value)}"
    return f"{FILE.value(value)} cannot be a key namespace (letters, digits, _ and - only)"


def _says_tag(value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, int):
        return f"expected an integer, got {FILE.value(value)}"
    return f"tag id {value} is not in family 36h11 (0..{TAG36H11_CODES - 1})"


def _vector(n: int, names: str) -> Any:
    def says(value: Any) -> str:
        return f"expected an array of {n} numbers [{names}], got {FILE.value(value)}"

    return Annotated[tuple[(Number,) * n], Says(says)]  # type: ignore[misc]


Number = Annotated[float, Meta(ge=-_MAX, le=_MAX)]  # any finite number
Positive = Annotated[float, Meta(gt=0, le=_MAX)]
NonNegative = Annotated[float, Meta(ge=0, le=_MAX)]
PositiveInt = Annotated[int, Meta(ge=1)]
Id = Annotated[str, Meta(pattern=_ID_REGEX), Says(_says_ident)]
SiteName = Annotated[str, Meta(pattern=SITE_NAME_RE.pattern), Says(_says_site_name)]
TagId = Annotated[int, Meta(ge=0, le=TAG36H11_CODES - 1), Says(_says_tag)]
Vec2 = _vector(2, "x, y")
Vec3 = _vector(3, "x, y, z")
Pose = _vector(3, "x, y, theta")
RoomPair = Annotated[
    tuple[Id, Id], Says(lambda v: f"expected an array of 2 room ids, got {FILE.value(v)}")  # noqa: E731
]
Rect = _vector(4, "xmin, ymin, xmax, ymax")


class _Table(Struct, kw_only=True, forbid_unknown_fields=True):
    """A table of the file: every key declared, no other allowed."""


class SiteTable(_Table, kw_only=True):
    name: SiteName


class ParamsTable(_Table, kw_only=True):
    robot_speed: Positive | None = None
    robot_radius: Positive | None = None
    load_time: NonNegative | None = None
    door_hold_time: NonNegative | None = None
    robot_capacity: PositiveInt | None = None
    wall_height: Positive | None = None
    wall_thickness: Positive | None = None


class HumanTable(_Table, kw_only=True):
    room: Id
    position: Vec2


class RoomTable(_Table, kw_only=True):
    id: Id
    rect: Rect

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.rect
        if x1 <= x0:
            raise ProtocolError("rect", f"xmax {x1:g} must be greater than xmin {x0:g} (zero or negative width)")
        if y1 <= y0:
            raise ProtocolError("rect", f"ymax {y1:g} must be greater than ymin {y0:g} (zero or negative depth)")


class _OpeningTable(_Table, kw_only=True):
    """What doors and passages share: the two rooms they join, where, how wide."""

    rooms: RoomPair
    center: Vec2
    width: Positive

    def __post_init__(self) -> None:
        if self.rooms[0] == self.rooms[1]:
            raise ProtocolError("rooms", f"joins room {self.rooms[0]!r} to itself")


class DoorTable(_OpeningTable, kw_only=True):
    id: Id
    human_operated: bool | None = None
    swing_into: Id | None = None


class PassageTable(_OpeningTable, kw_only=True):
    id: Id | None = None


class LandmarkTable(_Table, kw_only=True):
    tag: TagId
    size: Positive
    position: Vec3
    yaw: Number


class RobotTable(_Table, kw_only=True):
    id: Id
    start: Pose


class ObjectTable(_Table, kw_only=True):
    id: Id
    position: Vec2
    deliver_to: Id
    robot: Id


class SiteFile(_Table, kw_only=True):
    """A site file: the building, its openings and landmarks, the robots, the objects and the human."""

    site: SiteTable
    params: ParamsTable | None = None
    rooms: Annotated[list[RoomTable], Meta(min_length=1)]
    doors: list[DoorTable] = []
    passages: list[PassageTable] = []
    landmarks: list[LandmarkTable] = []
    robots: Annotated[list[RobotTable], Meta(min_length=1)]
    objects: list[ObjectTable] = []
    human: HumanTable


TABLES = ("site", "params", "human")
ARRAYS = ("rooms", "doors", "passages", "landmarks", "robots", "objects")


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


_ENTRY = re.compile(r"^(?P<table>[a-z_]+)(?:\[(?P<index>\d+)\])?(?:\.?(?P<rest>.*))?$")


def _site_error(file: str, doc: dict[str, Any], error: ProtocolError) -> SiteError:
    """``rooms[2].rect: ...`` as SiteError(file, 'rooms[2] (id "lab")', 'rect: ...')."""
    m = _ENTRY.match(error.field)
    if m is None:
        return SiteError(file, "", error.problem)
    table, index, rest = m["table"], m["index"], m["rest"] or ""
    label = table
    if index is not None:
        raw = doc.get(table)
        i = int(index)
        label = entry_label(table, i, raw[i] if isinstance(raw, list) and i < len(raw) else None)
    return SiteError(file, label, f"{rest}: {error.problem}" if rest else error.problem)


def parse_document(file: str, doc: dict[str, Any]) -> SiteFile:
    """The file's tables as a :class:`SiteFile`, or a :class:`SiteError` naming the entry and problem."""
    try:
        return msgspec.convert(doc, SiteFile)
    except msgspec.ValidationError as exc:
        raise _site_error(file, doc, field_error(exc, SiteFile, doc, words=FILE)) from None


def _values(table: Struct) -> dict[str, Any]:
    return {name: getattr(table, name) for name in table.__struct_fields__}


def check_document(file: str, doc: dict[str, Any]) -> dict[str, Any]:
    """Check every table's shape and types; returns ``{table: Entry}`` and ``{array: [Entry]}``."""
    parsed = parse_document(file, doc)
    out: dict[str, Any] = {}
    for key in TABLES:
        table = getattr(parsed, key)
        out[key] = None if table is None else Entry(key, _values(table))
    for key in ARRAYS:
        raws = doc.get(key, [])
        out[key] = [Entry(entry_label(key, i, raws[i]), _values(t)) for i, t in enumerate(getattr(parsed, key))]
    return out


def site_schema() -> dict[str, Any]:
    """The JSON Schema of site files (tables, keys, types and ranges)."""
    return msgspec.json.schema(SiteFile)


def params_from(entry: Entry | None) -> Params:
    if entry is None:
        return Params()
    return Params(**{k: v for k, v in entry.values.items() if v is not None})
