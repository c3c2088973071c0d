"""Key expressions (DESIGN §4). Every key lives under ``arroch/<site>/``.

Use these builders rather than formatting keys by hand, so a renamed key changes in one place.
Liveliness tokens live under ``arroch/<site>/@liveliness/<service>/<id>``: the ``@`` chunk is
verbatim in zenoh 1.x, so ``arroch/<site>/**`` subscribers never see them.
"""

from __future__ import annotations

import re

ROOT = "arroch"
_CHUNK = re.compile(r"^[A-Za-z0-9_\-]+$")


def _chunk(value: str, what: str) -> str:
    if not _CHUNK.match(value):
        raise ValueError(f"{what} {value!r} cannot be used in a key expression (letters, digits, _ and - only)")
    return value


class Keys:
    """The key expressions of one site namespace (``site`` may carry a run suffix for experiments)."""

    def __init__(self, site: str) -> None:
        self.site = _chunk(site, "site name")
        self.prefix = f"{ROOT}/{self.site}"

    def _k(self, *parts: str) -> str:
        return "/".join((self.prefix, *parts))

    # sim → all
    def clock(self) -> str:
        return self._k("clock")

    def robot_pose(self, robot: str = "*") -> str:
        return self._k("robot", robot if robot == "*" else _chunk(robot, "robot id"), "pose")

    def robot_status(self, robot: str = "*") -> str:
        return self._k("robot", robot if robot == "*" else _chunk(robot, "robot id"), "status")

    def robot_command(self, robot: str = "*") -> str:
        return self._k("robot", robot if robot == "*" else _chunk(robot, "robot id"), "command")

    def robot_traffic(self, robot: str = "*") -> str:
        """What a robot process's executor tells the others about the traffic rules (RobotTraffic)."""
        return self._k("robot", robot if robot == "*" else _chunk(robot, "robot id"), "traffic")

    def door_state(self, door: str = "*") -> str:
        return self._k("door", door if door == "*" else _chunk(door, "door id"), "state")

    def door_sensor(self, door: str = "*") -> str:
        """A real door's sensor (a door controller, or a ROS 2 ``std_msgs/Bool`` through the bridge):
        DoorState that a simulator in sensor mode follows."""
        return self._k("door", door if door == "*" else _chunk(door, "door id"), "sensor")

    # the human and the study
    def human_state(self) -> str:
        return self._k("human", "state")

    def participant_action(self) -> str:
        return self._k("participant", "action")

    def questionnaire(self) -> str:
        return self._k("participant", "answers")

    def study_control(self) -> str:
        return self._k("study", "control")

    # planner → all
    def plan(self) -> str:
        return self._k("plan")

    def intent(self, robot: str = "*") -> str:
        return self._k("intent", robot if robot == "*" else _chunk(robot, "robot id"))

    # human side → restrictor → planner
    def feedback(self) -> str:
        return self._k("feedback")

    def feedback_ack(self, sender: str = "*") -> str:
        return self._k("feedback", "ack", sender if sender == "*" else _chunk(sender, "sender id"))

    def constraints(self) -> str:
        return self._k("constraints")

    def constraint_library(self) -> str:
        """Queryable: the constraint library the running restrictor accepts feedback from."""
        return self._k("constraints", "library")

    # cameras and AR
    def camera_frame(self, camera: str = "*") -> str:
        return self._k("camera", camera if camera == "*" else _chunk(camera, "camera id"), "frame")

    def camera_truth(self, camera: str = "*") -> str:
        return self._k("camera", camera if camera == "*" else _chunk(camera, "camera id"), "truth")

    def overlay(self, camera: str = "*") -> str:
        return self._k("ar", camera if camera == "*" else _chunk(camera, "camera id"), "overlay")

    def event(self) -> str:
        return self._k("event")

    def liveliness(self, service: str = "*", instance: str = "*") -> str:
        parts = [service if service == "*" else _chunk(service, "service name")]
        parts.append(instance if instance == "*" else _chunk(instance, "instance id"))
        return self._k("@liveliness", *parts)

    def stats(self, service: str = "*", instance: str = "*") -> str:
        """Queryable where each service answers with its counters (bad messages, drops, ...)."""
        parts = [service if service == "*" else _chunk(service, "service name")]
        parts.append(instance if instance == "*" else _chunk(instance, "instance id"))
        return self._k("stats", *parts)

    def drain(self, token: str = "*") -> str:
        """Where :meth:`runtime.service.Service.drain` sends its barrier query (a second session of
        the same process answers it), so that what a process published has left it before it exits."""
        return self._k("drain", token if token == "*" else _chunk(token, "drain token"))

    # diagnostics
    def ping_reply(self) -> str:
        """Where ``arroch ping serve`` echoes every pose it hears on ``robot/*/pose``."""
        return self._k("ping", "reply")

    def all(self) -> str:
        return self._k("**")


def chunk_at(key: str, index: int) -> str:
    """The ``index``-th chunk of a key (e.g. the robot id of ``arroch/office/robot/r0/pose`` is chunk 3)."""
    return key.split("/")[index]
