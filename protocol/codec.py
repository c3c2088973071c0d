"""msgpack wire codec: encode messages, decode and validate payloads, with msgspec.

Decoding never trusts the payload: size first, then the envelope (``v``, ``type``, ``src``,
``seq``, ``stamp``), then every field of the type, each within the limits its type declares
(:mod:`protocol.schema`). Whatever is wrong raises :class:`ProtocolError` naming the field.
Unknown fields are ignored so that a newer minor revision of a sender still talks to an older
receiver; a newer *major* ``v`` is refused.

A valid payload takes two msgspec calls (the envelope, then the message: both in C). Anything
they refuse goes to the full path, :func:`_decode_checked`, which checks in a fixed order and
words the problem (:mod:`protocol.validation`), so the error does not depend on which check
msgspec happened to meet first.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Annotated, Any, TypeVar

import msgspec
from msgspec import Meta

from .errors import ProtocolError
from .messages import BY_TYPE, Message
from .schema import extra_checks, plain_value, record_to_wire
from .validation import field_error

M = TypeVar("M", bound=Message)

ENCODING = "application/msgpack"
_ABSOLUTE_MAX = max(cls.MAX_SIZE for cls in BY_TYPE.values())
_ENVELOPE = ("v", "type", "src", "seq", "stamp")


class _Envelope(msgspec.Struct):
    """What every payload must carry (values are checked with the message's own fields)."""

    type: str
    v: Annotated[int, Meta(ge=1)]
    src: Any
    seq: Any
    stamp: Any


_encode = msgspec.msgpack.Encoder(enc_hook=plain_value).encode
_envelope = msgspec.msgpack.Decoder(_Envelope).decode
_untyped = msgspec.msgpack.Decoder().decode
_TYPED: dict[type, Callable[[Any], Message]] = {}
_DECODERS: dict[type, Callable[[Any], Message]] = {}
_ACCEPTORS: dict[type, Callable[[Any], Message | None]] = {}


def _typed(cls: type[M]) -> Callable[[Any], M]:
    fn = _TYPED.get(cls)
    if fn is None:
        fn = _TYPED[cls] = msgspec.msgpack.Decoder(cls).decode
    return fn  # type: ignore[return-value]


def encode(msg: Message, extra: Mapping[str, Any] | None = None) -> bytes:
    """Serialise a message (envelope included) to msgpack bytes.

    ``extra`` adds fields the message type does not know, as a newer minor revision of a sender
    would (receivers ignore them); diagnostics use it to pad a payload to a chosen size. An extra
    field may not shadow a field of the type or of the envelope.
    """
    if not extra:
        return _encode(msg)
    data = record_to_wire(msg)
    clash = sorted(set(extra) & set(data))
    if clash:
        raise ValueError(f"extra fields {', '.join(clash)} would shadow fields of {msg.TYPE}")
    data.update(extra)
    return _encode(data)


def encoder_for(cls: type[M]) -> Callable[[M], bytes]:
    """``f(msg) -> bytes``: what :func:`encode` does without ``extra`` (the same for every class)."""
    return _encode


def decoder_for(cls: type[M]) -> Callable[[Any], M]:
    """``f(payload) -> msg``: what ``decode(payload, cls)`` does. Built once per class."""
    fn = _DECODERS.get(cls)
    if fn is not None:
        return fn  # type: ignore[return-value]
    accept = _acceptor(cls)

    def decode_msg(payload: Any) -> M:
        msg = accept(payload)
        return msg if msg is not None else _decode_checked(payload, cls)

    _DECODERS[cls] = decode_msg
    return decode_msg


def _acceptor(cls: type[M]) -> Callable[[Any], M | None]:
    """``f(payload)``: the message when msgspec accepts the payload as a ``cls`` (envelope, fields
    and the checks msgspec cannot do), else None. Built once per class."""
    fn = _ACCEPTORS.get(cls)
    if fn is not None:
        return fn  # type: ignore[return-value]
    typed, checks, limit, name, version = _typed(cls), extra_checks(cls), cls.MAX_SIZE, cls.TYPE, cls.VERSION
    envelope, errors = _envelope, (msgspec.MsgspecError, RecursionError, ValueError)  # ProtocolError is one

    def accept(payload: Any) -> M | None:
        if type(payload) is bytes and 0 < len(payload) <= limit:
            try:
                head = envelope(payload)
                if head.type == name and head.v <= version:
                    msg = typed(payload)
                    for field, check in checks:
                        check(getattr(msg, field), field)
                    return msg
            except errors:
                pass
        return None

    _ACCEPTORS[cls] = accept
    return accept


def validator_for(cls: type[Message]) -> Callable[[Any], object]:
    """``f(payload)`` raises :class:`ProtocolError` exactly when ``decode(payload, cls)`` would, with
    the same error (what a relay wants before passing the payload on). Its return value means nothing."""
    return decoder_for(cls)


def decode(payload: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate a payload.

    With ``expected``, the payload's ``type`` must name that class; without, any known type is
    accepted and the matching class is returned.
    """
    if expected is not None:
        return (_DECODERS.get(expected) or decoder_for(expected))(payload)  # type: ignore[return-value]
    return _decode_checked(payload, None)


def _unpack(payload: bytes | bytearray | memoryview, limit: int) -> Any:
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ProtocolError("", f"payload must be bytes, got {type(payload).__name__}")
    if len(payload) == 0:
        raise ProtocolError("", "empty payload")
    if len(payload) > limit:
        raise ProtocolError("", f"payload of {len(payload)} bytes exceeds the limit {limit}")
    try:
        data = _untyped(payload)
    except (msgspec.DecodeError, RecursionError, UnicodeDecodeError) as exc:
        raise ProtocolError("", f"not a valid msgpack document ({exc.__class__.__name__}: {exc})") from None
    if isinstance(data, msgspec.msgpack.Ext):
        raise ProtocolError("", "not a valid msgpack document (an extension type)")
    if isinstance(data, dict) and not all(type(k) is str for k in data):
        raise ProtocolError("", "not a valid msgpack document (a map key is not a string)")
    return data


def _accepted_as_is(payload: Any, expected: type[M] | None) -> M | None:
    if expected is None:
        try:
            expected = BY_TYPE.get(_envelope(bytes(payload)).type)  # type: ignore[assignment]
        except (msgspec.MsgspecError, RecursionError, ValueError, TypeError):
            return None
    return (
        None
        if expected is None
        else _acceptor(expected)(bytes(payload) if isinstance(payload, (bytearray, memoryview)) else payload)
    )


def _decode_checked(payload: bytes | bytearray | memoryview, expected: type[M] | None) -> M:
    """The full path: every check in order, raising the first problem found."""
    limit = expected.MAX_SIZE if expected is not None else _ABSOLUTE_MAX
    try:
        data = _unpack(payload, limit)
    except ProtocolError:
        # Reading every byte can fail where the message itself is fine: msgspec skips the fields
        # a message does not know without decoding them (a key that is not UTF-8, say).
        msg = _accepted_as_is(payload, expected)
        if msg is not None:
            return msg
        raise
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
        msg = _typed(cls)(payload)
        for field, check in extra_checks(cls):
            check(getattr(msg, field), field)
    except msgspec.ValidationError as exc:
        error = field_error(exc, cls, data)
        raise ProtocolError(error.field, error.problem, cls.TYPE) from None
    except ProtocolError as exc:
        raise ProtocolError(exc.field, exc.problem, cls.TYPE) from None
    return msg  # type: ignore[return-value]
