"""Malformed payloads are refused with a ProtocolError that names the problem.

The cases are generated from the message declarations (every envelope field, every required field,
every field's type and size limit), so each message type is covered field by field.
"""

from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.codec import decode, encode, validator_for
from protocol.errors import ProtocolError
from protocol.messages import ALL_MESSAGES, CameraTruth, Event, Intent, RobotPose, RobotStatus, TeamPlan
from tests.protocol.strategies import fields_of, is_required, minimal_wire, oversized_value, pack, wrong_type_value

ENVELOPE = ("v", "type", "src", "seq", "stamp")


def refused(payload: object, cls: type | None = None) -> ProtocolError:
    """Decode, expecting a refusal; returns the error for the caller's checks. With a class, the
    class's check alone (what a relay runs) must refuse it with the very same error."""
    with pytest.raises(ProtocolError) as info:
        decode(payload, cls)  # type: ignore[arg-type]
    if cls is not None:
        with pytest.raises(ProtocolError) as checked:
            validator_for(cls)(payload)
        assert (checked.value.field, str(checked.value)) == (info.value.field, str(info.value))
    return info.value


def _cases(kind: str) -> list:
    """(cls, field name, hint, meta) for every field of every message matching ``kind``."""
    out = []
    for cls in ALL_MESSAGES:
        for f, hint in fields_of(cls):
            if kind == "required" and not is_required(f):
                continue
            if kind == "float" and hint is not float:
                continue
            if kind == "oversized" and oversized_value(hint, f.metadata) is None:
                continue
            out.append(pytest.param(cls, f.name, hint, f.metadata, id=f"{cls.TYPE}.{f.name}"))
    return out


# ---------------------------------------------------------------------------- missing fields


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
@pytest.mark.parametrize("name", ENVELOPE)
def test_missing_envelope_field(cls, name):
    data = minimal_wire(cls)
    del data[name]
    for expected in (cls, None):
        err = refused(pack(data), expected)
        assert err.field == name
        assert "missing" in err.problem
        assert name in str(err)


@pytest.mark.parametrize("cls,name,hint,meta", _cases("required"))
def test_missing_required_field(cls, name, hint, meta):
    data = minimal_wire(cls)
    del data[name]
    err = refused(pack(data), cls)
    assert (err.field, err.problem, err.msg_type) == (name, "required field is missing", cls.TYPE)
    assert str(err) == f"{cls.TYPE}.{name}: required field is missing"


def test_missing_field_in_a_nested_record_is_named_with_its_path():
    data = minimal_wire(TeamPlan)
    del data["robots"]["k"][0]["start"]
    err = refused(pack(data), TeamPlan)
    assert err.field == "robots.k[0].start"


# ---------------------------------------------------------------------------- wrong types


@pytest.mark.parametrize("cls,name,hint,meta", _cases("all"))
def test_wrong_type_for_each_field(cls, name, hint, meta):
    data = minimal_wire(cls)
    data[name] = wrong_type_value(hint)
    err = refused(pack(data), cls)
    assert err.field == name or err.field.startswith((f"{name}.", f"{name}[")), err
    assert err.msg_type == cls.TYPE


@pytest.mark.parametrize(
    "name,value,problem",
    [
        ("seq", 1.5, "expected int, got float"),
        ("seq", True, "expected int, got bool"),
        ("x", True, "expected float, got bool"),
        ("x", None, "expected float, got NoneType"),
        ("robot", b"r0", "expected str, got bytes"),
        ("src", ["a"], "expected str, got list"),
    ],
)
def test_wrong_type_message_says_what_was_expected(name, value, problem):
    data = minimal_wire(RobotPose) | {name: value}
    assert refused(pack(data), RobotPose).problem == problem


def test_wrong_element_types_inside_containers():
    data = minimal_wire(Intent)
    data["trajectory"] = [[0.0, 1.0, 2.0, 3.0], [0.0, "1", 2.0, 3.0]]
    assert refused(pack(data), Intent).field == "trajectory[1]"
    data["trajectory"] = [[0.0, 1.0, 2.0, True]]
    assert refused(pack(data), Intent).field == "trajectory[0]"
    data = minimal_wire(RobotStatus) | {"carrying": ["o1", 5]}
    assert refused(pack(data), RobotStatus).field == "carrying[1]"


# ---------------------------------------------------------------------------- values out of range


@pytest.mark.parametrize("cls,name,hint,meta", _cases("float"))
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_floats_refused(cls, name, hint, meta, bad):
    data = minimal_wire(cls) | {name: bad}
    err = refused(pack(data), cls)
    assert err.field == name and "finite" in err.problem


def test_non_finite_values_inside_rows_and_json_refused():
    data = minimal_wire(Intent)
    data["trajectory"] = [[0.0, 1.0, 2.0, 3.0], [0.0, 1.0, math.nan, 3.0]]
    err = refused(pack(data), Intent)
    assert err.field == "trajectory[1][2]" and "finite" in err.problem
    data = minimal_wire(Event) | {"data": {"metrics": [1.0, math.inf]}}
    assert refused(pack(data), Event).field == "data.metrics[1]"
    data = minimal_wire(CameraTruth) | {"quaternion": [0.0, 0.0, 0.0, -math.inf]}
    assert refused(pack(data), CameraTruth).field == "quaternion[3]"


@pytest.mark.parametrize(
    "name,value,problem",
    [
        ("x", 1e5, "above the maximum"),
        ("y", -1e5, "below the minimum"),
        ("seq", -1, "below the minimum"),
        ("robot", "0r", "not an identifier"),
        ("robot", "r 0", "not an identifier"),
        ("robot", "r" * 65, "not an identifier"),
    ],
)
def test_out_of_range_values(name, value, problem):
    err = refused(pack(minimal_wire(RobotPose) | {name: value}), RobotPose)
    assert err.field == name and problem in err.problem


def test_choices_row_lengths_and_fixed_lengths():
    err = refused(pack(minimal_wire(RobotStatus) | {"state": "flying"}), RobotStatus)
    assert err.field == "state" and "'flying' is not one of" in err.problem
    err = refused(pack(minimal_wire(Intent) | {"trajectory": [[0.0, 1.0, 2.0]]}), Intent)
    assert err.field == "trajectory[0]" and "row of 4 numbers" in err.problem
    err = refused(pack(minimal_wire(CameraTruth) | {"position": [1.0, 2.0]}), CameraTruth)
    assert err.field == "position" and "expected 3 items, got 2" in err.problem


# ---------------------------------------------------------------------------- sizes


@pytest.mark.parametrize("cls,name,hint,meta", _cases("oversized"))
def test_oversized_field(cls, name, hint, meta):
    data = minimal_wire(cls) | {name: oversized_value(hint, meta)}
    payload = pack(data)
    err = refused(payload, cls)
    if len(payload) > cls.MAX_SIZE:
        # Too big for the message as a whole: refused before anything is parsed.
        assert err.field == "" and "exceeds the limit" in err.problem
    else:
        assert err.field == name and "exceeds the limit" in err.problem


def test_payload_over_the_message_size_limit_is_refused_unparsed():
    data = minimal_wire(RobotPose) | {"junk": "x" * RobotPose.MAX_SIZE}
    err = refused(pack(data), RobotPose)
    assert err.field == "" and f"exceeds the limit {RobotPose.MAX_SIZE}" in err.problem
    # Untyped decoding bounds by the largest message, then by the named type's own limit.
    assert "exceeds the limit" in refused(pack(data)).problem


def test_oversized_map_key_and_json_nesting():
    from protocol.messages import Feedback

    err = refused(pack(minimal_wire(Feedback) | {"params": {"k" * 300: 1}}), Feedback)
    assert err.field == "params" and "longer than 256" in err.problem
    nested: object = 1
    for _ in range(10):
        nested = [nested]
    err = refused(pack(minimal_wire(Event) | {"data": nested}), Event)
    assert err.field.startswith("data") and "nested deeper" in err.problem


# ---------------------------------------------------------------------------- version and type


@pytest.mark.parametrize(
    "v,problem",
    [
        (2, "schema version 2 is newer than the supported 1"),
        (99, "newer"),
        (0, "schema version 0 is not valid"),
        (-1, "not valid"),
        ("1", "missing or not an integer"),
        (1.0, "missing or not an integer"),
        (True, "missing or not an integer"),
        (None, "missing or not an integer"),
    ],
)
def test_wrong_or_newer_version(v, problem):
    for cls in (RobotPose, TeamPlan):
        err = refused(pack(minimal_wire(cls) | {"v": v}), cls)
        assert err.field == "v" and problem in err.problem and err.msg_type == cls.TYPE


def test_unknown_type():
    err = refused(pack(minimal_wire(RobotPose) | {"type": "Teleport"}), RobotPose)
    assert err.field == "type" and "unknown message type 'Teleport'" in err.problem
    assert refused(pack(minimal_wire(RobotPose) | {"type": 5})).field == "type"


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
def test_wrong_type_for_the_expected_class(cls):
    other = RobotPose if cls is not RobotPose else Intent
    err = refused(pack(minimal_wire(other)), cls)
    assert err.field == "type" and err.problem == f"expected {cls.TYPE}, got {other.TYPE}"


# ---------------------------------------------------------------------------- not even a message


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
def test_every_truncation_refused(cls):
    payload = pack(minimal_wire(cls))
    for cut in range(len(payload)):
        err = refused(payload[:cut], cls)
        assert err.field == "" and ("empty" in err.problem or "not a valid msgpack" in err.problem)


@pytest.mark.parametrize("value", [[1, 2], 1, "RobotPose", None, 1.5, b"bytes", True])
def test_non_map_payloads(value):
    err = refused(pack(value), RobotPose)
    assert err.field == "" and "must be a map" in err.problem


@pytest.mark.parametrize(
    "payload,problem",
    [
        (b"", "empty payload"),
        (pack(minimal_wire(RobotPose)) + b"\x00", "not a valid msgpack"),  # trailing bytes
        (b"\xc1", "not a valid msgpack"),  # a byte msgpack never uses
        (msgpack.packb({1: 2}), "not a valid msgpack"),  # non-string map key
        (msgpack.packb(msgpack.ExtType(5, b"x")), "not a valid msgpack"),  # extension types
        (b"\x91" * 5000 + b"\x00", "not a valid msgpack"),  # nesting deep enough to blow a stack
    ],
)
def test_broken_msgpack(payload, problem):
    err = refused(payload, RobotPose)
    assert err.field == "" and problem in err.problem


@pytest.mark.parametrize("payload", ["a string", 123, None, [b"x"]])
def test_non_bytes_payload(payload):
    err = refused(payload, RobotPose)
    assert "payload must be bytes" in err.problem


def test_bytearray_and_memoryview_payloads_are_accepted():
    payload = encode(RobotPose(robot="r0", x=1.0, y=2.0, theta=0.0))
    assert decode(bytearray(payload), RobotPose) == decode(memoryview(payload), RobotPose) == decode(payload, RobotPose)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_never_crash_the_decoder(payload):
    for cls in (RobotPose, Intent, None):
        try:
            decode(payload, cls)
        except ProtocolError:
            pass


_msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=10)
    | st.binary(max_size=10),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from(ALL_MESSAGES),
    st.dictionaries(
        st.sampled_from(["x", "robot", "trajectory", "data", "args", "src", "seq", "stamp", "kind", "state"]),
        _msgpack_values,
        max_size=6,
    ),
)
def test_random_field_values_are_refused_or_valid(cls, overrides):
    """Random msgpack data in real field names of a well-formed envelope: only ProtocolError, or a message."""
    data = minimal_wire(cls) | overrides
    try:
        msg = decode(pack(data), cls)
    except ProtocolError as exc:
        assert exc.msg_type == cls.TYPE and (exc.field in data or exc.field.split(".")[0].split("[")[0] in data)
    else:
        assert type(msg) is cls


def test_every_required_field_is_checked():
    """The generated tests above cover each message's required fields: make sure there are some."""
    assert any(f.required for f, _ in fields_of(RobotPose))
    assert {name for name in ("robot", "x", "y", "theta")} <= {f.name for f, _ in fields_of(RobotPose) if f.required}
