"""The demo mission's recording as the tools users open it with read it: every channel decoded by the
decoder of its declared encoding (``json``, ``protobuf``, ``cdr``), no channel twice, log times on the
wall clock, robot poses at 10 Hz of site time, the wire store ``arroch replay`` reads, no secret in
any file of the run; and ``arroch runs show`` summarising it (counts, time spans, the timeline PNG)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import msgspec
import pytest
import zstandard
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from protocol.messages import BY_TYPE, RobotPose
from services.recorder.layout import build_layout
from services.recorder.reading import channel_stats, messages, metadata
from services.recorder.wire import MEDIA_TYPE
from tests.procs import ROOT, arroch
from tests.recorder.foxglove_app import json_schema_problems

pytestmark = [pytest.mark.integration, pytest.mark.slow]

VIEW_CHANNELS = {
    "/site": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/paths": "foxglove.SceneUpdate",
    "/progress": "arroch.Progress",
    "/log": "foxglove.Log",
    "/camera/tablet/image": "foxglove.CompressedImage",
    "/camera/tablet/calibration": "foxglove.CameraCalibration",
    "/camera/tablet/overlay": "foxglove.ImageAnnotations",
    "/arroch/plan": "arroch.TeamPlan",
    "/arroch/constraints": "arroch.ConstraintSet",
    "/arroch/event": "arroch.Event",
    "/arroch/clock": "arroch.Clock",
}
ENCODINGS = {"json": "jsonschema", "protobuf": "protobuf", "cdr": "ros2msg"}  # message encoding: its schema's


class Decoders:
    """The decoder of each declared encoding, as a viewer picks it: JSON (with the Foxglove rules for its
    schema), protobuf (``mcap-protobuf-support``), ROS 2 CDR (``rosbags``, from the channel's ros2msg schema)."""

    def __init__(self) -> None:
        self.protobuf = DecoderFactory()
        self.cdr = get_typestore(Stores.EMPTY)
        self._by_channel: dict[int, object] = {}

    def decode(self, schema, channel, data: bytes):  # noqa: ANN001
        decoder = self._by_channel.get(channel.id)
        if decoder is None:
            decoder = self._by_channel[channel.id] = self._make(schema, channel)
        return decoder(data)

    def _make(self, schema, channel):  # noqa: ANN001
        assert schema is not None and ENCODINGS[channel.message_encoding] == schema.encoding, channel.topic
        if channel.message_encoding == "json":
            assert json_schema_problems(json.loads(schema.data)) == [], channel.topic
            return json.loads
        if channel.message_encoding == "protobuf":
            return self.protobuf.decoder_for("protobuf", schema)
        self.cdr.register(get_types_from_msg(schema.data.decode(), schema.name))
        return lambda data: self.cdr.deserialize_cdr(data, schema.name)


def test_every_channel_decodes_with_the_decoder_of_its_encoding_and_none_is_twice(mission):
    decoders = Decoders()
    counts: dict[str, int] = defaultdict(int)
    decoded: dict[str, list] = defaultdict(list)
    payload_topics: dict[bytes, set[str]] = defaultdict(set)
    with open(mission.recording, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = [c.topic for c in summary.channels.values()]
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        for schema, channel, message in reader.iter_messages():
            value = decoders.decode(schema, channel, message.data)
            counts[channel.topic] += 1
            if channel.topic.startswith("/arroch/"):  # the message itself, as its type reads it
                cls = BY_TYPE[schema.name.removeprefix("arroch.")]
                value = msgspec.convert(value, cls, strict=False)
                assert value.TYPE == cls.TYPE
            decoded[channel.topic].append(value)
            payload_topics[bytes(message.data)].add(channel.topic)
    assert len(topics) == len(set(topics)), "a topic on two channels"
    assert {c.message_encoding for c in summary.channels.values()} <= set(ENCODINGS)
    # No message on two channels (the old file had /plan, /events, /constraints twice), none left over.
    twice = {tuple(sorted(t)) for t in payload_topics.values() if len(t) > 1}
    assert twice == set(), twice
    assert not {"/plan", "/events", "/constraints", "/metrics"} & set(topics)
    for topic, schema in VIEW_CHANNELS.items():
        assert schemas.get(topic) == schema, (topic, schemas.get(topic))
        assert counts[topic] > 0, topic
    for rid in ("r0", "r1", "r2"):
        for what in ("pose", "status", "command"):
            assert counts[f"/arroch/robot/{rid}/{what}"] > 0
        assert counts[f"/arroch/intent/{rid}"] > 0
    # Frames of the bridge; the scene has every door, tag and object; doors follow their states.
    frames = {(t.parent_frame_id, t.child_frame_id) for msg in decoded["/tf"] for t in msg.transforms}
    assert {("map", f"{rid}/base_link") for rid in ("r0", "r1", "r2")} <= frames
    assert ("map", "tablet/camera_optical_frame") in frames
    first_scene = {e.id for e in decoded["/site"][0].entities}
    assert {"walls", "door/d_storage", "object/o0", "robot/r0"} <= first_scene
    assert any(i.startswith("tag/") for i in first_scene)
    assert len([e for msg in decoded["/site"][1:] for e in msg.entities if e.id == "door/d_storage"]) >= 2
    assert any(len(msg.points) > 0 for msg in decoded["/camera/tablet/overlay"])
    # Log: the services' own lines (from the merged log, naming it) beside events and acks.
    followed = [entry for entry in decoded["/log"] if entry.file == "supervisor.log"]
    assert {"planner", "sim", "up", "tablet"} <= {entry.name for entry in followed}
    assert all(entry.line > 0 for entry in followed)
    assert any(entry.name.startswith("restrictor-") and "accepted" in entry.message for entry in decoded["/log"])
    assert any(
        e.kind == "mission_done" and "completed" in msgspec.to_builtins(e.data) for e in decoded["/arroch/event"]
    )
    # Every topic the layout shows is in the file.
    layout = json.dumps(build_layout())
    for topic in {t for t in topics if f'"{t}' in layout}:
        assert counts[topic] > 0
    for needed in ("/camera/tablet/image", "/arroch/plan", "/progress", "/log", "/site", "/paths"):
        assert f'"{needed}' in layout and needed in topics


def test_log_times_are_the_wall_clock_of_the_run_start_plus_site_time(mission):
    recorded = metadata(mission.recording)
    origin = int(recorded["site_time_origin_ns"])
    assert mission.started * 1e9 <= origin <= mission.finished * 1e9, (mission.started, origin, mission.finished)
    decoders = Decoders()
    exact = transforms = 0
    with open(mission.recording, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert mission.started * 1e9 - 1e9 <= message.log_time <= origin + 3600e9, channel.topic
            if channel.topic.startswith("/arroch/"):
                stamp = decoders.decode(schema, channel, message.data)["stamp"]
                exact += message.log_time == origin + round(stamp * 1e9)
            elif channel.topic == "/tf":  # the timestamps inside a message are its log time too
                for t in decoders.decode(schema, channel, message.data).transforms:
                    assert t.timestamp.seconds * 10**9 + t.timestamp.nanos == message.log_time
                    transforms += 1
    assert exact > 1000 and transforms > 100
    # Readers give site time back: the recording's messages at their own stamps.
    poses = [r for r in messages(mission.recording) if isinstance(r.message, RobotPose)]
    assert poses and all(abs(r.time - r.message.stamp) < 1e-6 for r in poses)


def test_robot_poses_are_recorded_at_10_hz_of_site_time(mission):
    """Smooth replays need poses at 10 Hz of site time (the simulator's lockstep pose rate)."""
    stamps: dict[str, list[float]] = defaultdict(list)
    for record in messages(mission.recording):
        if isinstance(record.message, RobotPose):
            stamps[record.message.robot].append(record.message.stamp)
    assert set(stamps) == {"r0", "r1", "r2"}
    for rid, times in stamps.items():
        span = max(times) - min(times)
        assert span > 60 and len(times) / span >= 10.0, (rid, len(times), span)


def _mcap_texts(path: Path) -> list[bytes]:
    """Everything an MCAP file holds, decompressed: messages, attachments (the wire store unpacked),
    metadata, schemas and channel metadata."""
    out: list[bytes] = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        out += [bytes(m.data) for _s, _c, m in reader.iter_messages()]
        for attachment in reader.iter_attachments():
            data = bytes(attachment.data)
            out.append(zstandard.ZstdDecompressor().decompress(data) if attachment.media_type == MEDIA_TYPE else data)
        out += [json.dumps(m.metadata).encode() for m in reader.iter_metadata()]
        out += [bytes(s.data) for s in summary.schemas.values()]
        out += [json.dumps(c.metadata).encode() for c in summary.channels.values()]
    return out


def test_no_file_of_the_run_holds_the_tablet_pages_token(mission):
    token = mission.token.encode()
    assert len(token) >= 16 and f"?token={mission.token}" in mission.output  # the terminal shows it, as it must
    files = [p for p in mission.run.rglob("*") if p.is_file()]
    assert {"run.mcap", "supervisor.log", "metadata.yaml", "run_ros2_0.mcap"} <= {p.name for p in files}
    for path in files:
        texts = [path.read_bytes()] + (_mcap_texts(path) if path.suffix == ".mcap" else [])
        assert not any(token in text for text in texts), path
    # The line that carried it reached the log file and the recording, redacted.
    assert "?token=<redacted>" in (mission.run / "supervisor.log").read_text()
    with open(mission.recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        lines = [log.message for _s, _c, _m, log in reader.iter_decoded_messages(topics=["/log"])]
    assert any("?token=<redacted>" in line for line in lines)


def test_the_wire_store_keeps_every_message_as_it_travelled(mission):
    with open(mission.recording, "rb") as f:
        attachments = list(make_reader(f).iter_attachments())
    assert attachments and {a.media_type for a in attachments} == {MEDIA_TYPE}
    recorded = list(messages(mission.recording))
    frames = [r.message for r in recorded if r.topic == "/arroch/camera/tablet/frame"]
    counts = {c.topic: c.messages for c in channel_stats(mission.recording)}
    assert len(frames) == counts["/camera/tablet/image"] and all(f.jpeg[:2] == b"\xff\xd8" for f in frames)
    assert len(recorded) == sum(n for topic, n in counts.items() if topic.startswith("/arroch/"))
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
    assert "human door openings" in out and "her a1 actions" in out and "site time 0 on the wall clock: 20" in out
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
