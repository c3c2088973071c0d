"""msgpack wire codec: encode messages, decode and validate payloads.

Decoding never trusts the payload: size first, then msgpack with bounded containers, then the
envelope (``v``, ``type``, ``src``, ``seq``, ``stamp``), then every field of the type. Whatever is
wrong raises :class:`ProtocolError` naming the field. Unknown fields are ignored so that a newer
minor revision of a sender still talks to an older receiver; a newer *major* ``v`` is refused.

Both directions have a lean path for the common case, because they sit on every message of
every service: :func:`encoder_for` and :func:`decoder_for` generate one function per message
class (one Python frame per message, reused msgpack packers); the decoder tries the checks a valid
payload passes in one go and hands anything unusual to the full path, which produces the precise
error. :func:`encode` and :func:`decode` use them. :func:`validator_for` (checking without
building a message, for relays) first matches the payload against :func:`canonical_pattern`, a
regular expression of the encoder's own layout with everyday values: one call into C code.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import msgpack

from .errors import ProtocolError
from .messages import BY_TYPE, Message
from .schema import (
    ID_FIRST,
    ID_REST,
    MAX_STR,
    from_wire_function,
    plan_for,
    record_source,
    to_wire_function,
    whole_record_source,
    wire_map_source,
)

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
# Idle msgpack packers' pack methods. A Packer has a buffer, so two threads never share one: an
# encoder takes one (list.pop, atomic under the GIL), packs, and gives it back (list.append); with
# none idle it makes one. So there are at most as many as threads ever encoded at once. (A
# threading.local would do too, but its lookup costs several µs on a message's cold caches.)
_idle_packs: list[Callable[[Any], bytes]] = []


def _new_pack() -> Callable[[Any], bytes]:
    # autoreset: each pack() returns its bytes and starts afresh (also after an error).
    return msgpack.Packer(use_bin_type=True, autoreset=True).pack


def _pack(data: Any) -> bytes:
    """``data`` as msgpack, with an idle packer (the generated encoders inline this)."""
    try:
        pack = _idle_packs.pop()
    except IndexError:
        pack = _new_pack()
    out = pack(data)
    _idle_packs.append(pack)  # not after an error: the next encoder simply makes a new one
    return out


def encoder_for(cls: type[M]) -> Callable[[M], bytes]:
    """The generated encoder of one message class: ``f(msg) -> bytes`` (what :func:`encode` does
    without ``extra``, in one Python frame). Built once per class."""
    fn = _ENCODERS.get(cls)
    if fn is not None:
        return fn
    expr, consts = wire_map_source(cls, _envelope_trailer(cls), var="msg")
    consts.update(take=_idle_packs.pop, give=_idle_packs.append, new_pack=_new_pack)
    source = (  # _pack(), inlined: one frame less per message
        "def encode_msg(msg):\n"
        "    try:\n"
        "        pack = take()\n"
        "    except IndexError:\n"
        "        pack = new_pack()\n"
        f"    out = pack({expr})\n"
        "    give(pack)\n"
        "    return out\n"
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
    consts.update(
        unpackb=_unpackb,
        checked=_decode_checked,
        ProtocolError=ProtocolError,
        TYPE=cls.TYPE,
        VERSION=cls.VERSION,
        LIMIT=limit,
    )
    # msgpack's own limits are the payload's length (half of it for maps), which no valid payload
    # exceeds and which the size check above keeps within the class's: only the limits those do
    # not imply are passed (each keyword is work on every call), and ext types are refused.
    # msgpack >= 1.0 defaults to raw=False and strict_map_key=True, as _unpack asks.
    limits = ["max_ext_len=0"]
    if limit > MAX_ARRAY_LEN:
        limits.append(f"max_array_len={MAX_ARRAY_LEN}")
    if limit // 2 > MAX_MAP_LEN:
        limits.append(f"max_map_len={MAX_MAP_LEN}")
    # A checker need not look inside a payload in the encoder's own layout with everyday values:
    # one regular expression match (C code) says it is valid. (A decoder must build the message,
    # which takes the unpacking anyway, and matching first would only add to it.)
    canonical = None if build else canonical_pattern(cls)
    if canonical is not None:
        consts["CANONICAL"] = canonical.fullmatch
    source = [
        "def decode_msg(payload):",
        *(
            ["    if type(payload) is bytes and CANONICAL(payload) is not None:", "        return None"]
            if canonical is not None
            else []
        ),
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
        "    if type(version) is not int or not 0 < version <= VERSION or 'src' not in data or 'seq' not in data or "
        "'stamp' not in data:",
        "        return checked(payload, cls)",
        "    prefix = ''",
        "    try:",
        *body,
        "    except ProtocolError as exc:",
        "        raise ProtocolError(exc.field, exc.problem, TYPE) from None",
    ]
    exec("\n".join(source), consts)  # noqa: S102 - generated from the class's own fields
    return consts["decode_msg"]


# ---------------------------------------------------------------------------- canonical payloads

_CANONICAL: dict[type, re.Pattern[bytes] | None] = {}
_ANY = b"[\\x00-\\xff]"
_ASCII = b"[\\x00-\\x7f]"
_MAX_FIXSTR = 31  # msgpack's one-byte-header strings: 0xa0 + length in bytes
# msgpack's integer formats: (first byte(s), bytes that follow, lowest value, highest value).
_INT_FORMATS = (
    (b"[\\x00-\\x7f]", 0, 0, 127),  # positive fixint
    (b"[\\xe0-\\xff]", 0, -32, -1),  # negative fixint
    (b"\\xcc", 1, 0, 2**8 - 1),
    (b"\\xcd", 2, 0, 2**16 - 1),
    (b"\\xce", 4, 0, 2**32 - 1),
    (b"\\xcf[\\x00-\\x7f]", 7, 0, 2**63 - 1),
    (b"\\xcf[\\x80-\\xff]", 7, 2**63, 2**64 - 1),  # uint 64, in halves
    (b"\\xd0", 1, -(2**7), 2**7 - 1),
    (b"\\xd1", 2, -(2**15), 2**15 - 1),
    (b"\\xd2", 4, -(2**31), 2**31 - 1),
    (b"\\xd3", 8, -(2**63), 2**63 - 1),
)


def canonical_pattern(cls: type[Message]) -> re.Pattern[bytes] | None:
    """A regular expression over payloads as :func:`encoder_for` writes them (every field in order,
    then ``v`` and ``type``) with everyday values: strings of at most 31 ASCII characters (or one
    of their choices), integers in a msgpack format whose whole range is within the bounds, floats
    (float 64) within a power-of-two interval inside theirs, booleans, None for optionals. Every
    payload it matches is valid (:func:`decode` accepts it); others may be too, and are checked in
    full. None when some field is of another kind (lists, maps, bytes, records). Built once per class."""
    if cls in _CANONICAL:
        return _CANONICAL[cls]
    hints = typing.get_type_hints(cls)
    metas = {f.name: f.metadata for f in dataclasses.fields(cls)}
    header = msgpack.Packer().pack_map_header(len(plan_for(cls)) + len(_envelope_trailer(cls)))
    parts, longest = [re.escape(header)], len(header)
    for fp in plan_for(cls):
        value = _value_pattern(hints[fp.name], metas[fp.name], fp.check)
        if value is None:
            _CANONICAL[cls] = None
            return None
        key = msgpack.packb(fp.name)
        parts.append(re.escape(key) + value[0])
        longest += len(key) + value[1]
    for name, value in _envelope_trailer(cls).items():
        parts.append(re.escape(msgpack.packb(name) + msgpack.packb(value)))
        longest += len(parts[-1])  # escaping only lengthens: an upper bound
    # No size check goes with the pattern: whatever it matches must be within the class's limit.
    pattern = _CANONICAL[cls] = re.compile(b"".join(parts)) if longest <= cls.MAX_SIZE else None
    return pattern


def _value_pattern(hint: Any, meta: Mapping[str, Any], check: Callable[[Any, str], Any]) -> tuple[bytes, int] | None:
    """The pattern of a field's everyday valid values (see :func:`canonical_pattern`) and the most
    bytes it matches, or None."""
    if typing.get_origin(hint) in (types.UnionType, typing.Union):
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(members) != 1 or len(members) == len(typing.get_args(hint)):
            return None
        inner = _value_pattern(members[0], meta, check)  # X | None: None checks as valid, X as X
        return None if inner is None else (b"(?:\\xc0|" + inner[0] + b")", inner[1])
    if hint is bool:
        return b"[\\xc2\\xc3]", 1
    if hint is int:
        lo, hi = meta.get("lo"), meta.get("hi")
        formats = [
            (lead + (_ANY + b"{%d}" % size if size else b""), 1 + size)
            for lead, size, least, most in _INT_FORMATS
            if (lo is None or lo <= least) and (hi is None or most <= hi)
        ]
        return (b"(?:" + b"|".join(f for f, _ in formats) + b")", max(n for _, n in formats)) if formats else None
    if hint is float:
        pattern = _float_pattern(meta.get("lo"), meta.get("hi"))
        return None if pattern is None else (pattern, 9)
    if hint is str:
        if meta.get("choices") is not None:
            # Exactly the choices the field's own check lets through, as msgpack writes them.
            valid = [msgpack.packb(c) for c in meta["choices"] if _passes(check, c)]
            return (b"(?:" + b"|".join(map(re.escape, valid)) + b")", max(map(len, valid))) if valid else None
        longest = min(_MAX_FIXSTR, meta.get("max_len") or MAX_STR)
        first, rest = (ID_FIRST.encode(), ID_REST.encode()) if meta.get("ident") else (_ASCII, _ASCII)
        # The header byte says how many bytes follow; "" is valid whether an identifier is asked or not.
        lengths = [b"\\xa0"] + [
            b"\\x%02x" % (0xA0 + n) + first + (rest + b"{%d}" % (n - 1) if n > 1 else b"")
            for n in range(1, longest + 1)
        ]
        return b"(?:" + b"|".join(lengths) + b")", 1 + longest
    return None


def _passes(check: Callable[[Any, str], Any], value: Any) -> bool:
    """True when the field's check accepts ``value`` as it is."""
    try:
        return check(value, "") == value
    except ProtocolError:
        return False


def _float_pattern(lo: float | None, hi: float | None) -> bytes | None:
    """float 64 values inside [lo, hi], as far as the sign and exponent bits alone can tell: on the
    positive side [0, 2**b) with 2**b <= hi, on the negative side (-2**a, -0.0] with -2**a >= lo (the
    side left out when its bound is 0). Never infinities nor NaN (their exponent is all ones).
    None when a bound excludes 0 (a lower bound above 0, say), which exponents cannot express."""
    if (lo is not None and lo > 0) or (hi is not None and hi < 0):
        return None
    sides = [
        (sign, _max_exponent(bound))
        for sign, bound in ((0x00, hi), (0x80, None if lo is None else -lo))
        if bound is None or bound > 0
    ]
    alternatives = []
    for sign, top in sides:
        if top < 0:
            continue
        # The first two bytes hold the sign, the 11 exponent bits, then mantissa bits.
        high, low = sign | top >> 4, (top & 0xF) << 4 | 0xF
        if high > sign:
            alternatives.append(b"[\\x%02x-\\x%02x]" % (sign, high - 1) + _ANY)
        alternatives.append(b"\\x%02x[\\x00-\\x%02x]" % (high, low))
    if not alternatives:
        return None
    return b"\\xcb(?:" + b"|".join(alternatives) + b")" + _ANY + b"{6}"


def _max_exponent(bound: float | None) -> int:
    """The largest biased exponent of doubles below 2**b <= bound (no bound: 2046, every finite double)."""
    if bound is None:
        return 2046
    b = min(math.floor(math.log2(bound)), 1023)
    while 2.0**b > bound:  # log2 rounding, on the safe side
        b -= 1
    return min(2046, 1022 + b)


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
    return _pack(data)


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
