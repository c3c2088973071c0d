"""The recording of a real mission: every channel there, readable by the mcap reader, summarised by
``arroch runs show`` (counts, time spans, the table, the timeline PNG)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from services.recorder.reading import channel_stats, messages, metadata
from tests.procs import ROOT, arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

VIEW_CHANNELS = {
    "/site": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/paths": "foxglove.SceneUpdate",
    "/plan": "arroch.TeamPlan",
    "/constraints": "arroch.ConstraintSet",
    "/events": "arroch.Event",
    "/progress": "arroch.Progress",
    "/metrics": "arroch.Metrics",
    "/log": "foxglove.Log",
    "/camera/tablet/image": "foxglove.CompressedImage",
    "/camera/tablet/calibration": "foxglove.CameraCalibration",
    "/camera/tablet/overlay": "foxglove.ImageAnnotations",
}


def test_the_mission_recording_has_every_channel_with_schemas(mission):
    with open(mission.recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        decoded = {}
        for _schema, channel, _message, proto in reader.iter_decoded_messages(
            topics=["/tf", "/site", "/camera/tablet/overlay", "/log"]
        ):
            decoded.setdefault(channel.topic, []).append(proto)
    for topic, schema in VIEW_CHANNELS.items():
        assert schemas.get(topic) == schema, (topic, schemas.get(topic))
        assert counts[topic] > 0, topic
    assert counts["/metrics"] == 1
    # Raw ARROCH messages, one channel per key, for replay.
    for rid in ("r0", "r1", "r2"):
        for what in ("pose", "status", "command"):
            assert counts[f"/arroch/robot/{rid}/{what}"] > 0
        assert counts[f"/arroch/intent/{rid}"] > 0
    # Frame transforms for every robot and the camera; the scene has every door, tag and object.
    frames = {t.child_frame_id for msg in decoded["/tf"] for t in msg.transforms}
    assert {"robot/r0", "robot/r1", "robot/r2", "camera/tablet"} <= frames
    first_scene = {e.id for e in decoded["/site"][0].entities}
    assert {"walls", "door/d_storage", "object/o0", "robot/r0"} <= first_scene and any(
        i.startswith("tag/") for i in first_scene
    )
    # Door updates follow the sim's door states (closed, then opened by the human at least once).
    door_updates = [e for msg in decoded["/site"][1:] for e in msg.entities if e.id == "door/d_storage"]
    assert len(door_updates) >= 2
    assert any(len(msg.points) > 0 for msg in decoded["/camera/tablet/overlay"])
    # Log: the services' own log lines (from the merged log) beside events and acks.
    names = {entry.name for entry in decoded["/log"]}
    assert {"planner", "sim", "up"} <= names, names
    assert any(entry.name.startswith("restrictor-") and "accepted" in entry.message for entry in decoded["/log"])
    # Camera frames: the raw frame's JPEG is stored once (in the image channel) and paired back on reading.
    frames_read = [r.message for r in messages(mission.recording) if r.topic == "/arroch/camera/tablet/frame"]
    assert len(frames_read) == counts["/camera/tablet/image"] and all(f.jpeg[:2] == b"\xff\xd8" for f in frames_read)
    assert metadata(mission.recording)["namespace"].startswith("rec")


def test_runs_show_prints_the_summary_every_channel_and_draws_the_timeline(mission, tmp_path):
    png = tmp_path / "timeline.png"
    result = subprocess.run(
        arroch("runs", "show", str(mission.run), "--png", str(png)),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    out = result.stdout
    metrics = json.loads((mission.run / "metrics.json").read_text())
    assert f"{metrics['team_completion_time']:.1f} s" in out
    assert "human door openings" in out and "her a1 actions" in out
    contacts = next(line for line in out.splitlines() if "robot-robot contacts" in line)
    assert contacts.split()[2] == str(metrics["robot_overlaps"])
    for stats in channel_stats(mission.recording):
        line = next(line for line in out.splitlines() if line.strip().startswith(stats.topic + " "))
        assert f" {stats.messages} " in line and f"{stats.last:.1f}" in line, line
    assert png.stat().st_size > 20_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_runs_show_refuses_a_file_that_is_not_a_recording(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    result = subprocess.run(
        [sys.executable, "-m", "services.cli", "runs", "show", str(bad)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert str(bad) in result.stderr and "not a readable MCAP file" in result.stderr
