"""The real-world rehearsal of a study trial: a participant in place of the simulated human, real
doors, robots driven through ROS 2.

``arroch sim --ros2-bases --human participant --doors sensor`` plays the robots' ROS 2 bases (Twist
in, Odometry out) and nothing else a person would do: the human-operated door opens only when its
sensor says so, and the mission ends only when the participant says her task is done. Two
``arroch robot --ros2`` drivers drive the bases for the real planner; the door's sensor is a ROS 2
``std_msgs/Bool`` publisher (this test, through the project's own rmw_zenoh wire code: keys,
liveliness token, attachment, CDR) that ``arroch ros2 bridge`` turns into ``DoorState`` on
``door/d_storage/sensor``. The scripted person opens her door when a robot waits at it, lets it
shut once it has been open 12 site seconds and no robot is near it, and says her task is done after
5 site seconds. The mission completes with no closed-door crossing.
"""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import pytest
import zenoh

from protocol.messages import Clock, DoorState, Event, HumanState, ParticipantAction, RobotPose, RobotStatus
from protocol.site import loads_site
from runtime.ros2 import types as ros
from runtime.ros2.config import load_ros2_config
from runtime.ros2.node import RosNode
from tests.conftest import TestClient
from tests.procs import arroch
from tests.ros2.two_robots import SITE_TOML

pytestmark = pytest.mark.integration

DOOR = "d_storage"
TOPIC = "/doors/d_storage/open"
ROS2_TOML = f"""
[ros2]
key_format = "rmw_zenoh"
domain = 3

[ros2.doors.{DOOR}]
topic = "{TOPIC}"
"""
RATE = 3.0  # site seconds per wall second: the drivers run on the sim's clock, within their pose timeout
HOLD = 12.0  # site s she keeps the door open at least
TASK_DONE_AT = 5.0  # site s
BLOCK = zenoh.CongestionControl.BLOCK
TIMEOUT = 45.0  # wall s for the mission once the sim is up (about 10-15 s here)
DELIVERY_WALL_S = 2.0  # wall s a participant's message may take to reach the sim on a loaded machine


class Person:
    """The scripted participant and her door's sensor, run from the site's messages on a thread."""

    def __init__(self, client: TestClient, sensor: object) -> None:
        self.client = client
        self.sensor = sensor
        self.lock = threading.Lock()
        self.now = 0.0
        self.waiting: dict[str, str] = {}  # robot -> door it waits at
        self.poses: dict[str, tuple[float, float]] = {}
        self.door_open = False  # the world's view (door/d_storage/state)
        self.said_open_at: float | None = None  # site time she last opened it (the sensor said true)
        self.reports: list[tuple[float, bool]] = []  # (site time, open) the sensor published
        self.task_done_at: float | None = None  # site time (as she last heard it) she said her task was done
        self._stop = threading.Event()
        keys = client.keys
        client.subscribe(keys.clock(), Clock, self._on_clock, inline=True)
        client.subscribe(keys.robot_status(), RobotStatus, self._on_status, inline=True)
        client.subscribe(keys.robot_pose(), RobotPose, self._on_pose, inline=True)
        client.subscribe(keys.door_state(DOOR), DoorState, self._on_door, inline=True)
        self.thread = threading.Thread(target=self._run, name="person", daemon=True)
        self.thread.start()

    def _on_clock(self, msg: Clock, key: str) -> None:
        with self.lock:
            self.now = max(self.now, msg.time)

    def _on_status(self, msg: RobotStatus, key: str) -> None:
        with self.lock:
            if msg.state == "waiting_at_door":
                self.waiting[msg.robot] = msg.waiting_door
            else:
                self.waiting.pop(msg.robot, None)

    def _on_pose(self, msg: RobotPose, key: str) -> None:
        with self.lock:
            self.poses[msg.robot] = (msg.x, msg.y)

    def _on_door(self, msg: DoorState, key: str) -> None:
        with self.lock:
            self.door_open = msg.open

    def _say(self, is_open: bool, now: float) -> None:
        self.sensor.publish(ros.boolean(is_open))  # type: ignore[attr-defined]
        self.reports.append((now, is_open))

    def _run(self) -> None:
        center = (6.0, 4.0)
        while not self._stop.wait(0.02):
            with self.lock:
                now, waiting, poses = self.now, dict(self.waiting), dict(self.poses)
            if self.task_done_at is None and now >= TASK_DONE_AT:
                self.task_done_at = now
                self.client.publish(
                    self.client.keys.participant_action(),
                    ParticipantAction(participant="P01", trial="rehearsal", act="task_done"),
                )
            someone_waits = DOOR in waiting.values()
            if self.said_open_at is None:
                if someone_waits:
                    self.said_open_at = now
                    self._say(True, now)
            elif now - self.said_open_at >= HOLD and not someone_waits:
                if all(math.dist(p, center) > 1.5 for p in poses.values()):
                    self.said_open_at = None
                    self._say(False, now)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2)


def test_a_participant_trial_with_ros2_robots_and_a_real_door(spawn, router, namespace, client, tmp_path: Path):
    site_file = tmp_path / "rehearsal.toml"
    site_file.write_text(SITE_TOML)
    site = loads_site(SITE_TOML, "rehearsal.toml")
    cfg_file = tmp_path / "robots.toml"
    cfg_file.write_text(ROS2_TOML)
    config = load_ros2_config(cfg_file)
    common = ("--site", str(site_file), "--connect", router, "--namespace", namespace)
    ros2 = ("--ros2-config", str(cfg_file))

    events = client.collect(client.keys.event(), Event)
    humans = client.collect(client.keys.human_state(), HumanState)
    sensor_reports = client.collect(client.keys.door_sensor(DOOR), DoorState)
    node = RosNode(client, config.naming(), "door_sensor_d_storage", "/")
    person = Person(client, node.publisher(TOPIC, ros.BOOL))
    try:
        procs = {
            "planner": spawn(arroch("planner", *common), name="planner"),
            "bridge": spawn(arroch("ros2", "bridge", *common, *ros2), name="bridge"),
            **{
                rid: spawn(arroch("robot", "--ros2", "--robot", rid, *common, *ros2), name=rid)
                for rid in sorted(site.robots)
            },
        }
        for proc in procs.values():
            proc.wait_for("up on namespace", timeout=40)
        procs["bridge"].wait_for(f"door {DOOR}: its sensor is std_msgs/Bool on {TOPIC}")
        metrics = tmp_path / "metrics.json"
        events_out = tmp_path / "events.jsonl"
        sim = spawn(
            arroch(
                "sim",
                *common,
                *ros2,
                "--ros2-bases",
                "--human",
                "participant",
                "--doors",
                "sensor",
                "--trial",
                "rehearsal",
                "--rate",
                f"{RATE:g}",
                "--time-limit",
                "300",
                "--until-done",
                "--metrics-out",
                str(metrics),
                "--events-out",
                str(events_out),
            ),
            name="sim",
        )
        sim.wait_for("up on namespace", timeout=30)
        started = time.monotonic()
        # Bad input, dropped and counted, never a door opening: a door without a sensor, a report on
        # another door's key, a payload that is no DoorState; and a door act with no avatar to walk.
        keys = client.keys
        client.publish(keys.door_sensor("d_nowhere"), DoorState(door="d_nowhere", open=True, by="sensor"))
        client.publish(keys.door_sensor(DOOR), DoorState(door="d_other", open=True, by="sensor"))
        # BLOCK, as every Service publisher: a plain put may be dropped when the link is busy.
        client.session.put(keys.door_sensor(DOOR), b"\x00not a door state", congestion_control=BLOCK)
        walk = ParticipantAction(participant="P01", trial="rehearsal", act="go_to_door", door=DOOR)
        client.publish(keys.participant_action(), walk)
        code = sim.wait(TIMEOUT)
        wall = time.monotonic() - started
    finally:
        person.close()
    assert code == 0, sim.output[-4000:]
    assert "refused: door: no door 'd_nowhere' on site rehearsal" in sim.output
    assert "refused: door: a report of 'd_other' on 'd_storage''s sensor key" in sim.output
    assert "refused: act: go_to_door: the doors follow their sensors" in sim.output
    m = json.loads(metrics.read_text())
    assert m["completed"] is True, m
    assert sorted(o for r in m["robots"].values() for o in r["delivered"]) == ["o0", "o1"]
    assert m["closed_door_crossings"] == 0
    assert m["human"]["participant"] is True and m["human"]["doors"] == "sensor"
    # Her task ends when she says so (no simulated task draw): at the site time her word arrived. The
    # site runs at RATE x real time, so its trip through Zenoh costs RATE site s per wall s; beside a
    # loaded suite it arrived 1.8 site s after she sent it.
    said_at = person.task_done_at
    assert said_at is not None and said_at >= TASK_DONE_AT
    assert said_at <= m["agent_completion_times"]["human"] <= said_at + RATE * DELIVERY_WALL_S
    # Every opening of her door came from its sensor, and counts as hers.
    log = [json.loads(line) for line in events_out.read_text().splitlines()]
    opened = [e for e in log if e["kind"] == "door_opened"]
    assert opened and all(e["door"] == DOOR and e["data"]["by"] == "sensor" for e in opened)
    assert m["door_openings"][DOOR] == {"human": len(opened)} and m["human"]["door_openings"] >= len(opened)
    # The sensor's ROS 2 messages reached the sim through the bridge, as DoorState on door/<d>/sensor.
    assert person.reports and person.reports[0][1] is True
    seen = []
    while not sensor_reports.empty():
        seen.append(sensor_reports.get_nowait()[0])
    bridged = [d for d in seen if d.src.startswith("ros2bridge")]
    assert [(d.door, d.open, d.by) for d in bridged] == [(DOOR, o, "sensor") for _, o in person.reports]
    assert len(seen) == len(bridged) + 1  # and the test's own report on the wrong key
    # Her state said "sensor" (no avatar), and the mission's end came after her task and both deliveries.
    states = []
    while not humans.empty():
        states.append(humans.get_nowait()[0])
    assert states and {h.mode for h in states} == {"sensor"} and {h.place for h in states} == {"desk"}
    assert any(h.task_done for h in states)
    kinds = []
    while not events.empty():
        kinds.append(events.get_nowait()[0].kind)
    assert kinds.count("delivered") == 2 and kinds[-1] == "mission_done" and "closed_door_crossing" not in kinds
    # The drivers run on the sim's clock beside it: a command planned from a pose a moment old may be
    # refused by the driver's start check (the planner plans anew); nothing else may fail.
    failed = [e["data"].get("reason", "") for e in log if e["kind"] == "action_failed"]
    assert len(failed) <= 2 and all("trajectory starts" in r or "does not cross" in r for r in failed), failed
    counters = m["run"]["counters"]
    assert counters["door_sensor_refused"] == 2 and counters["door_sensor_reports"] == len(person.reports)
    assert counters.get(f"bad_messages:{keys.door_sensor(DOOR)}") == 1, counters
    assert counters["participant_actions_refused"] == 1 and counters["participant_actions"] == 1
    print(
        f"rehearsal: mission {m['time']:.1f} site s in {wall:.1f} wall s, {len(opened)} sensor opening(s), "
        f"{len(person.reports)} sensor reports, {len(failed)} failed actions"
    )
