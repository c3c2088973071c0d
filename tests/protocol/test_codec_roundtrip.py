"""Every message type survives encode → decode unchanged (property-based, strategies derived
from the message declarations themselves)."""

from __future__ import annotations

import math

import msgpack
import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.codec import decode, decoder_for, encode, encoder_for, validator_for
from protocol.messages import ALL_MESSAGES, BY_TYPE, Intent, RobotPose
from protocol.schema import record_to_wire
from tests.protocol.strategies import fields_of, minimal_wire, pack, sample_message, strategy_for

ROUND_TRIP = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
@ROUND_TRIP
@given(data=st.data())
def test_every_message_round_trips(cls, data):
    msg = data.draw(strategy_for(cls))
    payload = encode(msg)
    assert decode(payload, cls) == msg
    validator_for(cls)(payload)  # what decodes also passes the check alone (it raises otherwise)
    # Without an expected type the payload's own `type` picks the class.
    untyped = decode(payload)
    assert type(untyped) is cls and untyped == msg


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
def test_envelope_is_on_the_wire(cls):
    data = msgpack.unpackb(encode(sample_message(cls)))
    assert data["v"] == cls.VERSION and data["type"] == cls.TYPE
    assert (data["src"], data["seq"], data["stamp"]) == ("tester-1", 7, 12.5)
    # Exactly the declared fields plus v and type: nothing leaks onto the wire.
    assert set(data) == {f.name for f, _ in fields_of(cls)} | {"v", "type"}


def test_types_are_unique_and_registered():
    assert len(BY_TYPE) == len(ALL_MESSAGES)
    assert all(BY_TYPE[cls.TYPE] is cls for cls in ALL_MESSAGES)


@pytest.mark.parametrize("cls", ALL_MESSAGES, ids=lambda c: c.TYPE)
def test_per_class_paths_agree_with_the_generic_ones(cls):
    """The per-class encoder/decoder give what the generic record functions give."""
    msg = sample_message(cls)
    wire = record_to_wire(msg)
    assert msgpack.unpackb(encoder_for(cls)(msg)) == {**wire, "v": cls.VERSION, "type": cls.TYPE}
    assert decoder_for(cls)(pack(minimal_wire(cls))) == msg


def test_conversions_defaults_and_unknown_fields_decode_alike():
    """An int in a float field is converted, a field left out takes its default, an unknown field
    is ignored: each decodes to the same pose."""
    base = minimal_wire(RobotPose) | {"x": 1.5, "vel": 0.5, "omega": -0.25}
    fast = decode(pack(base), RobotPose)
    assert (fast.x, fast.vel, fast.omega) == (1.5, 0.5, -0.25)
    assert decode(pack(base | {"x": 2}), RobotPose) == msgspec.structs.replace(fast, x=2.0)
    assert decode(pack({k: v for k, v in base.items() if k != "omega"}), RobotPose) == msgspec.structs.replace(
        fast, omega=0.0
    )
    assert decode(pack(base | {"unknown": [1, 2]}), RobotPose) == fast


def test_int_in_a_float_field_decodes_as_float():
    data = minimal_wire(RobotPose) | {"x": 3, "y": -2}
    pose = decode(pack(data), RobotPose)
    assert (pose.x, pose.y) == (3.0, -2.0) and type(pose.x) is float and type(pose.y) is float


def test_missing_optional_fields_take_their_defaults():
    required = {f.name for f, _ in fields_of(RobotPose) if f.required}
    data = {k: v for k, v in minimal_wire(RobotPose).items() if k in required | {"v", "type", "src", "seq", "stamp"}}
    pose = decode(pack(data), RobotPose)
    assert (pose.vel, pose.omega) == (0.0, 0.0)


def test_extreme_valid_values_round_trip():
    pose = RobotPose(
        robot="r" * 64,
        x=-10_000.0,
        y=10_000.0,
        theta=-1000.0,
        vel=100.0,
        omega=-100.0,
        src="s" * 128,
        seq=2**63 - 1,
        stamp=-1e10,
    )
    assert decode(encode(pose), RobotPose) == pose
    tiny = RobotPose(robot="r0", x=5e-324, y=-0.0, theta=0.0, src="", seq=0, stamp=0.0)
    back = decode(encode(tiny), RobotPose)
    assert back.x == 5e-324 and math.copysign(1.0, back.y) == -1.0


def test_a_200_point_intent_round_trips():
    trajectory = [[100.0 + 0.1 * i, 1.0 + 0.05 * i, 5.0, 0.001 * i] for i in range(200)]
    intent = Intent(
        robot="r0",
        plan_id=3,
        action_id=4,
        action="approach",
        args=["d1"],
        trajectory=trajectory,
        src="planner-1",
        seq=9,
        stamp=100.0,
    )
    assert decode(encode(intent), Intent) == intent


def test_unknown_extra_fields_are_ignored_at_every_level():
    from protocol.messages import TeamPlan

    data = minimal_wire(TeamPlan)
    data["added_in_a_later_minor_revision"] = {"anything": [1, 2]}
    for steps in data["robots"].values():
        steps[0]["future_field"] = "ignored too"
    data["openings"][0]["another"] = 1.5
    assert decode(pack(data), TeamPlan) == sample_message(TeamPlan)


def test_encode_with_extra_fields_is_decoded_as_without():
    pose = sample_message(RobotPose)
    padded = encode(pose, {"pad": b"\x00" * 500})
    assert len(padded) > len(encode(pose)) + 500
    assert decode(padded, RobotPose) == pose
    with pytest.raises(ValueError, match="shadow"):
        encode(pose, {"x": 1.0})
    with pytest.raises(ValueError, match="shadow"):
        encode(pose, {"type": "Intent"})


def test_camera_frame_gravity_is_optional_and_old_frames_still_decode():
    from protocol.messages import CameraFrame

    old = msgpack.packb(
        {
            "v": CameraFrame.VERSION,
            "type": "CameraFrame",
            "src": "sim",
            "seq": 3,
            "stamp": 1.0,
            "camera": "tablet",
            "jpeg": b"\xff\xd8",
            "width": 640,
            "height": 480,
            "intrinsics": [500.0, 500.0, 320.0, 240.0],
            "distortion": [0.0] * 5,
        }
    )
    frame = decode(old, CameraFrame)
    assert frame.gravity == [] and frame.width == 640
    new = CameraFrame(
        camera="tablet",
        jpeg=b"\xff\xd8",
        width=640,
        height=480,
        intrinsics=[500.0, 500.0, 320.0, 240.0],
        gravity=[0.1, 9.8, 0.2],
    )
    assert decode(encode(new), CameraFrame).gravity == [0.1, 9.8, 0.2]
    bad = msgspec.structs.replace(new, gravity=[0.0, 9.8])
    with pytest.raises(Exception, match="gravity"):
        decode(encode(bad), CameraFrame)


def test_numpy_values_go_on_the_wire_as_plain_numbers():
    """Poses and camera parameters are often computed with numpy: they encode as msgpack numbers."""
    import numpy as np

    from protocol.messages import CameraTruth

    pose = RobotPose(robot="r0", x=np.float64(1.5), y=np.float32(2.0), theta=np.int64(0))
    assert msgpack.unpackb(encode(pose))["x"] == 1.5 and decode(encode(pose), RobotPose).y == 2.0
    truth = CameraTruth(camera="c", frame_seq=1, position=np.array([1.0, 2.0, 3.0]), quaternion=[0.0, 0.0, 0.0, 1.0])
    assert msgpack.unpackb(encode(truth))["position"] == [1.0, 2.0, 3.0]
    with pytest.raises(TypeError, match="cannot put a object on the wire"):
        encode(RobotPose(robot="r0", x=object(), y=0.0, theta=0.0))  # type: ignore[arg-type]
