"""The ROS 2 wire helpers (runtime/ros2): type hashes against the values ROS 2 publishes, keys and
tokens in rmw_zenoh's and zenoh-bridge-ros2dds's formats, the attachment layout, CDR round trips,
the robot config file's checks."""

from __future__ import annotations

import hashlib
import json
import math
import struct

import pytest
from rosbags.serde import SerdeError

from runtime.ros2 import types as ros
from runtime.ros2.attachment import Attachment, gid_of
from runtime.ros2.config import RosConfigError, load_ros2_config, parse_ros2_config
from runtime.ros2.keys import Qos, TopicNaming, full_topic


@pytest.mark.parametrize("typename", ros.USED_TYPES)
def test_type_hashes_match_what_ros2_publishes(typename):
    assert ros.type_hash(typename) == ros.PUBLISHED_HASHES[typename]


# ROS 2's field type ids (type_description_interfaces/msg/FieldType) of the one-field types below.
FIELD_TYPE_BOOLEAN, FIELD_TYPE_STRING = 15, 17


@pytest.mark.parametrize(("typename", "type_id"), [(ros.BOOL, FIELD_TYPE_BOOLEAN), (ros.STRING, FIELD_TYPE_STRING)])
def test_type_hashes_recomputed_from_the_msg_definition(typename, type_id):
    """``data`` is their only field (``bool data``, ``string data``): the hash is ROS 2's rule
    (rosidl_generator_type_description.calculate_type_hash) applied to that definition, by hand,
    independently of rosbags: SHA-256 of the type description as JSON, default values left out,
    with the C++ implementation's separators."""
    description = {
        "type_description": {
            "type_name": typename,
            "fields": [
                {
                    "name": "data",
                    "type": {"type_id": type_id, "capacity": 0, "string_capacity": 0, "nested_type_name": ""},
                }
            ],
        },
        "referenced_type_descriptions": [],
    }
    text = json.dumps(description, ensure_ascii=True, indent=None, separators=(", ", ": "), sort_keys=False)
    expected = "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()
    assert expected == ros.type_hash(typename) == ros.PUBLISHED_HASHES[typename]


def test_a_bool_round_trip():
    for value in (True, False):
        payload = ros.serialize(ros.boolean(value), ros.BOOL)
        assert payload == b"\x00\x01\x00\x00" + bytes([value]) and ros.deserialize(payload, ros.BOOL).data is value


def test_rmw_zenoh_keys_and_tokens():
    naming = TopicNaming("rmw_zenoh", 3)
    assert (
        naming.data_key("/r0/cmd_vel", ros.TWIST)
        == f"3/r0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{ros.PUBLISHED_HASHES[ros.TWIST]}"
    )
    assert naming.subscription_key("/r0/odom", ros.ODOMETRY) == "3/r0/odom/nav_msgs::msg::dds_::Odometry_/*"
    assert naming.node_token("abcd", 0, "/", "talker") == "@ros2_lv/3/abcd/0/0/NN/%/%/talker"
    token = naming.endpoint_token("abcd", 0, 10, "MS", "/", "listener", "/chatter", ros.STRING)
    # rmw_zenoh's design document's example for the listener demo (reliable, volatile, keep-last 10:
    # only the depth differs from rmw_zenoh's defaults, so only the depth is written).
    type_hash = ros.PUBLISHED_HASHES[ros.STRING]
    assert token == (
        f"@ros2_lv/3/abcd/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/{type_hash}/::,10:,:,:,,"
    )


def test_qos_chunks_list_only_what_differs_from_rmw_zenohs_defaults():
    assert Qos(depth=7).chunk() == "::,7:,:,:,,"  # the design document's talker
    assert Qos(depth=42).chunk() == "::,:,:,:,,"  # every value the default
    assert Qos(reliable=False, depth=1).chunk() == "2::,1:,:,:,,"  # best effort (an embedded client's cmd_vel)
    assert Qos(depth=1, transient_local=True).chunk() == ":1:,1:,:,:,,"  # amcl_pose
    # Eleven values in six ':'-separated groups, as rmw_zenoh's parser splits them.
    groups = Qos(depth=1, transient_local=True).chunk().split(":")
    assert [len(g.split(",")) for g in groups] == [1, 1, 2, 2, 2, 3]


def test_humble_keys_and_tokens_carry_no_type_hash():
    """Humble's rmw_zenoh writes TypeHashNotSupported where Jazzy writes the RIHS01 hash: a robot
    configured with type_hash = "TypeHashNotSupported" is spoken to in those keys."""
    config = parse_ros2_config({"robots": {"r0": {"type_hash": "TypeHashNotSupported"}}})
    humble, jazzy = config.naming("r0"), config.naming("r1")
    assert (
        humble.data_key("/r0/cmd_vel", ros.TWIST)
        == "0/r0/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported"
    )
    assert jazzy.data_key("/r1/cmd_vel", ros.TWIST).endswith(ros.PUBLISHED_HASHES[ros.TWIST])
    token = humble.endpoint_token("abcd", 0, 1, "MP", "/r0", "n", "/r0/cmd_vel", ros.TWIST)
    assert "/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported/" in token
    # Subscriptions take any hash: a Humble publisher is heard by a Jazzy-configured robot too.
    assert jazzy.subscription_key("/r1/odom", ros.ODOMETRY).endswith("/*")
    with pytest.raises(RosConfigError, match="type_hash"):
        parse_ros2_config({"robots": {"r0": {"type_hash": "RIHS01_x"}}})


def test_gid_is_xxh3_128_of_the_token():
    """rmw_zenoh_cpp's Entity::gid: XXH3-128 of the token, the 128-bit value's bytes low first.
    XXH3-128 of the empty input is 99aa06d3014798d86001c324468d497f (xxHash's reference)."""
    assert gid_of("") == bytes.fromhex("99aa06d3014798d86001c324468d497f")[::-1]
    token = "@ros2_lv/0/x/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/h/::,10:,:,:,,"
    assert gid_of(token) != gid_of(token + "x") and len(gid_of(token)) == 16


def test_ros2dds_keys_are_the_topic_names():
    assert TopicNaming("ros2dds").data_key("/r0/cmd_vel", ros.TWIST) == "r0/cmd_vel"
    assert TopicNaming("ros2dds", bridge_namespace="/fleet").data_key("/tf", ros.TF_MESSAGE) == "fleet/tf"


def test_topic_names():
    assert full_topic("/r0", "odom") == "/r0/odom"
    assert full_topic("/r0", "/tf") == "/tf"
    assert full_topic("/", "cmd_vel") == "/cmd_vel"
    with pytest.raises(ValueError):
        full_topic("/r0", "bad name")


def test_attachment_layout():
    gid = gid_of("@ros2_lv/0/x/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/h/::")
    data = Attachment(42, 1_700_000_000_123_456_789, gid).encode()
    # int64 sequence number, int64 timestamp (ns), then the 16-byte GID as a sequence (length 16).
    assert len(data) == 33 and struct.unpack_from("<qq", data) == (42, 1_700_000_000_123_456_789) and data[16] == 16
    assert Attachment.decode(data) == Attachment(42, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError):
        Attachment.decode(data[:-1])


def test_cdr_round_trip_of_an_odometry():
    msg = ros.odometry(12.5, "odom", "base_link", 1.25, -3.5, 2.9, 0.4, -0.2)
    payload = ros.serialize(msg, ros.ODOMETRY)
    assert payload[:4] == b"\x00\x01\x00\x00"  # CDR, little endian
    p = ros.pose_2d(ros.deserialize(payload, ros.ODOMETRY), ros.ODOMETRY)
    assert (p.x, p.y, p.v, p.omega, p.frame, p.child_frame) == (1.25, -3.5, 0.4, -0.2, "odom", "base_link")
    assert math.isclose(p.theta, 2.9, abs_tol=1e-12) and math.isclose(p.stamp, 12.5)
    with pytest.raises(SerdeError):  # a truncated payload is refused, not misread
        ros.deserialize(payload[:40], ros.ODOMETRY)


def test_config_file(tmp_path):
    f = tmp_path / "robots.toml"
    f.write_text(
        '[ros2]\nkey_format = "ros2dds"\ndomain = 5\n[ros2.robots.r0]\nnamespace = "/tb3"\npose_topic = "amcl_pose"\n'
        'pose_type = "pose"\nmap_to_odom = [1, 2, 0.5]\n'
    )
    config = load_ros2_config(f)
    assert config.naming().key_format == "ros2dds" and config.domain == 5
    link = config.link("r0")
    assert link.topic(link.pose_topic) == "/tb3/amcl_pose" and link.pose_typename == ros.POSE_COV_STAMPED
    assert link.map_to_odom == (1.0, 2.0, 0.5)
    assert config.link("r9").topic("cmd_vel") == "/r9/cmd_vel"  # a robot without a table: defaults
    f.write_text('[ros2]\ndomain = 5\n[ros2.robots.r1]\nkey_format = "ros2dds"\ndomain = 9\n')
    mixed = load_ros2_config(f)
    assert (mixed.naming("r1").key_format, mixed.naming("r1").domain) == ("ros2dds", 9)
    assert (mixed.naming("r0").key_format, mixed.naming("r0").domain) == ("rmw_zenoh", 5)
    assert mixed.with_overrides(domain=2).naming("r1").domain == 2  # the command line wins


def test_real_base_keys_in_the_config(tmp_path):
    f = tmp_path / "robots.toml"
    f.write_text(
        '[ros2.robots.r0]\ncmd_vel_type = "twist_stamped"\npose_type = "pose"\npose_topic = "amcl_pose"\n'
        'pose_durability = "transient_local"\nodom_topic = "odom"\nscan_topic = "scan"\nscan_timeout = 0.3\n'
        'obstacle_patience = 20\ntype_hash = "TypeHashNotSupported"\n'
    )
    link = load_ros2_config(f).link("r0")
    assert link.cmd_vel_typename == ros.TWIST_STAMPED and link.pose_durability == "transient_local"
    assert (link.topic(link.odom_topic), link.topic(link.scan_topic)) == ("/r0/odom", "/r0/scan")
    assert (link.scan_timeout, link.obstacle_patience, link.type_hash) == (0.3, 20.0, "TypeHashNotSupported")
    default = load_ros2_config(None).link("r0")
    assert (default.cmd_vel_typename, default.scan_topic, default.pose_durability) == (ros.TWIST, "", "volatile")


def test_twist_stamped_carries_stamp_and_frame():
    msg = ros.deserialize(
        ros.serialize(ros.cmd_vel(ros.TWIST_STAMPED, 0.4, -0.2, 1_700_000_000.25, "base_link"), ros.TWIST_STAMPED),
        ros.TWIST_STAMPED,
    )
    assert ros.twist_of(msg, ros.TWIST_STAMPED) == pytest.approx((0.4, -0.2))
    assert msg.header.frame_id == "base_link" and ros.seconds(msg.header.stamp) == pytest.approx(1_700_000_000.25)
    assert ros.twist_of(ros.cmd_vel(ros.TWIST, 0.4, -0.2, 0.0, ""), ros.TWIST) == pytest.approx((0.4, -0.2))


def test_door_sensors_in_the_config(tmp_path):
    from protocol.site import load_site
    from runtime.ros2.config import check_doors

    f = tmp_path / "robots.toml"
    f.write_text('[ros2]\ndomain = 4\n[ros2.doors.d_storage]\ntopic = "/building/storage_door"\n[ros2.doors.d_x]\n')
    config = load_ros2_config(f).with_overrides(key_format="ros2dds")
    assert config.doors["d_storage"].topic == "/building/storage_door"
    assert config.doors["d_x"].topic == "/doors/d_x/open"  # the default topic
    assert config.naming().data_key(config.doors["d_storage"].topic, ros.BOOL) == "building/storage_door"
    site = load_site()
    with pytest.raises(RosConfigError, match=r"robots.toml: ros2.doors.d_x: no such door on site office"):
        check_doors(config, site)
    f.write_text("[ros2.doors.d_lab]\n")
    with pytest.raises(RosConfigError, match=r"ros2.doors.d_lab: an automatic door of site office \(its human-op"):
        check_doors(load_ros2_config(f), site)
    f.write_text("[ros2.doors.d_storage]\n")
    check_doors(load_ros2_config(f), site)  # a human-operated door: fine


@pytest.mark.parametrize(
    "table, where",
    [
        ({"key_format": "dds"}, "ros2.key_format"),
        ({"domain": 999}, "ros2.domain"),
        ({"robots": {"r0": {"map_to_odom": [1, 2]}}}, "ros2.robots.r0.map_to_odom"),
        ({"robots": {"r0": {"pose_type": "gps"}}}, "ros2.robots.r0.pose_type"),
        ({"robots": {"r0": {"cmd_vel": "bad topic"}}}, "ros2.robots.r0.cmd_vel"),
        ({"robots": {"r0": {"speed": 1}}}, "ros2.robots.r0.speed"),
        ({"robots": {"r0": {"pose_timeout": -1}}}, "ros2.robots.r0.pose_timeout"),
        ({"robots": {"r0": {"key_format": "fastdds"}}}, "ros2.robots.r0.key_format"),
        ({"doors": {"d_storage": {"topic": "no spaces"}}}, "ros2.doors.d_storage.topic"),
        ({"doors": {"d_storage": {"topic": 3}}}, "ros2.doors.d_storage.topic"),
        ({"doors": {"d_storage": {"topc": "/x"}}}, "ros2.doors.d_storage.topc"),
        ({"doors": {"d_storage": "/x"}}, "ros2.doors.d_storage: expected a table"),
        ({"doors": {"bad door": {}}}, "ros2.doors.bad door: not a door id"),
        ({"doors": ["d_storage"]}, "ros2.doors: expected a table"),
        ({"robots": {"r0": {"cmd_vel_type": "twiststamped"}}}, "ros2.robots.r0.cmd_vel_type"),
        ({"robots": {"r0": {"pose_durability": "durable"}}}, "ros2.robots.r0.pose_durability"),
        ({"robots": {"r0": {"odom_topic": "odom"}}}, "ros2.robots.r0.odom_topic: odometry between"),
        ({"robots": {"r0": {"scan_topic": "bad scan"}}}, "ros2.robots.r0.scan_topic"),
        ({"robots": {"r0": {"scan_timeout": 0}}}, "ros2.robots.r0.scan_timeout"),
        ({"robots": {"r0": {"obstacle_patience": "long"}}}, "ros2.robots.r0.obstacle_patience"),
        ({"robots": {"r0": {"max_speed": math.inf}}}, "ros2.robots.r0.max_speed: expected a finite number"),
        ({"robots": {"r0": {"map_to_odom": [1, 2, math.nan]}}}, "ros2.robots.r0.map_to_odom: expected finite"),
        ({"robots": {"r0": {"robot": "r1"}}}, r"ros2.robots.r0.robot: unknown key \(known: base_frame, "),
        ({"robots": {"r0": "/r0"}}, "ros2.robots.r0: expected a table"),
        ({"colour": "red"}, r"ros2.colour: unknown key \(known: bridge_namespace, domain, doors, "),
        ({"robots": {"r0": {"pose_type": "gps"}}}, "ros2.robots.r0.pose_type: expected one of 'odometry', 'pose'"),
    ],
)
def test_config_errors_name_the_key(table, where):
    with pytest.raises(RosConfigError, match=f"robots.toml: {where}"):
        parse_ros2_config(table, "robots.toml")


def test_site_markers_follow_the_state():
    from protocol.site import load_site
    from runtime.ros2.markers import SiteState, site_markers

    site = load_site()
    state = SiteState(
        doors_open={"d_lab": True}, carried_by={"o0": "r0"}, delivered={"o1"}, object_at={"o1": (6.0, 2.0)}
    )
    msg = ros.deserialize(ros.serialize(site_markers(site, state, 3.0), ros.MARKER_ARRAY), ros.MARKER_ARRAY)
    by = {(m.ns, m.id): m for m in msg.markers}
    assert len([k for k in by if k[0] == "walls"]) == len(site.walls)
    doors = list(site.door_leaves)
    assert by[("doors", doors.index("d_lab"))].color.g > 0.5 and by[("doors", doors.index("d_storage"))].color.r > 0.5
    objects = list(site.objects)
    carried = by[("objects", objects.index("o0"))]
    assert carried.header.frame_id == "r0/base_link" and carried.frame_locked
    delivered = by[("objects", objects.index("o1"))]
    assert (delivered.pose.position.x, delivered.pose.position.y) == (6.0, 2.0) and abs(
        delivered.color.a - 0.4
    ) < 1e-6  # float32
    assert {m.header.frame_id for m in msg.markers if m.ns == "robots"} == {f"{rid}/base_link" for rid in site.robots}
