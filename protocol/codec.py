"""msgpack wire codec: encode messages, decode and validate payloads.

Decoding never trusts the payload: size first, then msgpack with bounded containers, then the
envelope (``v``, ``type``, ``src``, ``seq``, ``stamp``), then every field of the type. Whatever is
wrong raises :class:`ProtocolError` naming the field. Unknown fields are ignored so that a newer
minor revision of a sender still talks to an older receiver; a newer *major* ``v`` is refused.
"""

from __future__ import annotations

from typing import Any, TypeVar

import msgpack

from .errors import ProtocolError
from .messages import BY_TYPE, Message
from .schema import plan_for, record_to_wire

M = TypeVar("M", bound=Message)

ENCODING = "application/msgpack"
_ABSOLUTE_MAX = max(cls.MAX_SIZE for cls in BY_TYPE.values())
_ENVELOPE = ("v", "type", "src", "seq", "stamp")


def encode(msg: Message) -> bytes:
    """Serialise a message (envelope included) to msgpack bytes."""
    data = record_to_wire(msg)
    data["v"] = msg.VERSION
    data["type"] = msg.TYPE
    return msgpack.packb(data, use_bin_type=True)


def _unpack(payload: bytes | bytearray | memoryview, limit: int) -> Any:
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ProtocolError("", f"payload must be bytes, got {type(payload).__name__}")
    if len(payload) == 0:
        raise ProtocolError("", "empty payload")
    if len(payload) > limit:
        raise ProtocolError("", f"payload of {len(payload)} bytes exceeds the limit {limit}")
    try:
        return msgpack.unpackb(
            payload,
            raw=False,
            strict_map_key=True,
            max_str_len=limit,
            max_bin_len=limit,
            max_array_len=1_000_000,
            max_map_len=100_000,
            max_ext_len=0,
        )
    except ProtocolError:
        raise
    except (ValueError, TypeError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as exc:
        raise ProtocolError("", f"not a valid msgpack document ({exc.__class__.__name__}: {exc})") from None


def decode(payload: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate a payload.

    With ``expected``, the payload's ``type`` must name that class; without, any known type is
    accepted and the matching class is returned.
    """
    limit = expected.MAX_SIZE if expected is not None else _ABSOLUTE_MAX
    data = _unpack(payload, limit)
    if not isinstance(data, dict):
        raise ProtocolError("", f"payload must be a map, got {type(data).__name__}")
    type_name = data.get("type")
    if not isinstance(type_name, str):
        raise ProtocolError("type", "required string field is missing or not a string")
    cls = BY_TYPE.get(type_name)
    if cls is None:
        raise ProtocolError("type", f"unknown message type {type_name[:64]!r}")
    if expected is not None and cls is not expected:
        raise ProtocolError("type", f"expected {expected.TYPE}, got {type_name}")
    if len(payload) > cls.MAX_SIZE:
        raise ProtocolError("", f"payload of {len(payload)} bytes exceeds the limit {cls.MAX_SIZE}", cls.TYPE)
    version = data.get("v")
    if isinstance(version, bool) or not isinstance(version, int):
        raise ProtocolError("v", "schema version is missing or not an integer", cls.TYPE)
    if version > cls.VERSION:
        raise ProtocolError("v", f"schema version {version} is newer than the supported {cls.VERSION}", cls.TYPE)
    if version < 1:
        raise ProtocolError("v", f"schema version {version} is not valid", cls.TYPE)
    for name in _ENVELOPE[2:]:
        if name not in data:
            raise ProtocolError(name, "required field is missing", cls.TYPE)
    values = {}
    try:
        for fp in plan_for(cls):
            if fp.name in data:
                values[fp.name] = fp.check(data[fp.name], fp.name)
            elif fp.required:
                raise ProtocolError(fp.name, "required field is missing")
    except ProtocolError as exc:
        raise ProtocolError(exc.field, exc.problem, cls.TYPE) from None
    return cls(**values)  # type: ignore[return-value]
