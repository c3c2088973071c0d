"""Which Zenoh keys a recorder hears, and the MCAP topics and frames it writes.

Every ARROCH message is kept twice over, for two readers: as JSON (with its type's JSON Schema) on
``/arroch/<key below the namespace>``, what Foxglove shows and plots; and as the bytes it travelled
as, in the file's wire store (:mod:`.wire`), what ``arroch replay`` publishes again. Beside these,
the viewer channels (Foxglove schemas) show the run; their topics are the constants below.

Frames are those of ``arroch ros2 bridge`` (:mod:`runtime.ros2.markers`): ``map``, each robot's
``<rid>/base_link``, and the tablet camera's ``<cid>/camera_optical_frame`` (OpenCV axes, REP 103's
optical frame), so a Foxglove recording, a ROS 2 bag and the live bridge line up.
"""

from __future__ import annotations

from protocol.graph import RECORDED
from protocol.keys import Keys
from protocol.messages import Message
from protocol.site import Site
from runtime.ros2.markers import MAP_FRAME, robot_frame

__all__ = ["MAP_FRAME", "robot_frame"]

MESSAGE_PREFIX = "/arroch/"

# Viewer channels.
SCENE = "/site"  # foxglove.SceneUpdate: walls, doors (live state), rooms, tags, objects, robot bodies
TF = "/tf"  # foxglove.FrameTransforms: map -> <rid>/base_link, map -> <cid>/camera_optical_frame
PATHS = "/paths"  # foxglove.SceneUpdate: each robot's intent (motion plan polyline), in its colour
PROGRESS = "/progress"  # JSON: deliveries and door openings so far (plot panel)
LOG = "/log"  # foxglove.Log: feedback, acks, events, the services' log lines


def camera_image(camera: str) -> str:
    return f"/camera/{camera}/image"  # foxglove.CompressedImage


def camera_calibration(camera: str) -> str:
    return f"/camera/{camera}/calibration"  # foxglove.CameraCalibration


def camera_overlay(camera: str) -> str:
    return f"/camera/{camera}/overlay"  # foxglove.ImageAnnotations


def camera_frame(camera: str) -> str:
    return f"{camera}/camera_optical_frame"


def recorded_keys(keys: Keys) -> list[tuple[str, type[Message]]]:
    """Every key expression a recorder subscribes to, with its message type (the service graph's
    list, :data:`protocol.graph.RECORDED`, under this namespace)."""
    return [(f"{keys.prefix}/{key}", msg_type) for key, msg_type in RECORDED]


def expected_keys(keys: Keys, site: Site) -> list[tuple[str, type[Message]]]:
    """The keys of :func:`recorded_keys` a run on ``site`` will use, wildcards filled with its robots and
    doors (a camera's or a sender's keys cannot be known beforehand)."""
    fill = {"robot": sorted(site.robots), "intent": sorted(site.robots), "door": sorted(site.doors)}
    out = []
    for key, msg_type in recorded_keys(keys):
        rest = below(keys, key)
        if "*" not in rest:
            out.append((key, msg_type))
        elif rest.split("/")[0] in fill:
            out += [(key_of(keys, message_topic(rest.replace("*", i))), msg_type) for i in fill[rest.split("/")[0]]]
    return out


def below(keys: Keys, key: str) -> str:
    """``arroch/office/robot/r0/pose`` → ``robot/r0/pose`` (the namespace is the file's metadata)."""
    prefix = keys.prefix + "/"
    if not key.startswith(prefix):
        raise ValueError(f"key {key!r} is not under {prefix!r}")
    return key[len(prefix) :]


def message_topic(rest: str) -> str:
    """The JSON channel of the messages on a key (given below the namespace): ``/arroch/robot/r0/pose``."""
    return MESSAGE_PREFIX + rest


def key_of(keys: Keys, topic: str) -> str:
    """The inverse of :func:`message_topic` in a namespace (possibly another than the recorded one)."""
    if not topic.startswith(MESSAGE_PREFIX):
        raise ValueError(f"topic {topic!r} is not a recorded ARROCH message")
    return f"{keys.prefix}/{topic[len(MESSAGE_PREFIX) :]}"
