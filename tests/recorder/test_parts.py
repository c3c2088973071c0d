"""The recorder's parts without processes: how ``arroch up`` adds it, the log follower, the JSON
Schemas of the wire records, the scene's live door state."""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from protocol.keys import Keys
from protocol.launch.catalog import RECORDER_NAME, SERVICES, Launch, MissionOptions, service_argv
from protocol.messages import CameraFrame, Overlay, Primitive, TeamPlan
from protocol.site import load_site
from services.cli import main
from services.recorder.jsonschema import record_schema
from services.recorder.layout import layout_json
from services.recorder.logtail import LogFollower, parse
from services.recorder.profile import FoxgloveProfile
from services.recorder.reading import messages
from services.recorder.scene import DOOR_CLOSED, DOOR_OPEN, SiteScene
from services.recorder.sink import FoxgloveSink
from services.supervisor.cli import add_up_arguments, build_config
from tests.procs import arroch


def up_config(tmp_path: Path, *args: str):
    parser = argparse.ArgumentParser()
    add_up_arguments(parser)
    config, _options = build_config(parser.parse_args(["--namespace", "n", "--run-dir", str(tmp_path), *args]))
    return config


@pytest.mark.parametrize(
    "args, recorder",
    [
        ((), "record"),  # the default services include the sim: recorded
        (("--services", "planner,sim", "--no-record"), None),
        (("--services", "ping"), None),  # no mission, nothing recorded unless asked
        (("--services", "ping", "--record"), "record"),
        (("--services", "sim", "--no-record", "--view"), "view"),
    ],
)
def test_up_records_runs_with_a_sim_unless_told_otherwise(tmp_path, args, recorder):
    config = up_config(tmp_path, *args)
    specs = [s for s in config.services if s.name == RECORDER_NAME]
    assert [s.command[0] for s in specs] == ([recorder] if recorder else [])


def test_the_recorder_writes_into_the_run_folder_and_the_sim_waits_for_it(tmp_path):
    config = up_config(tmp_path, "--view", "--view-port", "9999")
    (recorder,) = [s for s in config.services if s.name == RECORDER_NAME]
    config.launch.run_dir = tmp_path / "20260101-000000"
    argv = service_argv(recorder, config.launch)
    assert argv[argv.index("--out") + 1] == str(config.launch.run_dir / "run.mcap")
    assert argv[argv.index("--logs") + 1] == str(config.launch.run_dir / "supervisor.log")
    assert argv[argv.index("--view-port") + 1] == "9999"
    assert RECORDER_NAME in SERVICES["sim"].after
    # In the secure profile it reads as the supervisor's role (every key but robot commands).
    secure = Launch(namespace="n", zenoh_config_dir=tmp_path, mission=MissionOptions())
    argv = service_argv(recorder, secure)
    assert argv[argv.index("--zenoh-config") + 1] == str(tmp_path / "supervisor.json5")


def test_the_log_follower_returns_whole_lines_only(tmp_path):
    log = tmp_path / "supervisor.log"
    follower = LogFollower(log)
    assert follower.poll() == []  # not there yet
    log.write_text("[planner] 2026-01-01 12:00:00,000 WARNING arroch.planner: slow solve\n[sim] half a li")
    (line,) = follower.poll()
    assert (line.name, line.level, line.text) == ("planner", "WARNING", "arroch.planner: slow solve")
    with open(log, "a") as f:
        f.write("ne\n")
    (rest,) = follower.poll()
    assert (rest.name, rest.level, rest.text) == ("sim", "INFO", "half a line")
    assert parse("no prefix at all").text == "no prefix at all"


def test_json_schemas_follow_the_message_types():
    schema = record_schema(TeamPlan)
    props = schema["properties"]
    assert schema["title"] == "TeamPlan" and props["type"]["const"] == "TeamPlan"
    assert props["makespan"] == {"type": "number"} and props["plan_id"] == {"type": "integer"}
    step = props["robots"]["additionalProperties"]["items"]
    assert step["title"] == "PlanStep" and step["properties"]["args"] == {"type": "array", "items": {"type": "string"}}


def test_the_scene_follows_door_states_and_carried_objects():
    scene = SiteScene(load_site())
    assert scene.door_changed("d_storage", False).shapes[0].color == DOOR_CLOSED
    assert scene.door_changed("d_storage", False) is None  # no change, nothing to send
    assert scene.door_changed("d_storage", True).shapes[0].color == DOOR_OPEN
    assert scene.door_changed("no_such_door", True) is None
    carried = scene.object_loaded("o0", "r0")
    assert carried.frame == "robot/r0" and carried.locked
    dropped = scene.object_delivered("o0", (1.0, 2.0))
    assert dropped.frame == "world" and dropped.shapes[0].center[:2] == (1.0, 2.0)


def test_the_layout_in_the_repository_is_the_one_the_code_builds(tmp_path):
    kept = (Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json").read_text()
    assert kept == layout_json()
    assert main(["view", "--write-layout", str(tmp_path / "layout.json")]) == 0
    layout = json.loads((tmp_path / "layout.json").read_text())
    panels = json.dumps(layout)
    for needed in (
        '"panelType": "ThreeDee"',
        '"panelType": "Image"',
        '"panelType": "Plot"',
        "/camera/tablet/overlay",
        "/progress.door_openings",
        "/camera/tablet/calibration",
    ):
        assert needed in panels, needed


@pytest.mark.parametrize(
    "args, problem",
    [
        (["--out", "x.txt"], "a recording is an .mcap file"),
        (["--out", "{existing}"], "the file exists already"),
        (["--out", "new.mcap", "--image-scale", "0"], "--image-scale must be in (0, 1]"),
        (["--out", "new.mcap", "--view", "--view-port", "{busy}"], "cannot serve the live view on 127.0.0.1:"),
    ],
)
def test_record_refuses_bad_output_paths_clearly(tmp_path, args, problem):
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"kept")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        filled = [a.replace("{existing}", str(existing)).replace("{busy}", str(busy.getsockname()[1])) for a in args]
        result = subprocess.run(
            arroch("record", *filled, "--connect", "tcp/127.0.0.1:9"),
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert result.returncode == 2 and problem in result.stderr, result.stderr
    assert existing.read_bytes() == b"kept" and not (tmp_path / "new.mcap").exists()


def test_frames_kept_smaller_keep_their_pixels_calibration_and_overlay_in_step(tmp_path):
    image = np.zeros((480, 640, 3), np.uint8)
    cv2.circle(image, (401, 201), 6, (255, 255, 255), -1)  # a bright disc centred on pixel (401, 201)
    jpeg = cv2.imencode(".jpg", image)[1].tobytes()
    frame = CameraFrame(
        src="sim-1",
        seq=7,
        stamp=12.0,
        camera="tablet",
        jpeg=jpeg,
        width=640,
        height=480,
        intrinsics=[500.0, 500.0, 319.5, 239.5],
    )
    overlay = Overlay(
        src="ar-1",
        seq=1,
        stamp=12.0,
        camera="tablet",
        frame_seq=7,
        width=640,
        height=480,
        primitives=[Primitive(kind="circle", points=[[401.0, 201.0]], radius=6.0, width=0.0, layer="robot:r0")],
    )
    keys = Keys("t")
    path = tmp_path / "small.mcap"
    profile = FoxgloveProfile(FoxgloveSink(path), keys, load_site(), image_scale=0.5)
    profile.handle(frame, keys.camera_frame("tablet"))
    profile.handle(overlay, keys.overlay("tablet"))
    profile.close()

    (kept_frame, kept_overlay) = [r.message for r in messages(path)]
    assert (kept_frame.width, kept_frame.height) == (320, 240)
    assert kept_frame.intrinsics == [250.0, 250.0, 159.5, 119.5]
    small = cv2.imdecode(np.frombuffer(kept_frame.jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)
    v, u = np.unravel_index(np.argmax(cv2.GaussianBlur(small, (5, 5), 0)), small.shape)
    assert abs(u - 200.25) <= 1 and abs(v - 100.25) <= 1  # (401 + 0.5) * 0.5 - 0.5
    assert kept_overlay.primitives[0].points == [[200.25, 100.25]] and kept_overlay.primitives[0].radius == 3.0
    with open(path, "rb") as f:
        decoded = {
            c.topic: m
            for _s, c, _r, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/camera/tablet/calibration", "/camera/tablet/overlay"]
            )
        }
    assert decoded["/camera/tablet/calibration"].width == 320 and decoded["/camera/tablet/calibration"].K[0] == 250.0
    circle = decoded["/camera/tablet/overlay"].circles[0]
    assert (circle.position.x, circle.position.y, circle.diameter) == (200.25, 100.25, 6.0)
    with pytest.raises(ValueError, match="--image-scale"):
        FoxgloveProfile(FoxgloveSink(None), keys, load_site(), image_scale=1.5)
