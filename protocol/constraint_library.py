"""The constraint library as the running restrictor serves it (queryable ``constraints/library``).

Feedback buttons (the AR client's panel, the tablet page) are built from this answer, never from a
library file loaded in the client's own process, so they always offer what the restrictor that
will judge the feedback accepts.

Wire form: one MessagePack map, ``{"v": 1, "type": "ConstraintLibrary", "src", "site", "entries"}``;
``entries`` is the library with the site's choices resolved, one map per entry (``id``, ``label``,
``help``, ``effect``, ``window``, ``usable``, ``params``: see docs/services/restrictor.md, "Library file").
:func:`decode_library` checks the shape and limits and raises :class:`ProtocolError` naming the
field; fields it does not know are ignored (a newer minor revision may add some).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import msgpack

from .errors import ProtocolError

TYPE = "ConstraintLibrary"
VERSION = 1
MAX_SIZE = 256 * 1024  # bytes; the packaged library for the office site is ~2 kB
MAX_ENTRIES = 100
MAX_PARAMS = 16
MAX_CHOICES = 1000
MAX_LABEL = 80
MAX_HELP = 300
MAX_ID = 64
PARAM_TYPES = ("int", "door", "room", "opening", "constraint")
EFFECTS = ("add", "cancel")


@dataclass(frozen=True)
class ConstraintLibrary:
    """A restrictor's answer: which site its choices are for, and the entries as plain data."""

    src: str
    site: str
    entries: list[dict[str, Any]]


def encode_library(src: str, site: str, entries: list[dict[str, Any]]) -> bytes:
    """The reply payload for ``entries`` (as ``library_for_site`` gives them), checked before it goes out."""
    payload = msgpack.packb({"v": VERSION, "type": TYPE, "src": src, "site": site, "entries": entries})
    decode_library(payload)  # a restrictor never serves what its clients would refuse
    return payload


def decode_library(payload: bytes) -> ConstraintLibrary:
    """The library in ``payload``; :class:`ProtocolError` naming the first field that is wrong."""
    if len(payload) > MAX_SIZE:
        raise ProtocolError("", f"payload of {len(payload)} bytes exceeds {MAX_SIZE}", TYPE)
    try:
        raw = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:
        raise ProtocolError("", f"not MessagePack ({type(exc).__name__})", TYPE) from None
    _map(raw, "")
    if raw.get("type") != TYPE:
        raise ProtocolError("type", f"expected {TYPE!r}, got {raw.get('type')!r}", TYPE)
    version = raw.get("v")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise ProtocolError("v", f"expected a positive integer, got {version!r}", TYPE)
    if version > VERSION:
        raise ProtocolError("v", f"version {version} is newer than {VERSION}, which this reader knows", TYPE)
    entries = _list(raw, "entries", "entries", MAX_ENTRIES)
    return ConstraintLibrary(
        src=_text(raw, "src", "src", MAX_ID * 2),
        site=_text(raw, "site", "site", MAX_ID),
        entries=[_entry(entry, f"entries[{i}]") for i, entry in enumerate(entries)],
    )


def _entry(raw: Any, where: str) -> dict[str, Any]:
    _map(raw, where)
    effect = _one_of(raw, "effect", f"{where}.effect", EFFECTS)
    usable = raw.get("usable")
    if not isinstance(usable, bool):
        raise ProtocolError(f"{where}.usable", f"expected a boolean, got {usable!r}", TYPE)
    params = _list(raw, "params", f"{where}.params", MAX_PARAMS)
    return {
        "id": _text(raw, "id", f"{where}.id", MAX_ID, empty=False),
        "label": _text(raw, "label", f"{where}.label", MAX_LABEL, empty=False),
        "help": _text(raw, "help", f"{where}.help", MAX_HELP),
        "effect": effect,
        "window": _window(raw.get("window"), f"{where}.window"),
        "usable": usable,
        "params": [_param(p, f"{where}.params[{i}]") for i, p in enumerate(params)],
    }


def _param(raw: Any, where: str) -> dict[str, Any]:
    _map(raw, where)
    kind = _one_of(raw, "type", f"{where}.type", PARAM_TYPES)
    out: dict[str, Any] = {
        "name": _text(raw, "name", f"{where}.name", MAX_ID, empty=False),
        "type": kind,
        "label": _text(raw, "label", f"{where}.label", MAX_LABEL, empty=False),
        "help": _text(raw, "help", f"{where}.help", MAX_HELP),
    }
    if kind == "int":
        lo, hi = _int(raw, "min", f"{where}.min"), _int(raw, "max", f"{where}.max")
        if lo > hi:
            raise ProtocolError(f"{where}.max", f"{hi} is below min {lo}", TYPE)
        out.update(min=lo, max=hi)
    elif kind == "constraint":
        out.update(choices=None, source="constraints")
    else:
        choices = _list(raw, "choices", f"{where}.choices", MAX_CHOICES)
        for i, choice in enumerate(choices):
            if not isinstance(choice, str) or not 0 < len(choice) <= MAX_ID:
                raise ProtocolError(f"{where}.choices[{i}]", f"expected an id of 1 to {MAX_ID} characters", TYPE)
        out.update(choices=list(choices), source="site")
    return out


def _window(raw: Any, where: str) -> dict[str, Any] | None:
    if raw is None:
        return None
    if isinstance(raw, dict) and set(raw) == {"param"}:
        return {"param": _text(raw, "param", f"{where}.param", MAX_ID, empty=False)}
    if isinstance(raw, dict) and set(raw) == {"minutes"}:
        return {"minutes": _int(raw, "minutes", f"{where}.minutes")}
    raise ProtocolError(where, f"expected null, {{param: name}} or {{minutes: n}}, got {raw!r:.60}", TYPE)


def _map(raw: Any, where: str) -> None:
    if not isinstance(raw, dict):
        raise ProtocolError(where, f"expected a map, got {type(raw).__name__}", TYPE)


def _one_of(raw: dict[str, Any], name: str, where: str, options: tuple[str, ...]) -> str:
    value = raw.get(name)
    if value not in options:
        raise ProtocolError(where, f"expected one of {', '.join(options)}, got {value!r}", TYPE)
    return value


def _text(raw: dict[str, Any], name: str, where: str, limit: int, *, empty: bool = True) -> str:
    value = raw.get(name)
    if not isinstance(value, str):
        raise ProtocolError(where, f"expected a string, got {type(value).__name__}", TYPE)
    if len(value) > limit or (not empty and not value):
        raise ProtocolError(where, f"expected {0 if empty else 1} to {limit} characters, got {len(value)}", TYPE)
    return value


def _int(raw: dict[str, Any], name: str, where: str) -> int:
    value = raw.get(name)
    if not isinstance(value, int) or isinstance(value, bool):
        raise ProtocolError(where, f"expected an integer, got {value!r:.40}", TYPE)
    return value


def _list(raw: dict[str, Any], name: str, where: str, limit: int) -> list[Any]:
    value = raw.get(name)
    if not isinstance(value, list):
        raise ProtocolError(where, f"expected a list, got {type(value).__name__}", TYPE)
    if len(value) > limit:
        raise ProtocolError(where, f"{len(value)} items, more than {limit}", TYPE)
    return value
