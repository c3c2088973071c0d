"""The ros2 profile, read back with ``rosbags`` (an independent reader): the ROS 2 types RViz and
``ros2 bag play`` take, robot poses equal to the ones the default recording kept, and each robot's
pose at every ``delivered`` event of the event log inside the object's destination room."""

from __future__ import annotations

import json
import math

import pytest
from rosbags.highlevel import AnyReader

from protocol.messages import RobotPose
from protocol.site import load_site
from services.recorder.reading import messages

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TYPES = {
    "/tf": "tf2_msgs/msg/TFMessage",
    "/robot/r0/pose": "geometry_msgs/msg/PoseStamped",
    "/robot/r0/path": "nav_msgs/msg/Path",
    "/camera/tablet/image/compressed": "sensor_msgs/msg/CompressedImage",
    "/camera/tablet/camera_info": "sensor_msgs/msg/CameraInfo",
    "/site": "visualization_msgs/msg/MarkerArray",
    "/rosout": "rcl_interfaces/msg/Log",
}


def test_the_ros2_bag_reads_back_with_rosbags_and_its_poses_match_the_run(mission):
    assert (mission.ros2 / "metadata.yaml").is_file()
    poses: dict[str, list[tuple[float, float, float, float]]] = {}
    counts: dict[str, int] = {}
    with AnyReader([mission.ros2]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for topic, msgtype in TYPES.items():
            assert types.get(topic) == msgtype, (topic, types.get(topic))
        for connection, _t, raw in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            if connection.topic.endswith("/pose"):
                msg = reader.deserialize(raw, connection.msgtype)
                q = msg.pose.orientation
                stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                poses.setdefault(connection.topic.split("/")[2], []).append(
                    (stamp, msg.pose.position.x, msg.pose.position.y, 2 * math.atan2(q.z, q.w))
                )
            elif connection.topic == "/camera/tablet/image/compressed":
                assert bytes(reader.deserialize(raw, connection.msgtype).data[:2]) == b"\xff\xd8"
    assert counts["/site"] >= 2  # the whole scene, then door changes

    # The same poses as the default recording's RobotPose messages (both recorders heard one run).
    recorded = {}
    for rec in messages(mission.recording):
        if isinstance(rec.message, RobotPose):
            m = rec.message
            recorded[(m.robot, round(m.stamp, 6))] = (m.x, m.y, m.theta)
    matched = 0
    for rid, rows in poses.items():
        for stamp, x, y, theta in rows:
            want = recorded.get((rid, round(stamp, 6)))
            if want is None:
                continue
            matched += 1
            assert abs(x - want[0]) < 1e-9 and abs(y - want[1]) < 1e-9
            assert abs(math.remainder(theta - want[2], math.tau)) < 1e-6
    assert matched >= 0.9 * sum(len(rows) for rows in poses.values()) > 100

    # Against the event log: where each robot stood when it delivered an object.
    site = load_site()
    events = [json.loads(line) for line in (mission.run / "events.jsonl").read_text().splitlines()]
    delivered = [e for e in events if e["kind"] == "delivered"]
    assert len(delivered) == 9
    for event in delivered:
        rows = poses[event["robot"]]
        stamp, x, y, _ = min(rows, key=lambda row: abs(row[0] - event["stamp"]))
        assert abs(stamp - event["stamp"]) < 1.0
        room = site.room_at(x, y)
        assert room is not None and room.id == site.objects[event["object"]].deliver_to, (event, x, y)
