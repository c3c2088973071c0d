"""The recorder's parts without processes (or with one short-lived one): how ``arroch up`` adds it,
the log follower and its redaction, the JSON Schemas of the messages as Foxglove reads them, the
layout as the apps import it, the scene's live door state, the timebase, the wire store, a failed
start that cleans up, a recorder that is the router when none answers."""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from protocol.codec import encode
from protocol.keys import Keys
from protocol.messages import ALL_MESSAGES, CameraFrame, Intent, Overlay, Primitive, RobotPose, TeamPlan
from protocol.site import load_site
from runtime.launch.catalog import RECORDER_NAME, SERVICES, Launch, MissionOptions, service_argv
from runtime.transport import NoRouter, ZenohOptions, free_tcp_port, through_local_router
from services.cli import main
from services.recorder.jsonschema import record_schema
from services.recorder.layout import build_layout, layout_json
from services.recorder.logtail import LogFollower, parse
from services.recorder.profile import FoxgloveProfile
from services.recorder.reading import messages
from services.recorder.scene import DOOR_CLOSED, DOOR_OPEN, SiteScene
from services.recorder.service import Recorder
from services.recorder.sink import FoxgloveSink
from services.recorder.timebase import Timebase
from services.recorder.wire import WireRecord, with_jpeg, without_jpeg
from services.supervisor.cli import add_up_arguments, build_config
from tests.conftest import TestClient
from tests.procs import arroch
from tests.recorder.foxglove_app import json_schema_problems, layout_problems


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


def test_up_record_profile_ros2_adds_the_bag_to_the_recording(tmp_path):
    config = up_config(tmp_path, "--record-profile", "ros2", "--ros-distro", "humble")
    (recorder,) = [s for s in config.services if s.name == RECORDER_NAME]
    config.launch.run_dir = tmp_path / "run"
    argv = service_argv(recorder, config.launch)
    assert argv[argv.index("--profile") + 1] == "foxglove,ros2" and argv[argv.index("--ros-distro") + 1] == "humble"
    assert argv[argv.index("--out") + 1] == str(tmp_path / "run" / "run.mcap")  # the bag goes beside it
    with pytest.raises(ValueError, match="not with --no-record"):
        up_config(tmp_path, "--record-profile", "ros2", "--no-record")


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


def test_the_log_follower_returns_whole_lines_only_and_no_secret(tmp_path):
    log = tmp_path / "supervisor.log"
    follower = LogFollower(log)
    assert follower.poll() == []  # not there yet
    log.write_text("[planner] 2026-01-01 12:00:00,000 WARNING arroch.planner: slow solve\n[sim] half a li")
    (line,) = follower.poll()
    assert (line.name, line.level, line.text, line.number) == ("planner", "WARNING", "arroch.planner: slow solve", 1)
    with open(log, "a") as f:
        f.write("ne\n\n[tablet]   https://127.0.0.1:4433/?token=Zq3_secret-Token123&mode=viewer\n")
        f.write("[ops] -----BEGIN PRIVATE KEY-----\n[ops] MIIEvQIBADANBgkq\n")
        f.write("[ops] -----END PRIVATE KEY-----\n[ops] ok\n")
    rest, url, *key, ok = follower.poll()
    assert (rest.name, rest.level, rest.text, rest.number) == ("sim", "INFO", "half a line", 2)
    assert url.text == "  https://127.0.0.1:4433/?token=<redacted>&mode=viewer" and url.number == 4
    assert [k.text for k in key] == ["<redacted>"] * 3 and ok.text == "ok"
    assert parse("no prefix at all").text == "no prefix at all"


def test_json_schemas_come_from_the_message_types_and_foxglove_reads_them():
    schema = record_schema(TeamPlan)
    props = schema["properties"]
    assert schema["title"] == "TeamPlan" and props["type"] == {"enum": ["TeamPlan"], "type": "string"}
    assert props["makespan"]["type"] == "number" and props["makespan"]["minimum"] == 0.0  # the type's limits
    step = props["robots"]["additionalProperties"]["items"]
    assert step["title"] == "PlanStep" and step["properties"]["args"]["items"]["type"] == "string"
    assert "$ref" not in json.dumps(schema)
    # Rows of numbers and free JSON have no type Foxglove takes: named, not typed (the values stay).
    intent = record_schema(Intent)
    assert "trajectory" not in intent["properties"] and "trajectory" in intent["description"]
    for cls in ALL_MESSAGES:
        assert json_schema_problems(record_schema(cls)) == [], cls.__name__
    # What msgspec's own schema has and Foxglove would refuse: the rules are not vacuous.
    assert json_schema_problems({"type": "object", "properties": {"t": {"type": "array", "items": {"type": "array"}}}})
    assert json_schema_problems({"type": "object", "properties": {"d": {"anyOf": [{"type": "null"}]}}})


def test_the_scene_follows_door_states_and_carried_objects():
    scene = SiteScene(load_site())
    assert scene.door_changed("d_storage", False).shapes[0].color == DOOR_CLOSED
    assert scene.door_changed("d_storage", False) is None  # no change, nothing to send
    assert scene.door_changed("d_storage", True).shapes[0].color == DOOR_OPEN
    assert scene.door_changed("no_such_door", True) is None
    carried = scene.object_loaded("o0", "r0")
    assert carried.frame == "r0/base_link" and carried.locked  # the bridge's frames
    dropped = scene.object_delivered("o0", (1.0, 2.0))
    assert dropped.frame == "map" and dropped.shapes[0].center[:2] == (1.0, 2.0)


def test_the_layout_in_the_repository_imports_as_the_apps_layout_data(tmp_path):
    kept = (Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json").read_text()
    assert kept == layout_json()
    assert main(["view", "--write-layout", str(tmp_path / "layout.json")]) == 0
    layout = json.loads((tmp_path / "layout.json").read_text())
    assert layout_problems(layout) == []
    assert {panel.split("!")[0] for panel in layout["configById"]} == {"3D", "Image", "Plot", "RosOut", "RawMessages"}
    image = layout["configById"]["Image!tablet"]["imageMode"]
    assert image["imageTopic"] == "/camera/tablet/image" and "/camera/tablet/overlay" in image["annotations"]
    # The SDK's layout type, which the file used to be, is not what the apps import.
    assert layout_problems({"content": {"type": "split", "items": []}})
    broken = build_layout()
    broken["configById"]["Plot!progress"]["series"] = []
    assert layout_problems(broken) == ["Plot!progress: keys its panel does not read: ['series']"]


@pytest.mark.parametrize(
    "args, problem",
    [
        (["--out", "x.txt"], "a recording is an .mcap file"),
        (["--out", "{existing}"], "the file exists already"),
        (["--out", "new.mcap", "--image-scale", "0"], "--image-scale must be in (0, 1]"),
        (["--out", "new.mcap", "--view", "--view-port", "{busy}"], "cannot serve the live view on 127.0.0.1:"),
        (["--profile", "ros2", "--out", "{folder}"], "a ROS 2 bag folder must not exist yet"),
    ],
)
def test_record_refuses_bad_output_paths_clearly(tmp_path, args, problem):
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"kept")
    (tmp_path / "bag").mkdir()
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = str(busy.getsockname()[1])
        filled = [a.format(existing=existing, busy=port, folder=tmp_path / "bag") for a in args]
        result = subprocess.run(
            arroch("record", *filled, "--connect", "tcp/127.0.0.1:9"),
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert result.returncode == 2 and problem in result.stderr, result.stderr
    assert existing.read_bytes() == b"kept" and not (tmp_path / "new.mcap").exists()
    assert list((tmp_path / "bag").iterdir()) == []


@pytest.mark.parametrize(
    "command",
    [
        ["record", "--profile", "ros2", "--out", "{out}"],
        ["record", "--profile", "foxglove,ros2", "--out", "{out}.mcap"],
        ["replay", "{recording}"],
    ],
)
def test_without_a_router_one_line_says_what_to_start_and_nothing_is_left_behind(tmp_path, command):
    recording = tmp_path / "run.mcap"
    written = FoxgloveProfile(FoxgloveSink(recording), Keys("t"), load_site(), Timebase(1), metadata={"namespace": "t"})
    written.start(1)
    written.close()
    nobody = f"tcp/127.0.0.1:{free_tcp_port()}"
    for _attempt in range(2):  # the retry meets the same answer, not a folder left by the first
        argv = [a.format(out=tmp_path / "out", recording=recording) for a in command]
        result = subprocess.run(
            arroch(*argv, "--connect", nobody), cwd=tmp_path, capture_output=True, text=True, timeout=60
        )
        assert result.returncode == 1, result.stderr
        (line,) = [line for line in result.stderr.splitlines() if "ERROR" in line]
        assert f"no Zenoh router answers on {nobody}: start one (`arroch router" in line
        assert "Traceback" not in result.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]


def test_a_start_that_fails_midway_removes_what_it_made(tmp_path, router):
    """The bag's folder appears between the checks and the start: the MCAP file made first goes again."""
    site = load_site()
    timebase = Timebase()
    recording = tmp_path / "run.mcap"
    bag = tmp_path / "run_ros2"
    from services.recorder.ros2 import Ros2Profile
    from services.recorder.rosbag import DISTROS

    profiles = [
        FoxgloveProfile(FoxgloveSink(recording), Keys("t"), site, timebase),
        Ros2Profile(bag, site, timebase, DISTROS["humble"], "t"),
    ]
    bag.mkdir()  # someone else's, after the recorder checked
    (bag / "theirs").write_text("kept")
    recorder = Recorder("t", ZenohOptions(connect=[router]), profiles, timebase)
    with pytest.raises(FileExistsError):
        recorder.open()
    recorder.close()
    assert not recording.exists() and (bag / "theirs").read_text() == "kept"


def test_with_no_router_on_its_endpoint_a_recorder_is_the_router(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    options, note = through_local_router(ZenohOptions(connect=[endpoint]), become=True)
    assert (options.mode, options.listen, options.connect) == ("router", [endpoint], []) and endpoint in note
    with pytest.raises(NoRouter, match="give --connect"):  # an endpoint the user named: never taken over
        through_local_router(ZenohOptions(connect=[endpoint], explicit={"connect"}), become=True)
    keys = Keys("t")
    timebase = Timebase()
    recording = tmp_path / "run.mcap"
    profile = FoxgloveProfile(FoxgloveSink(recording), keys, load_site(), timebase, metadata={"namespace": "t"})
    recorder = Recorder("t", options, [profile], timebase)
    recorder.open()
    try:
        # Now a router answers there: the next client connects to the recorder as to `arroch router`.
        plain = ZenohOptions(connect=[endpoint])
        assert through_local_router(plain, become=True) == (plain, "")
        client = TestClient("t", endpoint)
        client.open()
        try:
            deadline = time.monotonic() + 10
            while recorder.messages == 0 and time.monotonic() < deadline:
                client.publish(keys.robot_pose("r0"), RobotPose(robot="r0", x=1.0, y=2.0, theta=0.0))
                time.sleep(0.1)
        finally:
            client.close()
    finally:
        recorder.close()
    assert recorder.messages > 0
    assert {r.message.robot for r in messages(recording)} == {"r0"}


def test_the_timebase_puts_site_time_on_the_wall_clock():
    timebase = Timebase()
    before = time.time_ns()
    assert before <= timebase.at(5.0) <= time.time_ns()  # no origin yet: the wall clock itself
    assert timebase.fix(12.5, wall_ns=2_000_000_000_000_000_000) and not timebase.fix(99.0)
    assert timebase.at(12.5) == 2_000_000_000_000_000_000 and timebase.at(13.0) - timebase.at(12.5) == 500_000_000
    assert timebase.site(timebase.at(20.25)) == 20.25
    assert Timebase(0).at(1_700_000_000.5) == 1_700_000_000_500_000_000  # the wall clock's stamps as they are


def test_the_wire_store_gives_back_a_frames_bytes_exactly():
    jpeg = b"\xff\xd8" + bytes(range(256)) * 4 + b"\xff\xd9"
    frame = CameraFrame(src="s", seq=3, camera="tablet", jpeg=jpeg, width=4, height=4, intrinsics=[1, 1, 2, 2])
    payload = encode(frame)
    kept, cut = without_jpeg(payload, jpeg)
    assert len(kept) == len(payload) - len(jpeg) and jpeg not in kept
    assert with_jpeg(WireRecord("camera/tablet/frame", 1, kept, cut), jpeg) == payload
    assert without_jpeg(payload, b"not in it") == (payload, -1)


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
    timebase = Timebase(1_800_000_000_000_000_000)
    profile = FoxgloveProfile(FoxgloveSink(path), keys, load_site(), timebase, image_scale=0.5)
    profile.start(timebase.at(0.0))
    profile.origin_fixed()
    profile.handle(frame, keys.camera_frame("tablet"), encode(frame))
    profile.handle(overlay, keys.overlay("tablet"), encode(overlay))
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
        FoxgloveProfile(FoxgloveSink(None), keys, load_site(), timebase, image_scale=1.5)
