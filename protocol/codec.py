"""msgpack wire codec: encode messages, decode and validate payloads.

Decoding never trusts the payload: size first, then msgpack with bounded containers, then the
envelope (``v``, ``type``, ``src``, ``seq``, ``stamp``), then every field of the type. Whatever is
wrong raises :class:`ProtocolError` naming the field. Unknown fields are ignored so that a newer
minor revision of a sender still talks to an older receiver; a newer *major* ``v`` is refused.

Both directions have a lean path for the common case, because they sit on every message of
every service: :func:`encoder_for` and :func:`decoder_for` generate one function per message
class (one Python frame per message, a reused per-thread msgpack packer); the decoder tries the
checks a valid payload passes in one go and hands anything unusual to the full path, which
produces the precise error. :func:`encode` and :func:`decode` use them.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Mapping, TypeVar

import msgpack

from .errors import ProtocolError
from .messages import BY_TYPE, Message
from .schema import from_wire_function, record_source, to_wire_function, whole_record_source, wire_map_source

M = TypeVar("M", bound=Message)

ENCODING = "application/msgpack"
_ABSOLUTE_MAX = max(cls.MAX_SIZE for cls in BY_TYPE.values())
_ENVELOPE = ("v", "type", "src", "seq", "stamp")
MAX_ARRAY_LEN = 1_000_000
MAX_MAP_LEN = 100_000

_unpackb = msgpack.unpackb
_ENCODERS: dict[type, Callable[[Message], bytes]] = {}
_DECODERS: dict[type, Callable[[Any], Message]] = {}
_VALIDATORS: dict[type, Callable[[Any], object]] = {}
_WIRE_MAPS: dict[type, Callable[[Message], dict]] = {}
_local = threading.local()  # one msgpack.Packer per thread: a Packer has a buffer, so is not shared


def _new_pack() -> Callable[[Any], bytes]:
    # autoreset: each pack() returns its bytes and starts afresh (also after an error).
    _local.pack = msgpack.Packer(use_bin_type=True, autoreset=True).pack
    return _local.pack


def encoder_for(cls: type[M]) -> Callable[[M], bytes]:
    """The generated encoder of one message class: ``f(msg) -> bytes`` (what :func:`encode` does
    without ``extra``, in one Python frame). Built once per class."""
    fn = _ENCODERS.get(cls)
    if fn is not None:
        return fn
    expr, consts = wire_map_source(cls, _envelope_trailer(cls), var="msg")
    consts.update(local=_local, new_pack=_new_pack)
    source = (
        "def encode_msg(msg):\n"
        "    try:\n"
        "        pack = local.pack\n"
        "    except AttributeError:\n"
        "        pack = new_pack()\n"
        f"    return pack({expr})\n"
    )
    exec(source, consts)  # noqa: S102 - generated from the class's own fields
    fn = _ENCODERS[cls] = consts["encode_msg"]
    return fn


def _envelope_trailer(cls: type[Message]) -> dict[str, Any]:
    return {"v": cls.VERSION, "type": cls.TYPE}


def _wire_map(cls: type[Message]) -> Callable[[Message], dict]:
    """The message as a plain map, envelope included (for encoding with extra fields)."""
    fn = _WIRE_MAPS.get(cls)
    if fn is None:
        fn = _WIRE_MAPS[cls] = to_wire_function(cls, _envelope_trailer(cls))
    return fn


def decoder_for(cls: type[M]) -> Callable[[Any], M]:
    """The generated decoder of one message class: ``f(payload) -> msg``, what ``decode(payload, cls)``
    does, in one Python frame for a valid payload.

    It tries the checks a valid payload passes in one go (size, one msgpack call, then ``type``,
    ``v`` and every field at once when the class allows it, else ``type``, ``v``, envelope present,
    each field's inline test); anything unusual goes to the full path, which produces the precise
    error. Built once per class."""
    fn = _DECODERS.get(cls)
    if fn is None:
        fn = _DECODERS[cls] = _generate_decoder(cls, build=True)
    return fn


def validator_for(cls: type[Message]) -> Callable[[Any], object]:
    """The generated checker of one message class: ``f(payload)`` raises :class:`ProtocolError`
    exactly when ``decode(payload, cls)`` would, with the same error, and builds no message when
    it need not (what a relay wants: it passes the payload on as it is). Its return value means
    nothing. Built once per class."""
    fn = _VALIDATORS.get(cls)
    if fn is None:
        fn = _VALIDATORS[cls] = _generate_decoder(cls, build=False)
    return fn


def _generate_decoder(cls: type[M], *, build: bool) -> Callable[[Any], Any]:
    body, consts = record_source(cls, indent="        ")
    limit = cls.MAX_SIZE
    # The envelope's type and version are checked with the fields; literals, like the fields' bounds.
    lead = (("type", f"{{x}} == {cls.TYPE!r}"), ("v", f"type({{x}}) is int and 0 < {{x}} <= {cls.VERSION!r}"))
    whole = whole_record_source(cls, lead, build=build)
    if whole is not None:
        consts.update(whole[1])
    consts.update(unpackb=_unpackb, checked=_decode_checked, ProtocolError=ProtocolError,
                  TYPE=cls.TYPE, VERSION=cls.VERSION, LIMIT=limit)
    # msgpack's own limits are the payload's length (half of it for maps), which no valid payload
    # exceeds and which the size check above keeps within the class's: only the limits those do
    # not imply are passed (each keyword is work on every call), and ext types are refused.
    # msgpack >= 1.0 defaults to raw=False and strict_map_key=True, as _unpack asks.
    limits = ["max_ext_len=0"]
    if limit > MAX_ARRAY_LEN:
        limits.append(f"max_array_len={MAX_ARRAY_LEN}")
    if limit // 2 > MAX_MAP_LEN:
        limits.append(f"max_map_len={MAX_MAP_LEN}")
    source = [
        "def decode_msg(payload):",
        "    if type(payload) is not bytes or not 0 < len(payload) <= LIMIT:",
        "        return checked(payload, cls)",
        "    try:",
        f"        data = unpackb(payload, {', '.join(limits)})",
        "    except Exception:",
        "        return checked(payload, cls)",
        *(whole[0] if whole is not None else []),
        "    if type(data) is not dict or data.get('type') != TYPE:",
        "        return checked(payload, cls)",
        "    version = data.get('v')",
        "    if type(version) is not int or not 0 < version <= VERSION or 'src' not in data or 'seq' not in data or 'stamp' not in data:",
        "        return checked(payload, cls)",
        "    prefix = ''",
        "    try:",
        *body,
        "    except ProtocolError as exc:",
        "        raise ProtocolError(exc.field, exc.problem, TYPE) from None",
    ]
    exec("\n".join(source), consts)  # noqa: S102 - generated from the class's own fields
    return consts["decode_msg"]


def encode(msg: Message, extra: Mapping[str, Any] | None = None) -> bytes:
    """Serialise a message (envelope included) to msgpack bytes.

    ``extra`` adds fields the message type does not know, as a newer minor revision of a sender
    would (receivers ignore them); diagnostics use it to pad a payload to a chosen size. An extra
    field may not shadow a field of the type or of the envelope.
    """
    if not extra:
        return (_ENCODERS.get(type(msg)) or encoder_for(type(msg)))(msg)
    data = _wire_map(type(msg))(msg)
    clash = sorted(set(extra) & set(data))
    if clash:
        raise ValueError(f"extra fields {', '.join(clash)} would shadow fields of {msg.TYPE}")
    data.update(extra)
    try:
        pack = _local.pack
    except AttributeError:
        pack = _new_pack()
    return pack(data)


def _unpack(payload: bytes | bytearray | memoryview, limit: int) -> Any:
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ProtocolError("", f"payload must be bytes, got {type(payload).__name__}")
    if len(payload) == 0:
        raise ProtocolError("", "empty payload")
    if len(payload) > limit:
        raise ProtocolError("", f"payload of {len(payload)} bytes exceeds the limit {limit}")
    try:
        return _unpackb(
            payload,
            raw=False,
            strict_map_key=True,
            max_str_len=limit,
            max_bin_len=limit,
            max_array_len=MAX_ARRAY_LEN,
            max_map_len=MAX_MAP_LEN,
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
    if expected is not None:
        return (_DECODERS.get(expected) or decoder_for(expected))(payload)  # type: ignore[return-value]
    return _decode_checked(payload, None)


def _decode_checked(payload: bytes | bytearray | memoryview, expected: type[M] | None) -> M:
    """The full path: every check in order, raising the first problem found."""
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
    try:
        return from_wire_function(cls)(data, "")  # type: ignore[return-value]
    except ProtocolError as exc:
        raise ProtocolError(exc.field, exc.problem, cls.TYPE) from None
