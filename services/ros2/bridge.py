"""The ``arroch ros2 bridge`` process: the team's state as ROS 2 topics, the human's buttons back.

Out (frame ``map``; topic names under ``--ros-namespace``, default ``/arroch``):
- ``/tf`` ``tf2_msgs/TFMessage``: ``map`` → ``<rid>/base_link`` for every RobotPose;
- ``<ns>/<rid>/path`` ``nav_msgs/Path``: each robot's Intent (its current trajectory; a row's
  time is the pose's stamp);
- ``<ns>/site`` ``visualization_msgs/MarkerArray``: walls, doors with their state, tags, objects, the
  robots' bodies (on their tf frames);
  again on every door or object change and once a second (RViz joining late, no durable QoS here);
- ``<ns>/feedback_ack`` ``std_msgs/String``: JSON ``{"request", "accepted", "reason",
  "constraint_id", "constraints_version"}`` answering each feedback.
In: ``<ns>/feedback`` ``std_msgs/String``: JSON ``{"kind": ..., "params": {...}}`` (the
restrictor's constraint library, e.g. ``{"kind": "door_unavailable", "params": {"door": "d_storage",
"minutes": 4}}``), sent to the restrictor as a Feedback; a payload that is not such JSON is
answered with ``accepted: false`` and the reason. JSON in a String keeps the bridge free of custom
message packages, which every ROS 2 machine would have to build; any ROS 2 tool can publish it
(``ros2 topic pub /arroch/feedback std_msgs/msg/String "{data: '{...}'}"``).
In, for each real door mapped in the config's ``[ros2.doors.<door>]`` tables: its sensor,
``std_msgs/Bool`` on the door's ``topic`` (true: open), republished as ``DoorState(door, open=data,
by="sensor")`` on ``door/<door>/sensor``, every message as it comes (a simulator with ``--doors
sensor`` follows it, and ignores repetitions).
"""

from __future__ import annotations

import json
import queue
import threading
from typing import Any

from protocol.events import Delivered
from protocol.messages import DoorState, Event, Intent, RobotPose, RobotStatus
from protocol.site.model import Site
from runtime.ros2 import types as ros
from runtime.ros2.keys import TopicNaming
from runtime.ros2.markers import SiteState, robot_frame, site_markers
from runtime.ros2.node import RosNode
from runtime.service import Service
from runtime.transport import ZenohOptions

MARKER_PERIOD = 1.0  # wall s between republications of the site markers
FEEDBACK_TIMEOUT = 5.0  # s to wait for the restrictor's ack


class BridgeService(Service):
    def __init__(
        self,
        site: Site,
        naming: TopicNaming,
        zenoh_options: ZenohOptions,
        *,
        namespace: str | None = None,
        ros_namespace: str = "/arroch",
        map_frame: str = "map",
        clock: Any = None,
        door_topics: dict[str, str] | None = None,
    ) -> None:
        super().__init__("ros2bridge", namespace or site.name, zenoh_options, clock=clock)
        self.door_topics = dict(door_topics or {})  # door id -> its sensor's std_msgs/Bool topic
        self.site = site
        self.naming = naming
        self.ros_namespace = ros_namespace
        self.map_frame = map_frame
        self.state = SiteState()
        self.poses: dict[str, tuple[float, float, float]] = {}
        self._markers_dirty = True
        self._feedback: queue.Queue = queue.Queue()
        self._feedback_thread: threading.Thread | None = None
        self._pubs: dict[str, Any] = {}

    def setup(self) -> None:
        node = RosNode(self, self.naming, "arroch_bridge", self.ros_namespace)
        self._tf = node.publisher("/tf", ros.TF_MESSAGE)
        self._markers = node.publisher("site", ros.MARKER_ARRAY)
        self._acks = node.publisher("feedback_ack", ros.STRING)
        self._paths = {rid: node.publisher(f"{rid}/path", ros.PATH) for rid in sorted(self.site.robots)}
        node.subscribe("feedback", ros.STRING, self._on_feedback)
        for door, topic in sorted(self.door_topics.items()):
            node.subscribe(topic, ros.BOOL, lambda msg, key, door=door: self._on_door_sensor(door, msg))
            self.log.info("door %s: its sensor is std_msgs/Bool on %s", door, node.topic(topic))
        keys = self.keys
        self.subscribe(keys.robot_pose(), RobotPose, self._on_pose, latest=True)
        self.subscribe(keys.intent(), Intent, self._on_intent)
        self.subscribe(keys.door_state(), DoorState, self._on_door)
        self.subscribe(keys.robot_status(), RobotStatus, self._on_status)
        self.subscribe(keys.event(), Event, self._on_event)
        self.every(MARKER_PERIOD, self._publish_markers, first=0.0)
        self.every(0.05, self._markers_if_changed)
        self._feedback_thread = threading.Thread(target=self._send_feedback, name="ros2-feedback", daemon=True)
        self._feedback_thread.start()

    def teardown(self) -> None:
        self._feedback.put(None)

    # ------------------------------------------------------------------ ARROCH → ROS 2

    def _on_pose(self, pose: RobotPose, key: str) -> None:
        self.poses[pose.robot] = (pose.x, pose.y, pose.theta)  # where a robot puts down what it carried
        tf = ros.transform_stamped(pose.stamp, self.map_frame, robot_frame(pose.robot), pose.x, pose.y, pose.theta)
        self._tf.publish(ros.t(ros.TF_MESSAGE)(transforms=[tf]))

    def _on_intent(self, intent: Intent, key: str) -> None:
        publisher = self._paths.get(intent.robot)
        if publisher is None:
            self.count("intents_unknown_robot")
            return
        PoseStamped = ros.t("geometry_msgs/msg/PoseStamped")
        poses = [
            PoseStamped(header=ros.header(max(t, 0.0), self.map_frame), pose=ros.pose(x, y, th))
            for t, x, y, th in intent.trajectory
        ]
        publisher.publish(ros.t(ros.PATH)(header=ros.header(intent.stamp, self.map_frame), poses=poses))

    def _on_door(self, door: DoorState, key: str) -> None:
        if self.state.door(door.door, door.open):
            self._markers_dirty = True

    def _on_status(self, status: RobotStatus, key: str) -> None:
        where = self.poses.get(status.robot, (0.0, 0.0, 0.0))[:2]
        if self.state.carrying(status.robot, list(status.carrying), where):
            self._markers_dirty = True

    def _on_event(self, event: Event, key: str) -> None:
        if event.kind == "delivered" and event.object:
            pose = event.data.pose if isinstance(event.data, Delivered) else None
            where = (float(pose[0]), float(pose[1])) if isinstance(pose, list) else None
            if self.state.delivered_at(event.object, where):
                self._markers_dirty = True

    def _markers_if_changed(self) -> None:
        if self._markers_dirty:
            self._publish_markers()

    def _publish_markers(self) -> None:
        self._markers_dirty = False
        self._markers.publish(site_markers(self.site, self.state, self.clock.now(), self.map_frame))

    # ------------------------------------------------------------------ ROS 2 → ARROCH

    def _on_feedback(self, msg: Any, key: str) -> None:
        try:
            request = json.loads(msg.data)
            if (
                not isinstance(request, dict)
                or not isinstance(request.get("kind"), str)
                or not isinstance(request.get("params", {}), dict)
            ):
                raise ValueError('expected a JSON object {"kind": "...", "params": {...}}')
        except ValueError as exc:
            self.count("feedback_refused_json")
            self._ack({"request": msg.data[:512], "accepted": False, "reason": f"not a feedback: {exc}"})
            return
        self._feedback.put(request)

    def _on_door_sensor(self, door: str, msg: Any) -> None:
        self.count("door_sensor_reports")
        self.publish(self.keys.door_sensor(door), DoorState(door=door, open=bool(msg.data), by="sensor"))

    def _send_feedback(self) -> None:
        # Blocking queries (the restrictor's client helper), so on a thread of their own.
        from runtime.feedback_client import send_feedback

        while True:
            request = self._feedback.get()
            if request is None:
                return
            try:
                ack = send_feedback(self, request["kind"], dict(request.get("params", {})), timeout=FEEDBACK_TIMEOUT)
            except Exception as exc:  # a feedback the protocol refuses, a closing session
                self.count("feedback_errors")
                self._ack({"request": request, "accepted": False, "reason": str(exc)[:512]})
                continue
            if ack is None:
                self._ack({"request": request, "accepted": False, "reason": "no answer from the restrictor"})
            else:
                self._ack(
                    {
                        "request": request,
                        "accepted": ack.accepted,
                        "reason": ack.reason,
                        "constraint_id": ack.constraint_id,
                        "constraints_version": ack.constraints_version,
                    }
                )

    def _ack(self, body: dict[str, Any]) -> None:
        try:
            self._acks.publish(ros.string(json.dumps(body, sort_keys=True)))
        except Exception:  # the session closed under the feedback thread
            self.count("feedback_ack_errors")
