"""ROS 2 bags of the recorded mission, read back with ``rosbags`` (an independent reader): a Humble bag
recorded live (``arroch up --record-profile ros2 --ros-distro humble``) and a Jazzy bag converted
offline from ``run.mcap`` (``arroch runs export``), each with the metadata its distribution's rosbag2
writes and reads (rosbag2's ``humble``/``jazzy`` sources, as :mod:`services.recorder.rosbag` cites
them), ``/clock``, the bridge's frames and marker namespaces, poses equal to the recorded RobotPoses
and each robot at every ``delivered`` event inside the object's destination room. The offline
conversion is the live one: a Humble export equals the live bag."""

from __future__ import annotations

import json
import math
import subprocess
from collections import defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from ruamel.yaml import YAML

from protocol.messages import Clock, RobotPose
from protocol.site import load_site
from runtime.ros2.markers import SiteState, site_markers
from runtime.ros2.types import PUBLISHED_HASHES, TF_MESSAGE
from services.recorder.reading import messages, metadata
from tests.procs import ROOT, arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/arroch/r0/pose": "geometry_msgs/msg/PoseStamped",
    "/arroch/r0/path": "nav_msgs/msg/Path",
    "/arroch/camera/tablet/image/compressed": "sensor_msgs/msg/CompressedImage",
    "/arroch/camera/tablet/camera_info": "sensor_msgs/msg/CameraInfo",
    "/arroch/site": "visualization_msgs/msg/MarkerArray",
    "/rosout": "rcl_interfaces/msg/Log",
}
# metadata.yaml's keys as each distribution's rosbag2 writes them (rosbag2_storage: metadata_io.cpp in
# humble, include/rosbag2_storage/yaml.hpp in jazzy).
BAG_KEYS = {
    "version",
    "storage_identifier",
    "duration",
    "starting_time",
    "message_count",
    "topics_with_message_count",
    "compression_format",
    "compression_mode",
    "relative_file_paths",
    "files",
}
TOPIC_KEYS = {"name", "type", "serialization_format", "offered_qos_profiles"}
QOS_KEYS = {  # rosbag2_transport/src/rosbag2_transport/qos.cpp (humble), rosbag2_storage/src/qos.cpp (jazzy)
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
}


def export(run: Path, out: Path, distro: str) -> Path:
    result = subprocess.run(
        arroch("runs", "export", str(run), "--ros2", str(out), "--ros-distro", distro),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return out


@pytest.fixture(scope="module")
def jazzy(mission, tmp_path_factory) -> Path:
    return export(mission.run, tmp_path_factory.mktemp("export") / "jazzy", "jazzy")


def load_yaml(text: str):  # noqa: ANN201
    return YAML(typ="safe").load(text)


def bag_info(bag: Path) -> dict:
    return load_yaml((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def storage_metadata(bag: Path) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]], set[str]]:
    """The bag's MCAP file: its metadata records, each channel's metadata, its schemas' encodings."""
    with open(bag / f"{bag.name}_0.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        records = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        channels = {c.topic: dict(c.metadata) for c in summary.channels.values()}
        return records, channels, {s.encoding for s in summary.schemas.values()}


def check_common(bag: Path, info: dict) -> None:
    assert info["storage_identifier"] == "mcap" and info["relative_file_paths"] == [f"{bag.name}_0.mcap"]
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert info["message_count"] == sum(counts.values()) == info["files"][0]["message_count"] > 1000
    entries = {t["topic_metadata"]["name"]: t["topic_metadata"] for t in info["topics_with_message_count"]}
    for topic, msgtype in TYPES.items():
        entry = entries[topic]
        assert entry["type"] == msgtype and entry["serialization_format"] == "cdr" and counts[topic] > 0, topic
    _records, _channels, encodings = storage_metadata(bag)
    assert encodings == {"ros2msg"}


def test_the_humble_bag_has_humbles_metadata(mission):
    info = bag_info(mission.ros2)
    assert info["version"] == 5 and set(info) == BAG_KEYS  # no custom_data, ros_distro (versions 6, 8)
    check_common(mission.ros2, info)
    for topic in info["topics_with_message_count"]:
        meta = topic["topic_metadata"]
        assert set(meta) == TOPIC_KEYS  # no type_description_hash (version 7)
        qos = meta["offered_qos_profiles"]
        assert isinstance(qos, str)  # Humble reads a string holding YAML, not a list
        (profile,) = load_yaml(qos)
        assert set(profile) == QOS_KEYS and all(isinstance(profile[k], int) for k in ("history", "reliability"))
    records, channels, _ = storage_metadata(mission.ros2)
    assert records["rosbag2"] == {"ROS_DISTRO": "humble"}
    assert all(set(meta) == {"offered_qos_profiles"} for meta in channels.values())
    assert records["arroch"]["site_time_origin_ns"] == metadata(mission.recording)["site_time_origin_ns"]


def test_the_jazzy_bag_has_jazzys_metadata(jazzy):
    info = bag_info(jazzy)
    assert info["version"] == 9 and set(info) == BAG_KEYS | {"custom_data", "ros_distro"}
    assert info["ros_distro"] == "jazzy" and int(info["custom_data"]["site_time_origin_ns"]) > 0
    check_common(jazzy, info)
    store = get_typestore(Stores.ROS2_JAZZY)
    for topic in info["topics_with_message_count"]:
        meta = topic["topic_metadata"]
        assert set(meta) == TOPIC_KEYS | {"type_description_hash"}
        assert meta["type_description_hash"] == store.hash_rihs01(meta["type"])
        (profile,) = meta["offered_qos_profiles"]  # a YAML list, enums by name
        assert set(profile) == QOS_KEYS and profile["history"] == "keep_last"
        assert profile["reliability"] == "reliable" and profile["durability"] in ("volatile", "transient_local")
    tf = next(t for t in info["topics_with_message_count"] if t["topic_metadata"]["name"] == "/tf")
    assert tf["topic_metadata"]["type_description_hash"] == PUBLISHED_HASHES[TF_MESSAGE]  # as ROS 2 reports it
    records, channels, _ = storage_metadata(jazzy)
    assert load_yaml(records["rosbag2"]["serialized_metadata"]) == info
    assert channels["/tf"]["topic_type_hash"] == PUBLISHED_HASHES[TF_MESSAGE]


def read_bag(bag: Path) -> dict[str, list]:
    """Every message of the bag, deserialised with the definitions the bag carries."""
    out: dict[str, list] = defaultdict(list)
    with AnyReader([bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            out[connection.topic].append((timestamp, reader.deserialize(raw, connection.msgtype), bytes(raw)))
    return out


@pytest.mark.parametrize("which", ["humble", "jazzy"])
def test_the_bag_reads_back_with_clock_frames_markers_and_the_runs_poses(mission, jazzy, which):
    bag = mission.ros2 if which == "humble" else jazzy
    read = read_bag(bag)
    origin = int(metadata(mission.recording)["site_time_origin_ns"])
    recorded = list(messages(mission.recording))

    # /clock: the site clock on the wall clock, at every Clock message.
    clocks = [m.clock.sec * 10**9 + m.clock.nanosec for _t, m, _raw in read["/clock"]]
    expected = [origin + round(r.message.time * 1e9) for r in recorded if isinstance(r.message, Clock)]
    assert len(clocks) == len(expected) > 10 and sorted(clocks) == sorted(expected)

    # The bridge's frames and marker namespaces.
    parents_children = {(t.header.frame_id, t.child_frame_id) for _t, m, _r in read["/tf"] for t in m.transforms}
    assert {("map", f"{rid}/base_link") for rid in ("r0", "r1", "r2")} <= parents_children
    namespaces = {marker.ns for _t, m, _r in read["/arroch/site"] for marker in m.markers}
    bridge = {marker.ns for marker in site_markers(load_site(), SiteState(), 0.0).markers}
    assert namespaces == bridge
    assert len(read["/arroch/site"]) >= 2  # the whole site, then door changes

    # Poses: exactly the recorded RobotPoses, stamped on the wall clock like the recording.
    want: dict[tuple[str, int], list[RobotPose]] = defaultdict(list)  # a lockstep instant may have several
    for r in recorded:
        if isinstance(r.message, RobotPose):
            want[(r.message.robot, origin + round(r.message.stamp * 1e9))].append(r.message)
    poses: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    for rid in ("r0", "r1", "r2"):
        for timestamp, msg, _raw in read[f"/arroch/{rid}/pose"]:
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert stamp == timestamp and msg.header.frame_id == "map"
            q = msg.pose.orientation
            theta = 2 * math.atan2(q.z, q.w)
            assert any(
                (msg.pose.position.x, msg.pose.position.y) == (pose.x, pose.y)
                and abs(math.remainder(theta - pose.theta, math.tau)) < 1e-9
                for pose in want[(rid, stamp)]
            ), (rid, stamp)
            poses[rid].append(((stamp - origin) / 1e9, msg.pose.position.x, msg.pose.position.y))
    assert sum(len(rows) for rows in poses.values()) == sum(len(found) for found in want.values()) > 100
    assert all(raw[:2] == b"\x00\x01" for _t, _m, raw in read["/arroch/camera/tablet/image/compressed"])

    # Against the event log: where each robot stood when it delivered an object.
    site = load_site()
    events = [json.loads(line) for line in (mission.run / "events.jsonl").read_text().splitlines()]
    delivered = [e for e in events if e["kind"] == "delivered"]
    assert len(delivered) == 9
    for event in delivered:
        stamp, x, y = min(poses[event["robot"]], key=lambda row: abs(row[0] - event["stamp"]))
        assert abs(stamp - event["stamp"]) < 1.0
        room = site.room_at(x, y)
        assert room is not None and room.id == site.objects[event["object"]].deliver_to, (event, x, y)


def test_a_humble_export_of_the_recording_is_the_bag_recorded_live(mission, tmp_path):
    live = read_bag(mission.ros2)
    offline = read_bag(export(mission.run, tmp_path / "humble", "humble"))
    assert set(live) == set(offline)
    for topic in live:
        if topic == "/arroch/site":  # the first array is stamped when each began: the recorder before the run
            assert len(live[topic]) == len(offline[topic])
            continue
        assert sorted(raw for _t, _m, raw in live[topic]) == sorted(raw for _t, _m, raw in offline[topic]), topic
