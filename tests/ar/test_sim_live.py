"""End to end on the wire: the simulator's virtual tablet camera streams frames over Zenoh, the AR
client localises each one and publishes its Overlay; the simulator's CameraTruth for the same frame
says how far off the pose is."""

from __future__ import annotations

import time

import numpy as np
import pytest

from protocol.messages import CameraTruth, Overlay
from tests.conftest import wait_for_message
from tests.procs import arroch

pytestmark = pytest.mark.integration

camfeed = pytest.importorskip("services.sim.camfeed")
if not hasattr(camfeed, "CameraFeed"):
    pytest.skip("the simulator's camera feed is not installed", allow_module_level=True)

# Fixed camera in the office's storage room facing its east wall from 4 m (degrees), 1280x720.
CAMERA = "7.0,1.5,1.4,0,-5"


def test_sim_frames_become_overlays_with_the_true_pose(router, namespace, client, spawn):
    overlays = client.collect(client.keys.overlay("tab"), Overlay)
    truths = client.collect(client.keys.camera_truth("tab"), CameraTruth)
    ar = spawn(
        arroch("ar", "--namespace", namespace, "--connect", router, "--camera", "tab", "--clock", "sim"), name="ar"
    )
    ar.wait_for("waiting for frames", timeout=30)
    sim = spawn(
        arroch(
            "sim",
            "--namespace",
            namespace,
            "--connect",
            router,
            "--camera",
            CAMERA,
            "--camera-id",
            "tab",
            "--camera-rate",
            "3",
            "--camera-size",
            "1280x720",
            "--camera-fov",
            "50",
        ),
        name="sim",
    )
    truth_by_seq: dict[int, CameraTruth] = {}
    matched = []
    deadline = time.monotonic() + 60
    while len(matched) < 3 and time.monotonic() < deadline:
        overlay = wait_for_message(overlays, timeout=max(deadline - time.monotonic(), 0.1))
        while not truths.empty():
            t, _key = truths.get_nowait()
            truth_by_seq[t.frame_seq] = t
        time.sleep(0.3)  # the truth of this frame may still be on its way
        while not truths.empty():
            t, _key = truths.get_nowait()
            truth_by_seq[t.frame_seq] = t
        if overlay.frame_seq in truth_by_seq:
            matched.append((overlay, truth_by_seq[overlay.frame_seq]))
    assert len(matched) >= 3, (len(matched), sim.output[-2000:], ar.output[-2000:])
    for overlay, truth in matched:
        assert overlay.ok, overlay
        assert np.linalg.norm(np.array(overlay.position) - np.array(truth.position)) < 0.02
        assert overlay.latency < 5.0
    assert sim.alive() and ar.alive()
