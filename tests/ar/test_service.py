"""The AR client as a real process on Zenoh: frames in over ``camera/<cid>/frame``, Overlays out on
``ar/<cid>/overlay``; bad frames counted and dropped; a folder source with recording; clean exit."""

from __future__ import annotations

import json
import signal
import time

import cv2
import numpy as np
import pytest

from protocol.messages import CameraFrame, Event, Overlay, RobotPose
from runtime.frames import look_at
from services.ar_client.synth import render
from tests.ar.helpers import HALL_FILE, HD, VGA, site
from tests.conftest import wait_for_message
from tests.procs import arroch

pytestmark = pytest.mark.integration

TRUTH = look_at([3.5, 5.5, 1.3], [0.05, 5.0, 1.1])


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 92])
    assert ok
    return data.tobytes()


def _frame(K, jpeg: bytes) -> CameraFrame:  # noqa: ANN001
    return CameraFrame(camera="tab1", jpeg=jpeg, width=K.width, height=K.height, intrinsics=[K.fx, K.fy, K.cx, K.cy])


def _stats(client, namespace: str) -> dict:  # noqa: ANN001
    replies = client.query(client.keys.stats("ar", "*"), Event, timeout=3.0)
    assert replies, "the AR client does not answer its stats query"
    return replies[0].data


def test_frames_in_overlays_out_and_bad_frames_do_not_kill_it(router, namespace, client, spawn):
    ar = spawn(
        arroch(
            "ar",
            "--site",
            str(HALL_FILE),
            "--namespace",
            namespace,
            "--connect",
            router,
            "--clock",
            "wall",
            "--camera",
            "tab1",
        ),
        name="ar",
    )
    ar.wait_for("waiting for frames", timeout=30)
    overlays = client.collect(client.keys.overlay("tab1"), Overlay)
    time.sleep(0.5)  # let the subscriptions meet through the router
    client.publish(client.keys.robot_pose("r0"), RobotPose(robot="r0", x=2.0, y=5.0, theta=0.0))
    time.sleep(0.2)
    frame = render(site("hall"), TRUTH, HD)
    client.publish(client.keys.camera_frame("tab1"), _frame(HD, _jpeg(frame.image)))
    first = wait_for_message(overlays, timeout=15)
    assert first.ok and first.width == HD.width and len(first.tags) >= 4
    assert np.linalg.norm(np.array(first.position) - TRUTH.position) < 0.01
    layers = {p.layer for p in first.primitives}
    assert {"robot:r0", "status", "ui"} <= layers

    # Garbage instead of a JPEG, and a frame with impossible intrinsics: counted, dropped, no overlay.
    client.publish(client.keys.camera_frame("tab1"), _frame(HD, b"\xff\xd8\xff garbage"))
    time.sleep(0.5)
    bad = CameraFrame(
        camera="tab1", jpeg=_jpeg(frame.image), width=HD.width, height=HD.height, intrinsics=[0.0, 0.0, 1.0, 1.0]
    )
    client.publish(client.keys.camera_frame("tab1"), bad)
    time.sleep(0.5)
    assert _stats(client, namespace).get("bad_frames") == 2
    assert ar.alive()
    # ... and the next good frame is processed as before; a frame without tags is "lost" with its age.
    client.publish(client.keys.camera_frame("tab1"), _frame(HD, _jpeg(frame.image)))
    again = wait_for_message(overlays, lambda m: m.ok, timeout=15)
    assert again.seq > first.seq
    blank = np.full((HD.height, HD.width), 128, np.uint8)
    client.publish(client.keys.camera_frame("tab1"), _frame(HD, _jpeg(blank)))
    lost = wait_for_message(overlays, lambda m: not m.ok, timeout=15)
    assert lost.position == [] and lost.lost_age > 0.0

    ar.signal(signal.SIGTERM)
    assert ar.wait(10) == 0
    assert "stopped" in ar.output


def test_a_folder_of_images_is_processed_recorded_and_the_service_ends(router, namespace, client, spawn, tmp_path):
    hall = site("hall")
    folder = tmp_path / "frames"
    folder.mkdir()
    poses = [look_at([3.0 + 0.2 * k, 5.5, 1.3], [0.05, 5.0, 1.1]) for k in range(4)]
    for k, pose in enumerate(poses):
        cv2.imwrite(str(folder / f"f{k}.png"), render(hall, pose, VGA, seed=k).image)
    (folder / "broken.png").write_bytes(b"not an image")  # sorted first: a bad frame, dropped
    (folder / "intrinsics.json").write_text(json.dumps({"intrinsics": VGA.as_list()}))
    overlays = client.collect(client.keys.overlay("tablet"), Overlay)
    out = tmp_path / "out.mp4"
    ar = spawn(
        arroch(
            "ar",
            "--site",
            str(HALL_FILE),
            "--namespace",
            namespace,
            "--connect",
            router,
            "--clock",
            "wall",
            "--source",
            f"images:{folder}",
            "--record",
            str(out),
        ),
        name="ar",
    )
    assert ar.wait(60) == 0, ar.output
    assert "source finished after 5 frames" in ar.output
    got = []
    deadline = time.monotonic() + 5
    while len(got) < 4 and time.monotonic() < deadline:
        got.append(wait_for_message(overlays, timeout=5))
    assert [m.ok for m in got] == [True] * 4
    for m, pose in zip(got, poses, strict=True):
        assert np.linalg.norm(np.array(m.position) - pose.position) < 0.02
    video = cv2.VideoCapture(str(out))
    frames = 0
    while True:
        ok, img = video.read()
        if not ok:
            break
        frames += 1
        assert img.shape == (VGA.height, VGA.width, 3)
    video.release()
    assert frames == 4


def test_bad_configuration_is_refused_before_any_session(spawn, tmp_path):
    missing = spawn(arroch("ar", "--site", str(HALL_FILE), "--source", f"images:{tmp_path / 'nowhere'}"), name="ar")
    assert missing.wait(30) == 2
    assert "does not exist" in missing.output
    (tmp_path / "a.png").write_bytes(b"x")
    no_calibration = spawn(arroch("ar", "--site", str(HALL_FILE), "--source", f"images:{tmp_path}"), name="ar")
    assert no_calibration.wait(30) == 2
    assert "--intrinsics" in no_calibration.output
