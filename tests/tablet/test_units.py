"""The tablet server's pieces without processes: the page protocol and its limits, the camera
model of a browser stream (scaling a calibration, the default), the token and Origin checks."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from protocol.messages import Overlay, Primitive
from runtime.frames import look_at
from services.ar_client.project import Intrinsics, Projector
from services.ar_client.web import wire
from services.ar_client.web.intrinsics import CameraModel, default_intrinsics, load_intrinsics, scaled, write_intrinsics
from services.ar_client.web.security import COOKIE, TokenBucket, new_token, origin_allowed, token_matches
from services.ar_client.web.wire import Violation


@pytest.mark.parametrize("progressive", [False, True])
@pytest.mark.parametrize("size", [(640, 480), (1280, 720), (17, 33)])
def test_jpeg_size_reads_the_header_of_real_jpegs(size, progressive):
    image = np.random.default_rng(0).integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
    data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_PROGRESSIVE, int(progressive)])[1].tobytes()
    assert wire.jpeg_size(data) == size


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"\xff\xd8",
        b"GIF89a....",
        b"\xff\xd8\xff\xe0\x00\x01",
        b"\xff\xd8\x00\x00\x00\x00",
        b"\xff\xd8\xff\xda\x00\x08abcdef",
    ],
)
def test_jpeg_size_refuses_what_is_not_a_jpeg_header(data):
    with pytest.raises(Violation) as err:
        wire.jpeg_size(data)
    assert err.value.code == wire.CLOSE_UNSUPPORTED


def test_frames_are_bounded_before_decoding():
    ok = cv2.imencode(".jpg", np.zeros((480, 640, 3), np.uint8))[1].tobytes()
    frame = wire.parse_frame(wire.pack_frame(7, ok))
    assert (frame.seq, frame.width, frame.height, frame.jpeg) == (7, 640, 480, ok)
    huge = bytes.fromhex("ffd8ffc0000b08ea60ea6001011100")  # claims 60000x60000 in 15 bytes
    tiny = cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes()
    for payload, code in (
        (wire.pack_frame(1, huge), wire.CLOSE_TOO_BIG),
        (wire.pack_frame(1, tiny), wire.CLOSE_TOO_BIG),
        (wire.pack_frame(1, ok, b"XXXX"), wire.CLOSE_UNSUPPORTED),
        (b"ARF1", wire.CLOSE_UNSUPPORTED),
        (wire.pack_frame(1, b"\xff\xd8" + bytes(wire.MAX_FRAME_BYTES)), wire.CLOSE_TOO_BIG),
    ):
        with pytest.raises(Violation) as err:
            wire.parse_frame(payload)
        assert err.value.code == code


def test_text_and_feedback_shapes():
    assert wire.parse_text('{"type": "ping", "t": 1}') == wire.Ping(t=1)
    for text, code in (
        ("{", wire.CLOSE_BAD_DATA),
        ("[]", wire.CLOSE_POLICY),
        ('{"type": 3}', wire.CLOSE_POLICY),
        ("[" * 100000, wire.CLOSE_TOO_BIG),
        ('{"type": "x", "a": ' + "[" * 5000 + "]" * 5000 + "}", wire.CLOSE_BAD_DATA),
    ):
        with pytest.raises(Violation) as err:
            wire.parse_text(text)
        assert err.value.code == code, text[:20]
    request = wire.parse_text(
        json.dumps(
            {"type": "feedback", "id": 3, "kind": "door_unavailable", "params": {"door": "d_storage", "minutes": 30}}
        )
    )
    assert (request.id, request.kind, request.params) == (3, "door_unavailable", {"door": "d_storage", "minutes": 30})
    for bad in (
        {"id": -1, "kind": "k", "params": {}},
        {"id": True, "kind": "k", "params": {}},
        {"id": 1, "kind": "", "params": {}},
        {"id": 1, "kind": "k", "params": []},
        {"id": 1, "kind": "k", "params": {"a": [1]}},
        {"id": 1, "kind": "k", "params": {"a": True}},
        {"id": 1, "kind": "k", "params": {"a": "x" * 65}},
        {"id": 1, "kind": "k", "params": {"a": float("nan")}},
        {"id": 1, "kind": "k", "params": {f"p{i}": 1 for i in range(33)}},
        {"id": 1, "kind": "k", "params": {"a": 2**60}},
    ):
        with pytest.raises(Violation) as err:
            wire.parse_text(json.dumps({"type": "feedback", **bad}))
        assert err.value.code in (wire.CLOSE_POLICY, wire.CLOSE_BAD_DATA)  # NaN is not JSON


def test_overlay_message_keeps_the_world_and_drops_status_and_ui():
    overlay = Overlay(
        camera="tablet-1",
        frame_seq=9,
        width=640,
        height=480,
        ok=True,
        tags=[1, 2],
        reprojection_rmse=0.1234,
        primitives=[
            Primitive(kind="polyline", points=[[1.234, 2.0], [3.0, 4.06]], color=[1, 2, 3, 255], layer="robot:r0"),
            Primitive(kind="text", points=[[5, 5]], text="pose", layer="status"),
            Primitive(kind="polygon", points=[[0, 0], [1, 0], [1, 1]], layer="ui"),
            Primitive(kind="circle", points=[[9, 9]], radius=4, style="xray", layer="intent:r0"),
        ],
    )
    data = json.loads(wire.overlay_json(overlay, intrinsics="calibrated", server_ms=12.345))
    assert data["seq"] == 9 and data["ok"] and data["rmse"] == 0.123 and data["server_ms"] == 12.3
    assert [p["l"] for p in data["primitives"]] == ["robot:r0", "intent:r0"]
    assert data["primitives"][0]["p"] == [[1.2, 2.0], [3.0, 4.1]] and data["primitives"][1]["s"] == "xray"


def test_a_scaled_calibration_projects_like_the_original():
    full = Intrinsics(1000.0, 1002.0, 640.3, 358.9, 1280, 720, (0.1, -0.05, 0.001, 0.0005, 0.0))
    pose = look_at([0.0, 0.0, 1.2], [3.0, 0.5, 1.0])
    points = np.array([[3.0, 0.5, 1.0], [3.0, -0.5, 1.4], [2.5, 1.0, 0.2]])
    uv_full, _ = Projector(pose, full).project_points(points)
    half = scaled(full, 640, 360)
    uv_half, _ = Projector(pose, half).project_points(points)
    # Pixel centres at integers: a point at u in the full image is at (u + 0.5) / 2 - 0.5 in the half one.
    assert np.allclose((uv_full + 0.5) / 2 - 0.5, uv_half, atol=1e-9)
    assert scaled(full, 640, 480) is None  # another aspect: another sensor crop


def test_camera_model_says_where_its_intrinsics_come_from(tmp_path):
    path = tmp_path / "intrinsics.json"
    write_intrinsics(path, Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720), rms_px=0.2)
    calibrated = load_intrinsics(path)
    model = CameraModel(calibrated)
    K, source = model.for_size(640, 360)
    assert K.fx == 500.0 and source.startswith("calibrated")
    K, source = model.for_size(640, 480)
    assert source.startswith("default") and "another aspect" in source and K == default_intrinsics(640, 480)
    K, source = CameraModel().for_size(1280, 720)
    assert "not calibrated" in source
    # The default: the documented horizontal field of view.
    assert np.isclose(2 * np.degrees(np.arctan(K.width / 2 / K.fx)), 62.0)
    path.write_text('{"intrinsics": [1, 2]}')
    with pytest.raises(ValueError, match="6 numbers"):
        load_intrinsics(path)
    path.write_text("not json")
    with pytest.raises(ValueError, match="intrinsics.json"):
        load_intrinsics(path)


def test_token_and_origin_checks():
    token = new_token()
    assert len(token) >= 24 and new_token() != token
    assert token_matches(token, {"token": token}, {})
    assert token_matches(token, {}, {COOKIE: token})
    assert not token_matches(
        token, {"token": "wrong"}, {COOKIE: token}
    )  # an explicit wrong token is not rescued by the cookie
    assert not token_matches(token, {}, {}) and not token_matches(token, {"token": token[:-1]}, {})
    assert token_matches(token, {"token": token}, {COOKIE: "stale"})
    assert not token_matches(token, {"token": "é"}, {})
    assert origin_allowed("https://10.0.0.5:8443", "10.0.0.5:8443", "https")
    assert not origin_allowed("https://evil.example", "10.0.0.5:8443", "https")
    assert not origin_allowed("http://10.0.0.5:8443", "10.0.0.5:8443", "https")
    assert not origin_allowed(None, "10.0.0.5:8443", "https") and not origin_allowed("null", "10.0.0.5:8443", "https")
    assert origin_allowed("https://kiosk.lan/", "10.0.0.5:8443", "https", ["https://kiosk.lan"])


def test_token_bucket_limits_bursts_then_refills():
    bucket = TokenBucket(rate=1000.0, burst=5)
    assert all(bucket.take() for _ in range(5))
    slow = TokenBucket(rate=0.001, burst=3)
    assert [slow.take() for _ in range(4)] == [True, True, True, False]


def test_frames_carry_gravity_and_old_frames_still_parse():
    ok = cv2.imencode(".jpg", np.zeros((48, 64, 3), np.uint8))[1].tobytes()
    frame = wire.parse_frame(wire.pack_frame(9, ok, gravity=(0.5, 9.7, -1.0)))
    assert frame.seq == 9 and frame.jpeg == ok and frame.gravity == pytest.approx((0.5, 9.7, -1.0))
    assert wire.parse_frame(wire.pack_frame(9, ok)).gravity is None  # ARF1: no gravity
    unknown = wire.HEADER.pack(wire.GRAVITY_FRAME_MAGIC, 3) + wire.GRAVITY.pack(float("nan"), 0.0, 0.0) + ok
    assert wire.parse_frame(unknown).gravity is None and wire.parse_frame(unknown).jpeg == ok
    with pytest.raises(wire.Violation) as absurd:
        wire.parse_frame(wire.pack_frame(1, ok, gravity=(0.0, 500.0, 0.0)))
    assert absurd.value.code == wire.CLOSE_POLICY and "gravity" in absurd.value.reason
    with pytest.raises(wire.Violation):
        wire.parse_frame(wire.GRAVITY_FRAME_MAGIC + b"\x01\x00\x00\x00\x00")  # cut inside the gravity
