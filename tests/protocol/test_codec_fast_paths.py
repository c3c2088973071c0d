"""The codec's fast path agrees with its full path.

The decoder and checker of every message class (msgspec's envelope and typed decoding) must accept
and refuse exactly what the full path (``_decode_checked``, every check in order) accepts and
refuses, with the same error. Checked on drawn messages, on their payloads mutated byte by byte,
and on the edges of a pose's fields.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.codec import _decode_checked, decoder_for, encode, validator_for
from protocol.errors import ProtocolError
from protocol.messages import ALL_MESSAGES, Clock, DoorState, FeedbackAck, RobotPose
from tests.protocol.strategies import minimal_wire, pack, sample_message, strategy_for

PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FLAT = [Clock, DoorState, FeedbackAck, RobotPose]  # every field a scalar


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
    """Decoder and checker against the full path, for one payload."""
    reference = outcome(lambda p: _decode_checked(p, cls), payload)
    assert outcome(decoder_for(cls), payload) == reference
    checked = outcome(validator_for(cls), payload)  # (what it returns means nothing)
    assert checked[0] == reference[0] and (checked[0] == "ok" or checked == reference)


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
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


def _pose(**fields: Any) -> dict[str, Any]:
    return minimal_wire(RobotPose) | {"x": 1.5, "y": 2.0, "theta": 0.5, "vel": 0.25, "omega": 0.0} | fields


@pytest.mark.parametrize(
    "wire,valid",
    [
        (_pose(), True),
        (_pose(x=8191.999), True),
        (_pose(x=-8191.999), True),
        (_pose(x=8192.0), True),
        (_pose(x=10_000.0), True),
        (_pose(x=10_000.5), False),
        (_pose(x=-0.0), True),
        (_pose(x=math.nan), False),
        (_pose(x=math.inf), False),
        (_pose(x=5e-324), True),
        (_pose(x=2), True),  # an int in a float field: converted by the full path
        (_pose(src="s" * 31), True),
        (_pose(src="s" * 32), True),
        (_pose(src="s" * 129), False),
        (_pose(src="é"), True),  # not ASCII
        (_pose(robot=""), True),  # an empty identifier is allowed
        (_pose(robot="r-0_b"), True),
        (_pose(robot="0r"), False),
        (_pose(robot="r 0"), False),
        (_pose(robot=b"r0"), False),  # bin, not str
        (_pose(seq=0), True),
        (_pose(seq=2**63 - 1), True),
        (_pose(seq=2**63), False),
        (_pose(seq=-1), False),
        (_pose(seq=True), False),
        (_pose(v=2), False),
        (_pose(vel=None), False),
        (_pose(type="Intent"), False),
    ],
    ids=lambda v: repr(v)[:40] if not isinstance(v, dict) else None,
)
def test_pose_edges(wire, valid):
    payload = pack(wire)
    assert (outcome(validator_for(RobotPose), payload)[0] == "ok") == valid
    assert_agree(RobotPose, payload)


def test_any_key_order_and_unknown_fields_are_valid():
    wire = msgpack.unpackb(encode(sample_message(RobotPose)))
    shuffled = pack(dict(reversed(list(wire.items()))))
    assert outcome(validator_for(RobotPose), shuffled)[0] == "ok"
    padded = encode(sample_message(RobotPose), {"pad": b"\0" * 10})
    assert outcome(validator_for(RobotPose), padded)[0] == "ok"


def test_non_minimal_int_formats_agree():
    """A uint 16 holding 5 is still 5: both paths accept it."""
    payload = pack(_pose()).replace(b"\xa3seq\x07", b"\xa3seq\xcd\x00\x07")
    assert payload != pack(_pose())
    assert decoder_for(RobotPose)(payload).seq == 7
    assert_agree(RobotPose, payload)


def test_encoding_from_many_threads_at_once_gives_each_its_own_bytes():
    """One shared encoder and decoder serve every thread: each gets its own bytes and messages."""
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
