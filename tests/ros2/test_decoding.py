"""Every ROS 2 message ARROCH publishes, read back off Zenoh and decoded with ``rosbags``, matches the
ARROCH pose it came from (≤ 1 mm, ≤ 0.1°); samples carry rmw_zenoh's attachment and the topics are
announced with rmw_zenoh's liveliness tokens (what ``ros2 topic list`` reads).

- the bridge: RobotPose → ``/tf``, Intent → ``/arroch/<rid>/path``, DoorState → ``/arroch/site``
  markers, and feedback in / ack out through a real restrictor;
- the driver: the base's ``/r1/odom`` (decoded here) → the driver's RobotPose, through the map→odom
  transform of r1's start pose (rotated by -90°), or of the map→odom transform it reads on `/tf`, or
  straight from a localiser's PoseWithCovarianceStamped;
- the simulated bases: each `/<rid>/odom`, moved by its map→odom transform, is the robot's pose in the
  simulator; a Twist moves it and the base stops on its own without one.
"""

from __future__ import annotations

import json
import math
import queue
import time

from protocol.messages import DoorState, Intent, RobotPose
from protocol.site import load_site
from runtime.ros2 import types as ros
from runtime.ros2.attachment import Attachment
from runtime.ros2.config import Ros2Config
from runtime.ros2.keys import TopicNaming
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.ros2.harness import FakeBase, straight_command

SITE = load_site()
MM = 1e-3
DEG = math.radians(0.1)
NAMING = TopicNaming("rmw_zenoh", 0)


def angle_gap(a: float, b: float) -> float:
    return abs(math.atan2(math.sin(a - b), math.cos(a - b)))


class Tap:
    """Raw samples on a ROS 2 topic's rmw_zenoh key: (decoded message, attachment)."""

    def __init__(self, client, topic: str, typename: str) -> None:
        self.typename = typename
        self.q: queue.Queue = queue.Queue()
        key = NAMING.data_key(topic, typename)

        def on_sample(sample) -> None:  # noqa: ANN001
            att = sample.attachment
            self.q.put(
                (
                    ros.deserialize(sample.payload.to_bytes(), typename),
                    Attachment.decode(att.to_bytes()) if att is not None else None,
                )
            )

        client.hold(client.session.declare_subscriber(key, on_sample))

    def next(self, predicate=lambda m: True, timeout: float = 10.0):  # noqa: ANN001
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                msg, att = self.q.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            if predicate(msg):
                return msg, att
        raise AssertionError(f"no matching {self.typename} within {timeout} s")


def test_bridge_messages_decode_to_the_poses_they_came_from(spawn, router, namespace, client, tmp_path):
    restrictor = spawn(
        arroch(
            "restrictor",
            "--connect",
            router,
            "--namespace",
            namespace,
            "--fresh",
            "--clock",
            "wall",
            "--state-dir",
            str(tmp_path),
        ),
        name="restrictor",
    )
    bridge = spawn(
        arroch("ros2", "bridge", "--connect", router, "--namespace", namespace, "--clock", "wall"), name="bridge"
    )
    bridge.wait_for("ros2bridge-", timeout=20)
    restrictor.wait_for("restrictor-", timeout=20)
    tf = Tap(client, "/tf", ros.TF_MESSAGE)
    path = Tap(client, "/arroch/r1/path", ros.PATH)
    markers = Tap(client, "/arroch/site", ros.MARKER_ARRAY)
    acks = Tap(client, "/arroch/feedback_ack", ros.STRING)
    time.sleep(0.5)  # the subscriptions reach the router

    # RobotPose -> /tf
    pose = RobotPose(robot="r0", x=3.2567891, y=5.1234567, theta=2.4681357, vel=0.3, omega=0.1)
    client.publish(client.keys.robot_pose("r0"), pose)
    msg, att = tf.next(lambda m: m.transforms[0].child_frame_id == "r0/base_link")
    tr = msg.transforms[0]
    assert tr.header.frame_id == "map"
    assert abs(tr.transform.translation.x - pose.x) <= MM and abs(tr.transform.translation.y - pose.y) <= MM
    assert angle_gap(ros.yaw_of(tr.transform.rotation), pose.theta) <= DEG
    assert att is not None and len(att.gid) == 16 and att.sequence_number >= 1

    # Intent -> Path
    rows = [[10.0 + i, 12.5 + 0.1 * i, 8.0 - 0.2 * i, -1.5707963 + 0.05 * i] for i in range(12)]
    client.publish(
        client.keys.intent("r1"),
        Intent(robot="r1", plan_id=7, action_id=3, action="approach", args=["d_lab"], trajectory=rows),
    )
    msg, _ = path.next()
    assert len(msg.poses) == len(rows)
    for row, ps in zip(rows, msg.poses, strict=True):
        assert abs(ps.pose.position.x - row[1]) <= MM and abs(ps.pose.position.y - row[2]) <= MM
        assert angle_gap(ros.yaw_of(ps.pose.orientation), row[3]) <= DEG
        assert abs(ros.seconds(ps.header.stamp) - row[0]) <= 1e-6

    # DoorState -> the door's leaf marker, standing open
    door_ids = list(SITE.door_leaves)
    client.publish(client.keys.door_state("d_lab"), DoorState(door="d_lab", open=True, by="r1"))
    leaf = SITE.door_leaves["d_lab"]

    def door_open(m) -> bool:  # noqa: ANN001
        d = [k for k in m.markers if k.ns == "doors" and k.id == door_ids.index("d_lab")]
        return bool(d) and d[0].color.g > 0.5

    msg, _ = markers.next(door_open)
    (d,) = [k for k in msg.markers if k.ns == "doors" and k.id == door_ids.index("d_lab")]
    hx, hy = leaf.hinge
    assert abs(d.pose.position.x - (hx + math.cos(leaf.open_yaw) * leaf.length / 2)) <= MM
    assert abs(d.pose.position.y - (hy + math.sin(leaf.open_yaw) * leaf.length / 2)) <= MM
    assert angle_gap(ros.yaw_of(d.pose.orientation), leaf.open_yaw) <= DEG
    walls = [k for k in msg.markers if k.ns == "walls"]
    assert len(walls) == len(SITE.walls)
    tags = {k.id: k for k in msg.markers if k.ns == "tags"}
    for lm in SITE.landmarks:
        assert (
            abs(tags[lm.tag].pose.position.x - lm.position[0]) <= MM
            and abs(tags[lm.tag].pose.position.y - lm.position[1]) <= MM
        )

    # Feedback in (std_msgs/String JSON) -> the restrictor -> ack out
    from runtime.ros2.node import RosNode

    node = RosNode(client, NAMING, "test_tablet", "/arroch")
    feedback = node.publisher("feedback", ros.STRING)
    time.sleep(0.3)
    feedback.publish(ros.string("not json"))
    msg, _ = acks.next()
    assert json.loads(msg.data)["accepted"] is False
    feedback.publish(
        ros.string(json.dumps({"kind": "door_unavailable", "params": {"door": "d_storage", "minutes": 4}}))
    )
    msg, _ = acks.next(timeout=15)
    assert json.loads(msg.data).get("accepted") is True, msg.data
    assert json.loads(msg.data)["constraint_id"]

    # The topics are announced as rmw_zenoh does (what `ros2 topic list` reads).
    tokens = [
        str(r.ok.key_expr) for r in client.session.liveliness().get("@ros2_lv/0/**", timeout=3) if r.ok is not None
    ]
    assert any("/NN/%/%arroch/arroch_bridge" in t for t in tokens), tokens
    assert any(
        t.endswith(
            f"/MP/%/%arroch/arroch_bridge/%tf/tf2_msgs::msg::dds_::TFMessage_/{ros.PUBLISHED_HASHES[ros.TF_MESSAGE]}/::,10:,:,:,,"
        )
        for t in tokens
    ), tokens


def test_driver_pose_matches_the_odometry_it_came_from(spawn, router, namespace, client):
    robot = "r1"  # starts facing -y: the map->odom transform rotates
    start = SITE.robots[robot].start
    base = FakeBase(client, robot, start, Ros2Config())
    try:
        odom = Tap(client, "/r1/odom", ros.ODOMETRY)
        twist = Tap(client, "/r1/cmd_vel", ros.TWIST)
        poses = client.collect(client.keys.robot_pose(robot), RobotPose)
        spawn(
            arroch("robot", "--ros2", "--robot", robot, "--connect", router, "--namespace", namespace), name="robot"
        ).wait_for("robot robot-r1-", timeout=20)
        base.first_zero_after(0.0, timeout=10)
        client.publish(client.keys.robot_command(robot), straight_command(robot, start, 1.2, opening="d_lab"))
        base.wait_moving()
        time.sleep(1.0)
        seen = []
        while not odom.q.empty():
            m, att = odom.q.get()
            p = ros.pose_2d(m, ros.ODOMETRY)
            c, s = math.cos(start[2]), math.sin(start[2])
            seen.append((start[0] + c * p.x - s * p.y, start[1] + s * p.x + c * p.y, start[2] + p.theta))
            assert att is not None
        moved = [p for p in seen if math.dist(p[:2], start[:2]) > 0.05]
        assert moved, "the base did not move"
        checked = 0
        while True:
            try:
                rp, _ = poses.get_nowait()
            except queue.Empty:
                break
            best = min(seen, key=lambda q: math.dist(q[:2], (rp.x, rp.y)))
            assert math.dist(best[:2], (rp.x, rp.y)) <= MM and angle_gap(best[2], rp.theta) <= DEG, (rp, best)
            checked += 1
        assert checked >= 10
        msg, att = twist.next()
        assert att is not None and len(att.gid) == 16
    finally:
        base.close()


def test_driver_takes_map_to_odom_from_tf(spawn, router, namespace, client, tmp_path):
    robot = "r1"
    config_file = tmp_path / "robots.toml"
    config_file.write_text('[ros2.robots.r1]\ntf_topic = "/tf"\n')
    base = FakeBase(client, robot, SITE.robots[robot].start, Ros2Config())
    try:
        from runtime.ros2.node import RosNode

        tf = RosNode(client, NAMING, "test_localiser", "/").publisher("/tf", ros.TF_MESSAGE)
        map_to_odom = (12.0, 8.2, -1.4)  # not the start pose: the pose must come from tf
        poses = client.collect(client.keys.robot_pose(robot), RobotPose)
        spawn(
            arroch(
                "robot",
                "--ros2",
                "--robot",
                robot,
                "--connect",
                router,
                "--namespace",
                namespace,
                "--ros2-config",
                str(config_file),
            ),
            name="robot",
        ).wait_for("robot robot-r1-", timeout=20)
        deadline = time.monotonic() + 10
        while not poses.qsize() and time.monotonic() < deadline:
            tf.publish(ros.t(ros.TF_MESSAGE)(transforms=[ros.transform_stamped(0.0, "map", "odom", *map_to_odom)]))
            time.sleep(0.1)
        pose = wait_for_message(poses, timeout=5)
        assert abs(pose.x - map_to_odom[0]) <= MM and abs(pose.y - map_to_odom[1]) <= MM
        assert angle_gap(pose.theta, map_to_odom[2]) <= DEG
    finally:
        base.close()


def test_simulated_bases_publish_their_robots_poses_as_odometry(spawn, router, namespace, client):
    """``arroch sim --ros2-bases``: each base's odometry, read back and moved by its map->odom
    transform (the start pose), is where the simulator has the robot; a Twist moves it."""
    taps = {rid: Tap(client, f"/{rid}/odom", ros.ODOMETRY) for rid in SITE.robots}
    spawn(arroch("sim", "--connect", router, "--namespace", namespace, "--ros2-bases"), name="sim").wait_for(
        "sim sim-", timeout=20
    )
    for rid, tap in taps.items():
        msg, att = tap.next(timeout=10)
        p = ros.pose_2d(msg, ros.ODOMETRY)
        assert (p.frame, p.child_frame) == ("odom", "base_link") and att is not None
        x0, y0, th0 = SITE.robots[rid].start
        c, s = math.cos(th0), math.sin(th0)
        assert abs(x0 + c * p.x - s * p.y - x0) <= MM and abs(y0 + s * p.x + c * p.y - y0) <= MM
        assert angle_gap(th0 + p.theta, th0) <= DEG
    from runtime.ros2.node import RosNode

    cmd_vel = RosNode(client, NAMING, "test_teleop", "/r0").publisher("cmd_vel", ros.TWIST)
    for _ in range(10):  # 1 s at 0.4 m/s, straight ahead
        cmd_vel.publish(ros.twist(0.4, 0.0))
        time.sleep(0.1)
    msg, _ = taps["r0"].next(lambda m: m.twist.twist.linear.x == 0.0 and m.pose.pose.position.x > 0.2, timeout=10)
    assert 0.2 < msg.pose.pose.position.x < 0.8 and abs(msg.pose.pose.position.y) <= MM  # then it stopped on its own


def test_driver_takes_its_pose_from_a_localisation_topic(spawn, router, namespace, client, tmp_path):
    """``pose_type = "pose"``: PoseWithCovarianceStamped in the map frame (e.g. amcl_pose), no transform."""
    from runtime.ros2.node import RosNode

    config_file = tmp_path / "robots.toml"
    config_file.write_text('[ros2.robots.r1]\npose_topic = "amcl_pose"\npose_type = "pose"\n')
    localiser = RosNode(client, NAMING, "test_amcl", "/r1").publisher("amcl_pose", ros.POSE_COV_STAMPED)
    twist = Tap(client, "/r1/cmd_vel", ros.TWIST)
    poses = client.collect(client.keys.robot_pose("r1"), RobotPose)
    spawn(
        arroch(
            "robot",
            "--ros2",
            "--robot",
            "r1",
            "--connect",
            router,
            "--namespace",
            namespace,
            "--ros2-config",
            str(config_file),
        ),
        name="robot",
    ).wait_for("robot robot-r1-", timeout=20)
    where = (12.3456, 7.6543, -1.2345)
    deadline = time.monotonic() + 10
    while not poses.qsize() and time.monotonic() < deadline:
        localiser.publish(ros.pose_with_covariance_stamped(0.0, "map", *where))
        time.sleep(0.1)
    pose = wait_for_message(poses, timeout=5)
    assert abs(pose.x - where[0]) <= MM and abs(pose.y - where[1]) <= MM and angle_gap(pose.theta, where[2]) <= DEG
    msg, _ = twist.next()  # every pose is answered
    assert msg.linear.x == 0.0


def test_nodes_of_one_session_share_one_id_counter_and_gids_are_rmw_zenohs(client):
    """Two nodes on one session, as the simulator's bases are: every node and entity id is drawn
    from one counter (as rmw_zenoh's context does), so no two tokens of the session share
    <node id>/<entity id>; a sample's attachment carries the GID rmw_zenoh computes from its
    publisher's token (XXH3-128); keep-last publishers drop rather than block under congestion."""
    import zenoh

    from runtime.ros2.attachment import gid_of
    from runtime.ros2.node import RosNode

    naming = TopicNaming("rmw_zenoh", 11)
    a = RosNode(client, naming, "node_a", "/r0")
    b = RosNode(client, naming, "node_b", "/r1")
    pub_a = a.publisher("cmd_vel", ros.TWIST)
    b.publisher("cmd_vel", ros.TWIST)
    b.subscribe("odom", ros.ODOMETRY, lambda msg, key: None)
    zid = str(client.session.info.zid())
    replies = client.session.liveliness().get(f"@ros2_lv/11/{zid}/**", timeout=3)
    tokens = sorted({str(r.ok.key_expr) for r in replies if r.ok is not None})  # a token may answer twice
    ids = [tuple(t.split("/")[3:5]) for t in tokens]
    assert len(tokens) == 5 and len(set(ids)) == 5, tokens  # two nodes, three endpoints
    entity_ids = [int(e) for _, e in ids]
    assert len(set(entity_ids)) == 5  # one counter: ids unique across the nodes too
    attachments: queue.Queue = queue.Queue()
    client.hold(
        client.session.declare_subscriber(
            naming.data_key("/r0/cmd_vel", ros.TWIST), lambda s: attachments.put(s.attachment.to_bytes())
        )
    )
    time.sleep(0.3)
    pub_a.publish(ros.twist(0.1, 0.0))
    gid = Attachment.decode(attachments.get(timeout=5)).gid
    (token,) = [t for t in tokens if "/MP/" in t and "%r0%cmd_vel" in t]
    assert gid == gid_of(token)
    assert pub_a._publisher.congestion_control == zenoh.CongestionControl.DROP
