"""Frame sources: a video file and a folder of images, parsed from --source, read in order."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from runtime.frames import look_at
from services.ar_client.pipeline import Pipeline
from services.ar_client.sources import ImageFolderSource, VideoSource, folder_intrinsics, open_source, parse_source
from services.ar_client.synth import render
from tests.ar.helpers import VGA, site


def test_parse_source():
    assert parse_source("sim").kind == "sim"
    assert parse_source("device:0").target == "0"
    for bad in ("cam", "video:", "device:x", "usb:1"):
        with pytest.raises(ValueError):
            parse_source(bad)
    with pytest.raises(FileNotFoundError):
        parse_source("video:/no/such/file.mp4")


def test_a_video_file_is_read_and_localised(tmp_path):
    hall = site("hall")
    path = tmp_path / "walk.avi"
    # MJPG in AVI: lossy like a real camera, and written by every OpenCV build.
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 15.0, (VGA.width, VGA.height))
    poses = [look_at([2.5 + 0.1 * k, 5.0 + 0.1 * k, 1.3], [0.05, 5.0, 1.2]) for k in range(5)]
    for k, pose in enumerate(poses):
        writer.write(cv2.cvtColor(render(hall, pose, VGA, seed=k).image, cv2.COLOR_GRAY2BGR))
    writer.release()
    source = open_source(parse_source(f"video:{path}"), VGA)
    assert isinstance(source, VideoSource) and source.fps == pytest.approx(15.0)
    pipeline = Pipeline(hall)
    for k, pose in enumerate(poses):
        frame = source.read()
        assert frame is not None and frame.seq == k + 1
        overlay, _ = pipeline.process(frame.image, frame.intrinsics, float(k))
        assert overlay.ok and np.linalg.norm(np.array(overlay.position) - pose.position) < 0.02
    assert source.read() is None
    source.close()


def test_a_folder_needs_a_calibration_and_reads_in_name_order(tmp_path):
    for name in ("b.png", "a.jpg", "notes.txt"):
        (tmp_path / name).write_bytes(b"x")
    with pytest.raises(ValueError, match="intrinsics"):
        open_source(parse_source(f"images:{tmp_path}"), None)
    (tmp_path / "intrinsics.json").write_text(
        json.dumps({"intrinsics": VGA.as_list(), "distortion": [0.1, 0, 0, 0, 0]})
    )
    K = folder_intrinsics(tmp_path)
    assert K is not None and K.width == 640 and K.distortion[0] == 0.1
    source = open_source(parse_source(f"images:{tmp_path}"), None)
    assert isinstance(source, ImageFolderSource)
    assert [source.read().name, source.read().name, source.read()] == ["a.jpg", "b.png", None]
    (tmp_path / "intrinsics.json").write_text('{"intrinsics": [1, 2]}')
    with pytest.raises(ValueError, match="intrinsics.json"):
        folder_intrinsics(tmp_path)
