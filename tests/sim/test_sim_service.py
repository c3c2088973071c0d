"""``arroch sim`` as a real process on Zenoh, driven by a planner stand-in (tests/sim/standin.py)."""

from __future__ import annotations

import json
import signal
import threading
import time

import pytest

from protocol.messages import Clock, ConstraintSet, DoorState, Event, RobotCommand, RobotPose, RobotStatus
from protocol.site import load_site
from tests.conftest import TestClient, wait_for_message
from tests.procs import arroch
from tests.sim.standin import LossyStandIn, StandInPlanner

pytestmark = pytest.mark.integration

HUMAN_TOML = """[human]
task_mean = 300.0
task_std = 30.0
focus_count = 2
focus_min_minutes = 1
focus_max_minutes = 2
"""


def sim_argv(router: str, namespace: str, *extra: str) -> list[str]:
    return arroch("sim", "--connect", router, "--namespace", namespace, *extra)


class Running:
    """A StandInPlanner on its own thread, stopped on exit."""

    def __init__(self, planner: StandInPlanner) -> None:
        self.planner = planner

    def __enter__(self) -> StandInPlanner:
        self.planner.open()
        self.thread = threading.Thread(target=self.planner.run, daemon=True)
        self.thread.start()
        return self.planner

    def __exit__(self, *exc: object) -> None:
        self.planner.stop()
        self.thread.join(5)


def drain(q) -> list:
    out = []
    while not q.empty():
        out.append(q.get()[0])
    return out


def test_two_seeded_lockstep_runs_give_identical_event_logs_even_when_plans_are_lost(router, client, spawn, tmp_path):
    """The second run's planner loses two plans and their commands on the way: the simulator, paused
    for them, asks for them again and takes them as if they had come, so nothing that happens differs."""
    site = load_site(None)
    human = tmp_path / "human.toml"
    human.write_text(HUMAN_TOML)
    logs, wire, feedback = [], [], []
    for run in range(2):
        namespace = f"{client.keys.site}{run}"
        watcher = TestClient(namespace, router).open()
        try:
            events = watcher.collect(watcher.keys.event(), Event)
            clocks = watcher.collect(watcher.keys.clock(), Clock)
            statuses = watcher.collect(watcher.keys.robot_status(), RobotStatus)
            doors = watcher.collect(watcher.keys.door_state(), DoorState)
            poses = watcher.collect(watcher.keys.robot_pose(), RobotPose)
            out = tmp_path / f"events{run}.jsonl"
            metrics = tmp_path / f"metrics{run}.json"
            sim = spawn(
                sim_argv(
                    router,
                    namespace,
                    "--mode",
                    "lockstep",
                    "--seed",
                    "5",
                    "--method",
                    "arroch",
                    "--human-config",
                    str(human),
                    "--until-done",
                    "--events-out",
                    str(out),
                    "--metrics-out",
                    str(metrics),
                ),
                name=f"sim{run}",
            )
            sim.wait_for("up on namespace")
            if run == 0:
                # No planner yet: lockstep time must not move.
                first = wait_for_message(clocks, timeout=10)
                time.sleep(1.0)
                later = drain(clocks) or [first]
                assert all(c.time == 0.0 and c.paused and c.mode == "lockstep" for c in [first, *later])
                assert later[-1].world_version == 1 and later[-1].awaiting == "plan"  # what the planner answers at once
            standin = StandInPlanner if run == 0 else LossyStandIn
            with Running(standin(site, namespace, router)) as planner:
                assert sim.wait(90) == 0, sim.output
                feedback.append([(f.kind, dict(f.params), f.src) for f in planner.feedback])
            if run == 1:
                assert planner.lost >= 2, "the lossy stand-in lost nothing"
                assert sim.output.count("asking the planner for its plan and commands again") >= 2, sim.output
            time.sleep(0.3)
            wire.append(drain(events))
            # Statuses, door states and poses went out too, with what the planner needs.
            st = drain(statuses)
            assert any(x.state == "waiting_at_door" and x.waiting_door == "d_storage" for x in st)
            assert any(x.state == "unloading" and x.carrying for x in st)
            assert (
                max(x.world_version for x in st)
                == json.loads(out.read_text().splitlines()[-1])["data"]["world_versions"]
            )
            ds = drain(doors)
            assert any(d.door == "d_storage" and d.open and d.by == "human" and d.until > d.stamp for d in ds)
            ps = drain(poses)
            assert {p.robot for p in ps} == {"r0", "r1", "r2"} and max(p.stamp for p in ps) > 100.0
            logs.append(out.read_text().splitlines())
            m = json.loads(metrics.read_text())
        finally:
            watcher.close()
        assert "mission done" in sim.output
    assert logs[0] == logs[1]  # event for event, byte for byte
    events = [json.loads(line) for line in logs[0]]
    kinds = [e["kind"] for e in events]
    assert kinds.count("delivered") == 9 and kinds[-1] == "mission_done"
    assert "waiting_at_door" in kinds and "human_opens_door" in kinds and "human_done" in kinds
    # Feedback really went over Zenoh to the (stand-in) restrictor, and was acknowledged.
    assert feedback[0] and all(
        kind == "door_unavailable" and set(p) == {"door", "minutes"} for kind, p, _src in feedback[0]
    )
    assert [(k, p) for k, p, _ in feedback[0]] == [(k, p) for k, p, _ in feedback[1]]
    assert kinds.count("feedback_sent") == len(feedback[0]) == m["feedback"]["accepted"]
    # What went over the wire is what was logged, and mission_done carries the metrics.
    assert [(e.kind, e.stamp) for e in wire[1]] == [(e["kind"], e["time"]) for e in events]
    assert (
        wire[1][-1].data.team_completion_time == events[-1]["data"]["team_completion_time"] == m["team_completion_time"]
    )
    assert m["run"]["realtime_factor"] > 1.0


def test_human_feedback_reaches_the_real_restrictor(router, client, spawn, tmp_path):
    site = load_site(None)
    human = tmp_path / "human.toml"
    # One focus interval, always declared: the restrictor must get exactly one door_unavailable.
    human.write_text(
        "[human]\ntask_mean = 240.0\ntask_std = 0.0\nfocus_count = 1\nfocus_min_minutes = 2\nfocus_max_minutes = "
        "2\ndeclare_probability = 1.0\n"
    )
    namespace = client.keys.site
    sets = client.collect(client.keys.constraints(), ConstraintSet)
    events = client.collect(client.keys.event(), Event)
    spawn(
        arroch(
            "restrictor",
            "--connect",
            router,
            "--namespace",
            namespace,
            "--clock",
            "sim",
            "--state-dir",
            str(tmp_path / "state"),
        ),
        name="restrictor",
    ).wait_for("up on namespace")
    sim = spawn(
        sim_argv(router, namespace, "--mode", "lockstep", "--seed", "2", "--human-config", str(human), "--until-done"),
        name="sim",
    )
    sim.wait_for("up on namespace")
    with Running(StandInPlanner(site, namespace, router, restrictor=False)):
        assert sim.wait(60) == 0, sim.output
    answered = wait_for_message(events, lambda e: e.kind == "feedback_answered", timeout=5)
    assert answered.data.accepted is True and answered.data.constraints_version >= 1
    cs = wait_for_message(sets, lambda s: any(c.kind == "door_unavailable" for c in s.constraints), timeout=5)
    (c,) = [c for c in cs.constraints if c.kind == "door_unavailable"]
    assert c.params == {"door": "d_storage", "minutes": 2}
    assert c.end - c.start == pytest.approx(120.0, abs=1.0)
    assert c.start == pytest.approx(answered.data.sent, abs=1.0)  # on the sim's clock


def test_bad_input_is_refused_counted_and_survived_then_sigterm_exits_cleanly(router, client, spawn):
    from protocol.codec import encode

    events = client.collect(client.keys.event(), Event)
    statuses = client.collect(client.keys.robot_status("*"), RobotStatus)
    sim = spawn(sim_argv(router, client.keys.site, "--mode", "lockstep"), name="sim")
    sim.wait_for("up on namespace")
    wait_for_message(statuses, lambda s: s.robot == "r0", timeout=10)
    key = client.keys.robot_command("r0")
    client.session.put(key, b"\x93not msgpack at all")
    client.session.put(key, encode(Event(kind="human_done", data={"task_duration": None})))
    client.publish(
        key,
        RobotCommand(
            robot="r0",
            plan_id=1,
            action_id=1,
            action="approach",
            args=["d_nowhere"],
            trajectory=[[0, 1.5, 5.0, 0.0], [1, 2.0, 5.0, 0.0]],
        ),
    )
    failed = wait_for_message(events, lambda e: e.kind == "action_failed", timeout=10)
    assert failed.robot == "r0" and "d_nowhere" in failed.data.reason and failed.data.action_id == 1
    status = wait_for_message(statuses, lambda s: s.robot == "r0" and s.state == "failed", timeout=10)
    assert "d_nowhere" in status.detail and status.world_version >= 2
    client.publish(client.keys.robot_command("r9"), RobotCommand(robot="r9", plan_id=1, action_id=1, action="stop"))
    assert wait_for_message(events, lambda e: e.kind == "action_failed" and e.robot == "r9", timeout=10)
    client.publish(client.keys.robot_command("r1"), RobotCommand(robot="r0", plan_id=1, action_id=9, action="stop"))
    time.sleep(0.5)
    (stats,) = [r for r in client.query(client.keys.stats("sim"), Event, timeout=5)]
    assert stats.data["bad_messages"] >= 2
    assert stats.data["commands_refused"] == 1 and stats.data["commands_unknown_robot"] == 1
    assert sim.alive()
    sim.signal(signal.SIGTERM)
    assert sim.wait(10) == 0
    assert "stopped" in sim.output


def test_rate_mode_runs_k_times_real_time_and_sigint_exits_cleanly(router, client, spawn):
    clocks = client.collect(client.keys.clock(), Clock)
    poses = client.collect(client.keys.robot_pose("r0"), RobotPose)
    sim = spawn(sim_argv(router, client.keys.site, "--rate", "20", "--pose-rate", "10"), name="sim")
    first = wait_for_message(clocks, lambda c: c.time > 0, timeout=15)
    drain(poses)
    t0 = time.monotonic()
    time.sleep(2.0)
    last = drain(clocks)[-1]
    wall = time.monotonic() - t0
    assert last.mode == "rate" and last.rate == 20.0 and not last.paused
    assert 0.6 * 20 * wall <= last.time - first.time <= 1.1 * 20 * wall
    # Poses at --pose-rate per second of sim time.
    stamps = [p.stamp for p in drain(poses)]
    assert len(stamps) / (stamps[-1] - stamps[0]) == pytest.approx(10.0, rel=0.15)
    sim.signal(signal.SIGINT)
    assert sim.wait(10) == 0
    assert "received SIGINT" in sim.output


@pytest.mark.parametrize(
    "args, message",
    [
        (["--site", "/nonexistent/site.toml"], "site.toml"),
        (["--mode", "rate"], "--mode rate needs --rate"),
        (["--mode", "realtime", "--rate", "5"], "--rate goes with --mode rate or lockstep"),
        (["--mode", "lockstep", "--rate", "0"], "--rate must be > 0"),
        (["--human-config", "/nonexistent/h.toml"], "h.toml"),
        (["--camera", "somewhere"], "--camera 'somewhere'"),
    ],
)
def test_bad_configuration_exits_2_before_any_session(args, message, spawn):
    proc = spawn(arroch("sim", "--connect", "tcp/127.0.0.1:9", *args), name="sim")
    assert proc.wait(20) == 2
    assert message in proc.output


def test_help(spawn):
    proc = spawn(arroch("sim", "--help"), name="help")
    assert proc.wait(20) == 0
    for option in (
        "--method",
        "--mode",
        "--rate",
        "--seed",
        "--door-probability",
        "--human-config",
        "--until-done",
        "--camera",
        "--events-out",
        "--metrics-out",
    ):
        assert option in proc.output


def test_feedback_nobody_acknowledges_ends_lockstep_loudly_as_failed(router, client, spawn, tmp_path):
    """In lockstep the human's time stands still until her feedback is answered; going on without the
    answer after some wall seconds would make the mission depend on the machine's load. So the run
    waits, and past --lockstep-abort it fails (exit code 3, an ERROR line, no metrics)."""
    site = load_site(None)
    human = tmp_path / "human.toml"
    human.write_text(
        "[human]\ntask_mean = 400.0\ntask_std = 0.0\nfocus_count = 1\ndeclare_probability = 1.0\nfeedback_timeout = "
        "0.3\nfeedback_retries = 1\n"
    )
    metrics = tmp_path / "m.json"
    sim = spawn(
        sim_argv(
            router,
            client.keys.site,
            "--mode",
            "lockstep",
            "--method",
            "arroch",
            "--human-config",
            str(human),
            "--until-done",
            "--metrics-out",
            str(metrics),
            "--lockstep-abort",
            "2",
        ),
        name="sim",
    )
    sim.wait_for("up on namespace")
    with Running(StandInPlanner(site, client.keys.site, router, restrictor=False)):  # and no restrictor at all
        assert sim.wait(60) == 3, sim.output
    assert "lockstep aborted" in sim.output and "no ack of the human's feedback door_unavailable" in sim.output
    assert (
        "no ack for feedback" not in sim.output
    )  # it kept trying (every 0.3 s) rather than giving up after 2 attempts
    assert not metrics.exists()


@pytest.mark.parametrize("method", ["no-feedback", "no-comm"])
def test_baselines_complete_without_feedback(router, client, spawn, tmp_path, method):
    metrics = tmp_path / "m.json"
    sim = spawn(
        sim_argv(
            router,
            client.keys.site,
            "--mode",
            "lockstep",
            "--method",
            method,
            "--seed",
            "4",
            "--until-done",
            "--metrics-out",
            str(metrics),
        ),
        name="sim",
    )
    sim.wait_for("up on namespace")
    with Running(StandInPlanner(load_site(None), client.keys.site, router)) as planner:
        assert sim.wait(60) == 0, sim.output
        assert planner.feedback == []
    m = json.loads(metrics.read_text())
    assert m["completed"] and m["feedback"]["sent"] == 0 and m["params"]["method"] == method
    assert m["human_door_openings"] > 0


def test_tablet_camera_publishes_frames_and_their_truth(router, client, spawn):
    import cv2
    import numpy as np

    from protocol.messages import CameraFrame, CameraTruth

    frames = client.collect(client.keys.camera_frame("tab"), CameraFrame)
    truths = client.collect(client.keys.camera_truth("tab"), CameraTruth)
    sim = spawn(
        sim_argv(
            router,
            client.keys.site,
            "--rate",
            "5",
            "--camera",
            "tablet",
            "--camera-id",
            "tab",
            "--camera-rate",
            "4",
            "--camera-size",
            "320x240",
        ),
        name="sim",
    )
    first = wait_for_message(frames, timeout=30)
    time.sleep(1.5)
    got = [first, *drain(frames)]
    assert 4 <= len(got) <= 12  # ~4 per wall second
    image = cv2.imdecode(np.frombuffer(got[-1].jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (240, 320, 3) and image.std() > 10  # a real picture, not a blank
    assert got[-1].intrinsics[0] == pytest.approx(240 / (2 * np.tan(np.radians(30))))
    truth = {t.frame_seq: t for t in drain(truths)}
    pairs = [(f, truth[f.seq]) for f in got if f.seq in truth]
    assert len(pairs) >= 3  # every frame has its truth, matched by the frame's seq
    site = load_site(None)
    for _, t in pairs:
        assert t.position[2] == pytest.approx(1.3)
        # Held at her desk (or on her way to the door, 0.5 m in front of it).
        assert np.hypot(t.position[0] - site.human.position[0], t.position[1] - site.human.position[1]) < 4.0
    sim.signal(signal.SIGTERM)
    assert sim.wait(10) == 0


def test_snapshot_subcommand_is_wired(spawn, tmp_path):
    out, truth = tmp_path / "f.png", tmp_path / "t.json"
    proc = spawn(
        arroch(
            "sim",
            "snapshot",
            "--camera",
            "9,1.5,1.3,120,0",
            "--size",
            "320x240",
            "--out",
            str(out),
            "--truth",
            str(truth),
        ),
        name="snapshot",
    )
    assert proc.wait(60) == 0, proc.output
    assert out.stat().st_size > 1000
    assert json.loads(truth.read_text())["position"] == [9.0, 1.5, 1.3]
