"""``arroch up`` with real processes: merged prefixed logs, restarts, giving up, clean stops, the
run folder, and no process left behind whatever happens to the supervisor."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from protocol.messages import Event, RobotStatus
from runtime.launch.catalog import SERVICES, Launch, MissionOptions, service_argv
from tests.procs import Proc, arroch

CRASH = "{python} -c 'import sys; sys.exit(3)'"
BAD_CONFIG = "{python} -c 'import sys; print(\"bad option\"); sys.exit(2)'"
IDLE = "{python} -c 'import time; time.sleep(120)'"


def up(spawn, run_dir: Path, *args: str) -> Proc:
    return spawn(arroch("up", "--progress", "line", "--run-dir", str(run_dir), *args), name="up")


def children_up(spawn, run_dir: Path, router: str, namespace: str, *args: str) -> Proc:
    """``arroch up`` on a router of the test's, with no ARROCH service: only the ``--child`` ones in ``args``."""
    return up(spawn, run_dir, "--no-router", "--connect", router, "--namespace", namespace, "--services", "", *args)


def started(proc: Proc) -> dict[str, list[int]]:
    """Every pid the supervisor reported starting, per child, in order."""
    pids: dict[str, list[int]] = {}
    for name, pid in re.findall(r"started (\S+) \(pid (\d+)\)", proc.output):
        pids.setdefault(name, []).append(int(pid))
    return pids


def alive(pid: int) -> bool:
    """Running (a zombie waiting for its parent counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


def kill_leftovers(pids: list[int]) -> None:
    for pid in pids:
        if alive(pid):
            os.kill(pid, signal.SIGKILL)


def wait_count(proc: Proc, text: str, count: int, timeout: float = 20.0) -> None:
    """Until ``text`` has appeared ``count`` times (Proc.wait_for finds the first one only)."""
    deadline = time.monotonic() + timeout
    while proc.output.count(text) < count:
        assert time.monotonic() < deadline, f"{text!r} not seen {count} times within {timeout} s:\n{proc.output}"
        assert proc.alive(), f"supervisor exited:\n{proc.output}"
        time.sleep(0.05)


def exit_code(proc: Proc, timeout: float = 20.0) -> int:
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"supervisor still running after {timeout} s:\n{proc.output}") from None


def the_run(run_dir: Path) -> Path:
    runs = list(run_dir.iterdir())
    assert len(runs) == 1, runs
    return runs[0]


def test_up_merges_logs_restarts_killed_children_and_stops_cleanly_on_ctrl_c(spawn, namespace, tmp_path):
    sup = up(
        spawn,
        tmp_path,
        "--services",
        "ping",
        "--namespace",
        namespace,
        "--child",
        "pinger={python} -m services.cli ping send --count 5 --namespace {namespace}",
    )
    endpoint = sup.wait_for("[router] router ready on").rsplit(" ", 1)[1]
    # The extra child found the router and the namespace on its own, and its output is prefixed.
    assert re.search(rf"^\[pinger\] ping {namespace}: 5/5 echoes", sup.wait_for("[pinger] ping "))
    sup.wait_for("[ping] ping serve ready")
    first = started(sup)["ping"][0]
    os.kill(first, signal.SIGKILL)
    sup.wait_for("ping was killed by SIGKILL")
    sup.wait_for("restarted ping (pid")
    second = started(sup)["ping"][1]
    assert second != first and alive(second) and not alive(first)
    wait_count(sup, "ping is up (", 2)  # the new one has joined
    # The router is a child like any other: restarted on the same endpoint, and the clients reconnect.
    os.kill(started(sup)["router"][0], signal.SIGKILL)
    sup.wait_for("router was killed by SIGKILL")
    wait_count(sup, f"router ready on {endpoint}", 2)
    wait_count(sup, "ping is up (", 3)  # the supervisor's session and the echo server are back
    assert started(sup)["ping"] == [first, second], "the echo server should have reconnected, not restarted"
    # The restarted server answers through the restarted router.
    check = spawn(arroch("ping", "send", "--connect", endpoint, "--namespace", namespace, "--count", "5"), name="check")
    assert "5/5 echoes" in check.wait_for("echoes", timeout=30)
    assert exit_code(check) == 0

    everyone = [pid for pids in started(sup).values() for pid in pids]
    sup.signal(signal.SIGINT)  # what Ctrl-C in a terminal does: the supervisor's group only
    try:
        assert exit_code(sup) == 0, sup.output
        assert wait_gone(everyone, 5) == [], f"left behind: {sup.output}"
    finally:
        kill_leftovers(everyone)
    assert "stopped (received SIGINT)" in sup.output
    run = the_run(tmp_path)
    merged = (run / "supervisor.log").read_text()
    for prefix in ("[up] ", "[router] ", "[ping] ", "[pinger] "):
        assert any(line.startswith(prefix) for line in merged.splitlines()), prefix
    summary = json.loads((run / "run.json").read_text())
    assert summary["children"]["ping"]["starts"] == 2 and summary["children"]["router"]["starts"] == 2
    assert summary["stop_reason"] == "received SIGINT" and not summary["mission_done"]


def test_up_backs_off_then_gives_up_on_a_crash_loop(spawn, router, namespace, tmp_path):
    sup = children_up(
        spawn,
        tmp_path,
        router,
        namespace,
        "--max-restarts",
        "2",
        "--child",
        f"crash={CRASH}",
        "--child",
        f"idle={IDLE}",
    )
    assert exit_code(sup) == 1, sup.output
    out = sup.output
    delays = [
        float(d) for d in re.findall(r"crash exited with code 3 after [\d.]+ s; restarting it in ([\d.]+) s", out)
    ]
    assert delays == [0.5, 1.0], out  # exponential backoff
    assert "crash exited with code 3; it was restarted 2 times in the last minute: giving up" in out
    assert len(started(sup)["crash"]) == 3
    assert wait_gone(started(sup)["idle"], 5) == [], "the other child was not stopped"


def test_up_does_not_restart_a_child_with_a_configuration_error(spawn, router, namespace, tmp_path):
    sup = children_up(
        spawn,
        tmp_path,
        router,
        namespace,
        "--child",
        f"bad={BAD_CONFIG}",
        "--child",
        f"idle={IDLE}",
    )
    assert exit_code(sup) == 1, sup.output
    assert "[bad] bad option" in sup.output
    assert "bad exited with code 2: its configuration is wrong" in sup.output
    assert len(started(sup)["bad"]) == 1
    assert wait_gone(started(sup)["idle"], 5) == []


# A child that notes in a file when it is asked to stop, and leaves ``linger`` s later.
NOTING_CHILD = """
import signal, sys, time
name, log, linger = sys.argv[1], sys.argv[2], float(sys.argv[3])
def stop(*_):
    with open(log, "a") as f:
        f.write(f"{name} asked {time.time()}\\n")
    time.sleep(linger)
    with open(log, "a") as f:
        f.write(f"{name} gone {time.time()}\\n")
    sys.exit(0)
signal.signal(signal.SIGTERM, stop)
open(log, "a").write(f"{name} ready\\n")
while True:
    time.sleep(1)
"""


def test_the_recorder_is_stopped_after_the_services_that_publish(spawn, router, namespace, tmp_path):
    """The recorder settles on what reached it once nothing is published any more: it is asked to stop
    only once every other service has gone (a run's tail is not lost on a loaded machine)."""
    script, log = tmp_path / "child.py", tmp_path / "stops.log"
    script.write_text(NOTING_CHILD)
    child = f"{{python}} {script} {{name}} {log} {{linger}}"
    sup = children_up(
        spawn,
        tmp_path / "runs",
        router,
        namespace,
        "--no-record",
        "--child",
        "recorder=" + child.format(python="{python}", name="recorder", linger=0),
        "--child",
        "world=" + child.format(python="{python}", name="world", linger=1.0),
    )
    deadline = time.monotonic() + 30
    while not (log.exists() and log.read_text().count("ready") == 2):
        assert time.monotonic() < deadline and sup.alive(), sup.output
        time.sleep(0.05)
    sup.signal(signal.SIGINT)
    assert exit_code(sup) == 0, sup.output
    stops = [line.split() for line in log.read_text().splitlines() if "ready" not in line]
    at = {(name, what): float(when) for name, what, when in stops}
    assert at[("recorder", "asked")] >= at[("world", "gone")], at


def test_up_until_done_prints_the_metrics_and_writes_the_run_folder(spawn, router, namespace, client, tmp_path):
    sup = children_up(
        spawn,
        tmp_path,
        router,
        namespace,
        "--until-done",
        "--child",
        f"idle={IDLE}",
        "--progress-interval",
        "0.5",
    )
    sup.wait_for("supervising")
    # Publish only once the supervisor's subscription has reached this client through the router.
    probe = client.session.declare_publisher(client.keys.event())
    deadline = time.monotonic() + 10
    while not probe.matching_status.matching:
        assert time.monotonic() < deadline, "the supervisor never subscribed to events"
        time.sleep(0.02)
    metrics = {"completed": True, "team_completion_time": 321.5, "human_door_openings": 1}
    client.publish(client.keys.robot_status("r0"), RobotStatus(robot="r0", state="moving", delivered=["o0"]))
    client.publish(client.keys.event(), Event(kind="delivered", robot="r1", object="o3"))
    client.publish(client.keys.event(), Event(kind="door_opened", door="d_storage", data={"by": "human"}))
    sup.wait_for("door openings 1")  # progress shows both deliveries and the opening
    assert re.search(r"delivered 2\b", sup.output), sup.output
    client.publish(client.keys.event(), Event(kind="mission_done", data=metrics))
    assert exit_code(sup) == 0, sup.output
    assert "stopped (mission done)" in sup.output
    assert re.search(r"\[up\] team completion time\s+321\.5\s+s", sup.output), sup.output
    assert re.search(r"\[up\] human door openings\s+1\s+count", sup.output), sup.output
    run = the_run(tmp_path)
    assert json.loads((run / "metrics.json").read_text()) == metrics
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert [e["kind"] for e in events] == ["delivered", "door_opened", "mission_done"]
    assert events[1]["data"] == {"by": "human"} and events[2]["src"] == client.src
    assert wait_gone(started(sup)["idle"], 5) == []


def test_a_supervisor_killed_outright_takes_its_children_with_it(spawn, namespace, tmp_path):
    sup = up(spawn, tmp_path, "--services", "ping", "--namespace", namespace)
    sup.wait_for("[ping] ping serve ready")
    children = [pid for pids in started(sup).values() for pid in pids]
    assert len(children) == 2  # router and ping
    os.kill(sup.popen.pid, signal.SIGKILL)
    try:
        assert wait_gone(children, 10) == [], "children outlived a SIGKILLed supervisor"
    finally:
        kill_leftovers(children)


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--services", "planner,bogus,ar"],
            "unknown service 'bogus' (known: planner, restrictor, sim, ar, tablet, ping)",
        ),
        (["--child", "ping=sleep 1"], "'ping' is taken"),
        (["--child", "nocommand"], "expected NAME=COMMAND"),
        (["--no-router", "--services", ""], "nothing to run"),
        (["--linger"], "--linger keeps a run up after its mission: it goes with --until-done"),
        (["--zenoh-config-dir", "/nonexistent", "--services", "sim"], "missing Zenoh configs /nonexistent/sim.json5"),
        # The tablet page runs as the AR identity: its config is ar.json5, asked for once.
        (
            ["--zenoh-config-dir", "/nonexistent", "--services", "ar,tablet", "--no-router", "--camera", "tablet"],
            "missing Zenoh configs /nonexistent/ar.json5, /nonexistent/supervisor.json5 (",
        ),
    ],
)
def test_up_refuses_bad_options_clearly(args, message, tmp_path):
    result = subprocess.run(
        arroch("up", "--namespace", "t", "--run-dir", str(tmp_path), *args), capture_output=True, text=True, timeout=30
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert message in result.stdout, result.stdout
    assert not list(tmp_path.iterdir()), "a refused run must not leave a run folder"


def test_the_camera_option_reaches_the_sim_and_the_tablet_page_and_overlays_go_to_the_run_folder(tmp_path):
    run = tmp_path / "20260101-000000"
    launch = Launch(
        namespace="n", zenoh_config_dir=tmp_path, mission=MissionOptions(camera="tablet", mode="lockstep"), run_dir=run
    )
    sim, ar, tablet = (service_argv(SERVICES[name], launch) for name in ("sim", "ar", "tablet"))
    assert sim[sim.index("--camera") + 1] == "tablet" and sim[sim.index("--mode") + 1] == "lockstep"
    assert "--camera-every" not in sim  # the sim's default: held frames only
    smooth = Launch(namespace="n", mission=MissionOptions(camera="tablet", camera_every=2.0))
    smooth_sim = service_argv(SERVICES["sim"], smooth)
    assert smooth_sim[smooth_sim.index("--camera-every") + 1] == "2"  # arroch demo's, for people watching
    assert ar[ar.index("--snapshots") + 1] == str(run / "overlays") and "--camera" not in ar
    assert tablet[tablet.index("--camera-source") + 1] == "sim:tablet" and tablet[tablet.index("--port") + 1] == "0"
    assert tablet[tablet.index("--zenoh-config") + 1] == str(tmp_path / "ar.json5")  # the AR identity
    assert "ar" in SERVICES["sim"].after  # the AR client watches from the mission's first frame
    # Without a camera the page takes each browser's own camera, and the sim renders nothing.
    plain = Launch(namespace="n", connect=["tcp/127.0.0.1:1"])
    assert "--camera-source" not in service_argv(SERVICES["tablet"], plain) and "--camera" not in service_argv(
        SERVICES["sim"], plain
    )


def test_the_sim_starts_only_once_the_restrictor_is_up(spawn, namespace, tmp_path):
    sup = up(spawn, tmp_path, "--services", "sim,restrictor", "--namespace", namespace, "--rate", "20", "--no-record")
    sup.wait_for("sim starts once restrictor is up")
    sup.wait_for("started sim (pid", timeout=60)
    lines = sup.output.splitlines()
    up_at = next(i for i, line in enumerate(lines) if "restrictor is up (" in line)
    started_at = next(i for i, line in enumerate(lines) if "started sim (pid" in line)
    assert started_at > up_at, sup.output
    sup.wait_for("sim is up (", timeout=60)
    sup.signal(signal.SIGTERM)
    assert exit_code(sup) == 0, sup.output


def test_up_without_a_reachable_router_says_so(tmp_path):
    result = subprocess.run(
        arroch(
            "up",
            "--no-router",
            "--connect",
            "tcp/127.0.0.1:9",
            "--namespace",
            "t",
            "--services",
            "ping",
            "--run-dir",
            str(tmp_path),
            "--progress",
            "off",
        ),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 1, result.stdout
    assert "could not join the Zenoh network (tcp/127.0.0.1:9)" in result.stdout
    assert "started ping" not in result.stdout
