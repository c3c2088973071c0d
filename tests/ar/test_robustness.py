"""Unexpected input never breaks the pipeline: it either answers (possibly "lost") or raises BadFrame."""

from __future__ import annotations

import cv2
import numpy as np

from protocol.messages import Intent, RobotPose
from services.ar_client.pipeline import BadFrame, Pipeline
from services.ar_client.project import Intrinsics
from services.ar_client.world import WorldView
from tests.ar.helpers import site


def test_random_bytes_noise_and_odd_sizes():
    rng = np.random.default_rng(7)
    world = WorldView()
    world.on_pose(RobotPose(robot="r0", x=2.0, y=5.0, theta=0.0))
    # Odd intents: a single row, times going backwards, a far-away path.
    world.on_intent(Intent(robot="r0", trajectory=[[5.0, 1.0, 1.0, 0.0]]))
    world.on_intent(
        Intent(robot="r1", trajectory=[[9.0, 1.0, 1.0, 0.0], [3.0, 2.0, 2.0, 0.0], [1.0, 900.0, -900.0, 0.0]])
    )
    pipeline = Pipeline(site("hall"), world)
    answered = refused = 0
    for k in range(60):
        kind = k % 4
        if kind == 0:
            frame: bytes | np.ndarray = rng.bytes(int(rng.integers(0, 5000)))
            K = Intrinsics(500, 500, 320, 240, 640, 480)
        elif kind == 1:
            h, w = int(rng.integers(1, 64)), int(rng.integers(1, 64))
            frame = rng.integers(0, 256, (h, w), dtype=np.uint8)
            K = Intrinsics(50, 50, w / 2, h / 2, w, h)
        elif kind == 2:
            frame = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
            ok, jpeg = cv2.imencode(".jpg", frame)
            frame = jpeg.tobytes()[: int(rng.integers(10, len(jpeg)))]  # truncated JPEG
            K = Intrinsics(500, 500, 320, 240, 640, 480)
        else:
            frame = rng.integers(0, 256, (480, 640), dtype=np.uint8)
            K = Intrinsics(float(rng.uniform(1, 1e5)), float(rng.uniform(1, 1e5)), 320, 240, 640, 480)
        try:
            overlay, image = pipeline.process(frame, K, float(k))
        except BadFrame:
            refused += 1
            continue
        answered += 1
        assert overlay.width == K.width and (overlay.ok or overlay.position == [])
    assert answered >= 15 and refused >= 15
