"""The codec's fast paths agree with its full path.

The generated decoder and checker of every message class must accept and refuse exactly what the
full path (``_decode_checked``, every check in order) accepts and refuses, with the same error, and
whatever the canonical-layout pattern behind ``validator_for`` matches must be valid. Checked on
drawn messages, on their payloads mutated byte by byte, and on the edges of each pattern piece.
"""

from __future__ import annotations

import math
import re
import struct
import threading
from collections.abc import Callable
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.codec import (
    _decode_checked,
    _float_pattern,
    _value_pattern,
    canonical_pattern,
    decoder_for,
    encode,
    validator_for,
)
from protocol.errors import ProtocolError
from protocol.messages import ALL_MESSAGES, Clock, DoorState, FeedbackAck, RobotPose
from tests.protocol.strategies import minimal_wire, pack, sample_message, strategy_for

PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FLAT = [Clock, DoorState, FeedbackAck, RobotPose]  # every field a scalar: these have a pattern


def outcome(fn: Callable[[Any], Any], payload: Any) -> tuple:
    """``("ok", result)`` or ``("refused", field, message)``."""
    try:
        return ("ok", fn(payload))
    except ProtocolError as exc:
        return ("refused", exc.field, str(exc))


def mutated(payload: bytes) -> st.SearchStrategy[bytes]:
    """The payload with a few bytes changed, cut out, added, or cut short."""
    n = len(payload)
    index = st.integers(0, n - 1)
    flips = st.lists(st.tuples(index, st.integers(0, 255)), min_size=1, max_size=3).map(
        lambda edits: bytes(_apply(bytearray(payload), edits))
    )
    cut = st.tuples(index, st.integers(1, 4)).map(lambda c: payload[: c[0]] + payload[c[0] + c[1] :])
    added = st.tuples(st.integers(0, n), st.binary(min_size=1, max_size=4)).map(
        lambda a: payload[: a[0]] + a[1] + payload[a[0] :]
    )
    short = index.map(lambda i: payload[:i])
    return st.one_of(flips, cut, added, short)


def _apply(buf: bytearray, edits: list[tuple[int, int]]) -> bytearray:
    for i, byte in edits:
        buf[i] = byte
    return buf


def assert_agree(cls: type, payload: bytes) -> None:
    """Decoder, checker and pattern against the full path, for one payload."""
    reference = outcome(lambda p: _decode_checked(p, cls), payload)
    assert outcome(decoder_for(cls), payload) == reference
    checked = outcome(validator_for(cls), payload)  # (what it returns means nothing)
    assert checked[0] == reference[0] and (checked[0] == "ok" or checked == reference)
    pattern = canonical_pattern(cls)
    if pattern is not None and pattern.fullmatch(payload):
        assert reference[0] == "ok", (payload, reference)


# The other classes' checkers are their decoders' code (test_codec_malformed compares the two).
@pytest.mark.parametrize("cls", FLAT, ids=lambda c: c.TYPE)
@PROPERTY
@given(data=st.data())
def test_fast_paths_accept_and_refuse_what_the_full_path_does(cls, data):
    payload = encode(data.draw(strategy_for(cls)))
    assert_agree(cls, payload)
    assert_agree(cls, data.draw(mutated(payload)))


@pytest.mark.parametrize("cls", FLAT, ids=lambda c: c.TYPE)
@PROPERTY
@given(data=st.data())
def test_fast_paths_agree_on_values_in_other_msgpack_formats(cls, data):
    """The wire map of a drawn message with values rewritten as other senders may write them:
    ints where floats are expected, floats where ints are, None, a bin for a str, longer strings."""
    wire = msgpack.unpackb(encode(data.draw(strategy_for(cls))))
    name = data.draw(st.sampled_from(sorted(wire)))
    wire[name] = data.draw(
        st.none()
        | st.booleans()
        | st.integers(-(2**63), 2**64 - 1)
        | st.floats()
        | st.text(max_size=40)
        | st.binary(max_size=8)
    )
    assert_agree(cls, pack(wire))


@pytest.mark.parametrize("cls", FLAT, ids=lambda c: c.TYPE)
def test_everyday_payloads_take_the_pattern(cls):
    """What services send (short ASCII strings, everyday numbers) matches, so a relay's check is one match."""
    msg = sample_message(cls)
    msg.src, msg.seq, msg.stamp = "pingsend-12345", 1234, 1712.25
    assert canonical_pattern(cls).fullmatch(encode(msg))
    assert canonical_pattern(cls) is canonical_pattern(cls)  # built once


def test_classes_with_containers_have_no_pattern():
    assert {cls for cls in ALL_MESSAGES if canonical_pattern(cls) is not None} == set(FLAT)


def _pose(**fields: Any) -> dict[str, Any]:
    return minimal_wire(RobotPose) | {"x": 1.5, "y": 2.0, "theta": 0.5, "vel": 0.25, "omega": 0.0} | fields


@pytest.mark.parametrize(
    "wire,matches,valid",
    [
        (_pose(), True, True),
        (_pose(x=8191.999), True, True),  # |x| < 2**13 <= 10 000: the pattern's interval
        (_pose(x=-8191.999), True, True),
        (_pose(x=8192.0), False, True),  # within the bounds, beyond the interval: checked in full
        (_pose(x=10_000.0), False, True),
        (_pose(x=10_000.5), False, False),
        (_pose(x=-0.0), True, True),
        (_pose(x=math.nan), False, False),
        (_pose(x=math.inf), False, False),
        (_pose(x=5e-324), True, True),
        (_pose(x=2), False, True),  # an int in a float field: converted by the full path
        (_pose(src="s" * 31), True, True),
        (_pose(src="s" * 32), False, True),  # longer than one-byte-header strings
        (_pose(src="s" * 129), False, False),
        (_pose(src="é"), False, True),  # not ASCII
        (_pose(robot=""), True, True),  # an empty identifier is allowed
        (_pose(robot="r-0_b"), True, True),
        (_pose(robot="0r"), False, False),
        (_pose(robot="r 0"), False, False),
        (_pose(robot=b"r0"), False, False),  # bin, not str
        (_pose(seq=0), True, True),
        (_pose(seq=2**63 - 1), True, True),
        (_pose(seq=2**63), False, False),
        (_pose(seq=-1), False, False),
        (_pose(seq=True), False, False),
        (_pose(v=2), False, False),
        (_pose(vel=None), False, False),
        (_pose(type="Intent"), False, False),
    ],
    ids=lambda v: repr(v)[:40] if not isinstance(v, dict) else None,
)
def test_pattern_edges(wire, matches, valid):
    payload = pack(wire)
    assert bool(canonical_pattern(RobotPose).fullmatch(payload)) == matches
    assert (outcome(validator_for(RobotPose), payload)[0] == "ok") == valid
    assert_agree(RobotPose, payload)


def test_pattern_follows_the_key_order_of_the_encoder_only():
    wire = msgpack.unpackb(encode(sample_message(RobotPose)))
    shuffled = pack(dict(reversed(list(wire.items()))))
    assert not canonical_pattern(RobotPose).fullmatch(shuffled)
    assert outcome(validator_for(RobotPose), shuffled)[0] == "ok"  # still valid: checked in full
    padded = encode(sample_message(RobotPose), {"pad": b"\0" * 10})
    assert not canonical_pattern(RobotPose).fullmatch(padded) and outcome(validator_for(RobotPose), padded)[0] == "ok"


def test_non_minimal_int_formats_agree():
    """A uint 16 holding 5 is still 5: both paths accept it."""
    payload = pack(_pose()).replace(b"\xa3seq\x07", b"\xa3seq\xcd\x00\x07")
    assert canonical_pattern(RobotPose).fullmatch(payload)
    assert decoder_for(RobotPose)(payload).seq == 7
    assert_agree(RobotPose, payload)


BOUNDS = [
    (None, None),
    (-1e4, 1e4),
    (0.0, 1.0),
    (0.0, 0.5),
    (-3.0, 0.0),
    (-1e-300, 1e-300),
    (0.0, 2.0**-1022),
    (-(2.0**1023), 1.0),
]


@pytest.mark.parametrize("lo,hi", BOUNDS)
@settings(max_examples=100, deadline=None)
@given(bits=st.integers(0, 2**64 - 1) | st.floats().map(lambda x: struct.unpack(">Q", struct.pack(">d", x))[0]))
def test_float_pattern_matches_only_finite_values_within_the_bounds(lo, hi, bits):
    pattern = _float_pattern(lo, hi)
    x = struct.unpack(">d", bits.to_bytes(8, "big"))[0]
    if re.fullmatch(pattern, b"\xcb" + bits.to_bytes(8, "big"), re.S):
        assert math.isfinite(x) and (lo is None or lo <= x) and (hi is None or x <= hi), x


def test_float_pattern_covers_the_everyday_range():
    pose = re.compile(_float_pattern(-1e4, 1e4), re.S)
    for x in (0.0, 1.0, -1.0, 0.1, 8191.5, -8191.5, 1e-200):
        assert pose.fullmatch(b"\xcb" + struct.pack(">d", x)), x
    assert _float_pattern(0.5, 1.0) is None and _float_pattern(-1.0, -0.5) is None  # bounds excluding 0


# Every msgpack integer format: (first byte, struct format of what follows, lowest, highest).
INT_ENCODINGS = [
    (None, ">B", 0, 127),
    (None, ">b", -32, -1),
    (b"\xcc", ">B", 0, 2**8 - 1),
    (b"\xcd", ">H", 0, 2**16 - 1),
    (b"\xce", ">I", 0, 2**32 - 1),
    (b"\xcf", ">Q", 0, 2**64 - 1),
    (b"\xd0", ">b", -(2**7), 2**7 - 1),
    (b"\xd1", ">h", -(2**15), 2**15 - 1),
    (b"\xd2", ">i", -(2**31), 2**31 - 1),
    (b"\xd3", ">q", -(2**63), 2**63 - 1),
]


@pytest.mark.parametrize("lo,hi", [(None, None), (0, 2**63 - 1), (0, 2**31), (-5, 5), (-(2**63), -1)])
@settings(max_examples=100, deadline=None)
@given(n=st.integers(-(2**63), 2**64 - 1) | st.sampled_from([0, 127, 128, -32, -33, 255, 256, 2**63 - 1, 2**63]))
def test_int_pattern_matches_only_values_within_the_bounds(lo, hi, n):
    piece = _value_pattern(int, {"lo": lo, "hi": hi}, lambda v, path: v)
    if piece is None:  # no format lies wholly within the bounds: every such int is checked in full
        assert (lo, hi) == (-5, 5)
        return
    for first, fmt, least, most in INT_ENCODINGS:  # every format that holds n, not only the shortest
        if least <= n <= most:
            encoded = (first or b"") + struct.pack(fmt, n)
            assert msgpack.unpackb(encoded) == n
            if re.fullmatch(piece[0], encoded, re.S):
                assert (lo is None or lo <= n) and (hi is None or n <= hi), (n, encoded)


def test_encoding_from_many_threads_at_once_gives_each_its_own_bytes():
    """Packers are taken from a shared pool: never two encoders on one at the same time."""
    results: dict[int, list[bytes]] = {}

    def work(k: int) -> None:
        results[k] = [encode(RobotPose(robot=f"r{k}", x=float(i), y=0.0, theta=0.0, seq=i)) for i in range(3000)]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k, payloads in results.items():
        assert [decoder_for(RobotPose)(p).x for p in payloads] == [float(i) for i in range(3000)]
        assert {decoder_for(RobotPose)(p).robot for p in payloads} == {f"r{k}"}
