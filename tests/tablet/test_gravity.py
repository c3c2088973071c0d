"""The page sends the device's gravity with its frames, and gravity picks a single small tag's right
pose: real headless Chromium, its fake camera playing a 640x480 view of the hall's lone east-wall tag
from 4.5 m (17 px; AR client synthetic frames, truth known), and a scripted ``devicemotion`` source.

Without motion data the frames go without gravity and the pose is mostly the tag's mirror solution,
over a metre off; once the page hears ``devicemotion`` (the reaction to gravity a still tablet
measures, in device axes), every frame carries gravity in the camera frame and the pose is right.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from runtime.frames import gravity_in_camera
from services.ar_client.synth import render
from services.ar_client.web.fakecam import write_y4m
from services.ar_client.web.intrinsics import write_intrinsics
from tests.ar.helpers import HALL_FILE, SINGLE_TAG, VGA, only_tags
from tests.ar.test_gravity import single_tag_view
from tests.tablet.helpers import start_tablet

pytestmark = pytest.mark.integration


def test_gravity_from_devicemotion_rides_with_the_frames_and_fixes_a_single_tag_pose(
    router, namespace, spawn, browser, tmp_path
):
    truth = single_tag_view(-30.0)
    lone = only_tags("hall", (SINGLE_TAG,))
    frames = [cv2.cvtColor(render(lone, truth, VGA, seed=430 + k).image, cv2.COLOR_GRAY2BGR) for k in range(4)]
    video = tmp_path / "camera.y4m"
    write_y4m(video, frames, fps=15)
    intrinsics = tmp_path / "intrinsics.json"
    write_intrinsics(intrinsics, VGA)
    server = start_tablet(
        spawn, router, namespace, tmp_path / "tablet", "--site", str(HALL_FILE), "--intrinsics", str(intrinsics)
    )

    page = browser(fake_camera=video, window=(1000, 700))
    page.navigate(server.url)
    blind = page.wait_for(
        "(() => { const s = window.arroch && window.arroch.state();"
        " return s && s.overlay && s.overlay.ok && s.overlay.seq > 3 && s; })()",
        timeout=40,
    )
    assert blind["gravity"] is None and blind["overlay"]["gravity"] is None  # no motion data yet: none sent
    assert blind["overlay"]["tags"] == [SINGLE_TAG]
    # Which of the tag's two planar solutions the blind pose is depends on the first frames' noise after
    # the browser's encoding: mostly the mirror one, over a metre off, but not always (it was right in
    # one run of many), so it is not asserted here; tests/ar/test_gravity.py shows it on the frames.

    # A still tablet's accelerometer: the reaction to gravity, in device axes (x right, y up the
    # screen, z out of the screen); the rear camera's axes are (x, -y, -z) of those.
    g_cam = gravity_in_camera(truth.R_wc)
    reaction = {"x": -g_cam[0], "y": g_cam[1], "z": g_cam[2]}
    page.evaluate(
        "window.__motion = setInterval(() => window.dispatchEvent(new DeviceMotionEvent('devicemotion',"
        f" {{ accelerationIncludingGravity: {json.dumps(reaction)}, interval: 16 }})), 16)"
    )
    seen = page.wait_for(
        "(() => { const s = window.arroch.state(); const o = s.overlay;"
        " return o && o.ok && o.gravity && s.gravity_source === 'devicemotion' && s; })()",
        timeout=20,
    )
    assert np.allclose(seen["overlay"]["gravity"], g_cam, atol=0.01)  # the server solved with what the page measured
    assert np.allclose(seen["gravity"], g_cam, atol=1e-3)
    # The drawn pose moves over to the right solution (the filter takes a few consistent frames to follow a jump).
    right = page.wait_for(
        "(() => { const o = window.arroch.state().overlay;"
        f" const d = Math.hypot(o.position[0] - {truth.position[0]}, o.position[1] - {truth.position[1]}, "
        f"o.position[2] - {truth.position[2]});"
        " return o.ok && o.gravity && d < 0.15 && o; })()",
        timeout=20,
    )
    assert right["tags"] == [SINGLE_TAG]
    page.evaluate("clearInterval(window.__motion)")
    # The turn by the screen angle: at 90 (device turned counter-clockwise, its top to the left) the
    # device's y axis is the screen's -x and its x axis the screen's y.
    turned = page.evaluate(
        "import('/static/gravity.js').then((m) => [m.screenAligned([1, 2, 3], 0), m.screenAligned([1, 2, 3], 90),"
        " m.screenAligned([1, 2, 3], 180), m.screenAligned([1, 2, 3], 270)])"
    )
    np.testing.assert_allclose(turned, [[1, 2, 3], [-2, 1, 3], [-1, -2, 3], [2, -1, 3]], atol=1e-9)
    assert server.proc.alive()
