"""Separate processes talking over Zenoh on localhost (free ports chosen at run time), peer to peer
and through `arroch router`; `arroch ping serve` stops cleanly on SIGTERM and SIGINT."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from protocol.messages import RobotPose
from runtime.transport import free_tcp_port
from tests.conftest import wait_for_message
from tests.procs import ROOT, Proc, arroch

pytestmark = pytest.mark.integration

SEND_TIMEOUT = 60


def run_send(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        arroch("ping", "send", "--json", "--log-level", "WARNING", *args),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=SEND_TIMEOUT,
    )


def start_serve(spawn, *args: str) -> Proc:
    proc = spawn(arroch("ping", "serve", *args), name="ping-serve")
    proc.wait_for("ping serve ready", timeout=20)
    return proc


def check_summary(result: subprocess.CompletedProcess, count: int) -> dict:
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert (summary["sent"], summary["received"], summary["lost"]) == (count, count, 0)
    assert 0 < summary["min_us"] <= summary["p50_us"] <= summary["p99_us"] <= summary["max_us"]
    return summary


def test_ping_peer_to_peer(spawn, namespace):
    """One process listens (peer), the other connects to it (peer): no router anywhere."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    start_serve(spawn, "--mode", "peer", "--listen", endpoint, "--namespace", namespace)
    summary = check_summary(
        run_send("--mode", "peer", "--connect", endpoint, "--namespace", namespace, "--count", "50", "--rate", "0"), 50
    )
    assert summary["namespace"] == namespace


def test_ping_through_the_router(spawn, module_router, namespace):
    """Both processes are clients of `arroch router` (the default deployment)."""
    start_serve(spawn, "--connect", module_router, "--namespace", namespace)
    summary = check_summary(
        run_send(
            "--connect",
            module_router,
            "--namespace",
            namespace,
            "--count",
            "30",
            "--rate",
            "200",
            "--payload-bytes",
            "600",
        ),
        30,
    )
    assert 590 <= summary["payload_bytes"] <= 600  # padded with a field the server ignores


def test_ping_serve_echoes_poses_unchanged(spawn, module_router, namespace, peer):
    start_serve(spawn, "--connect", module_router, "--namespace", namespace)
    echoes = peer.collect(peer.keys.ping_reply(), RobotPose)
    sent = RobotPose(robot="r5", x=-3.25, y=7.5, theta=3.0, vel=0.4, omega=-0.2)
    deadline = time.monotonic() + 20
    while echoes.empty() and time.monotonic() < deadline:  # until the server's subscriber is known
        peer.publish(peer.keys.robot_pose("r5"), sent)
        time.sleep(0.1)
    echo = wait_for_message(echoes, timeout=1)
    # The whole message comes back, envelope included (it is the sender's, not the server's).
    assert echo.src == peer.src and echo.seq >= 1
    assert (echo.robot, echo.x, echo.y, echo.theta, echo.vel, echo.omega) == ("r5", -3.25, 7.5, 3.0, 0.4, -0.2)


def test_ping_send_without_a_server_fails_in_time(module_router, namespace):
    started = time.monotonic()
    result = run_send("--connect", module_router, "--namespace", namespace, "--wait", "1", "--count", "5")
    assert result.returncode == 1
    assert "no ping server answered" in result.stderr
    assert time.monotonic() - started < 15


def test_bad_configuration_is_reported_not_hung(spawn, tmp_path):
    proc = spawn(arroch("ping", "serve", "--namespace", "x", "--zenoh-config", str(tmp_path / "missing.json5")))
    assert proc.wait(15) != 0
    assert "missing.json5" in proc.output


# ---------------------------------------------------------------------------- clean stop


def descendants(pid: int) -> set[int]:
    """Every process below ``pid``, read from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    found: set[int] = set()
    todo = [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def group_is_empty(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return True
    return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_service_stops_within_2s_and_leaves_nothing(spawn, module_router, namespace, sig):
    proc = start_serve(spawn, "--connect", module_router, "--namespace", namespace)
    # Busy first: a ping run, so the server stops with live subscribers and publishers.
    check_summary(run_send("--connect", module_router, "--namespace", namespace, "--count", "20", "--rate", "0"), 20)
    below = descendants(proc.popen.pid)
    started = time.monotonic()
    os.kill(proc.popen.pid, sig)  # the process alone, as a supervisor or systemd would
    code = proc.wait(10)
    elapsed = time.monotonic() - started
    assert code == 0, proc.output
    assert elapsed < 2.0, f"took {elapsed:.2f} s to stop"
    assert group_is_empty(proc.popen.pid), "something of its process group survived"
    assert not any(Path(f"/proc/{pid}").exists() for pid in below)
    assert "stopped" in proc.output


def test_ping_send_stops_on_sigint_with_what_it_measured(spawn, module_router, namespace):
    start_serve(spawn, "--connect", module_router, "--namespace", namespace)
    send = spawn(
        arroch(
            "ping",
            "send",
            "--json",
            "--connect",
            module_router,
            "--namespace",
            namespace,
            "--count",
            "100000",
            "--rate",
            "50",
        ),
        name="ping-send",
    )
    send.wait_for("pingsend", timeout=20)  # its start-up log line
    time.sleep(1.5)
    started = time.monotonic()
    os.kill(send.popen.pid, signal.SIGINT)
    assert send.wait(10) == 0
    assert time.monotonic() - started < 2.0
    send.stop()
    summary = json.loads(next(line for line in send.output.splitlines() if line.startswith("{")))
    assert summary["interrupted"] is True
    assert 0 < summary["received"] == summary["sent"] < 100000
    assert group_is_empty(send.popen.pid)


def test_service_stops_promptly_after_losing_its_router(spawn, namespace):
    """A dead link must not make the Zenoh close hang the exit."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = spawn(arroch("router", "--listen", endpoint), name="router")
    router.wait_for("router ready", timeout=20)
    proc = start_serve(spawn, "--connect", endpoint, "--namespace", namespace)
    os.kill(router.popen.pid, signal.SIGKILL)
    router.wait(5)
    time.sleep(0.3)
    started = time.monotonic()
    os.kill(proc.popen.pid, signal.SIGTERM)
    assert proc.wait(10) == 0
    assert time.monotonic() - started < 2.0
    assert group_is_empty(proc.popen.pid)


def signal_storm(pid: int, senders: int = 2) -> None:
    """SIGTERMs from ``senders`` threads, back to back until ``pid`` is gone: the worst case of what
    a process tied to its parent with PR_SET_PDEATHSIG gets when that parent, with many threads, is
    killed (one signal per exiting thread)."""

    def send() -> None:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                return

    threads = [threading.Thread(target=send, daemon=True) for _ in range(senders)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(11)


@pytest.mark.parametrize("what", ["router", "service"])
def test_a_burst_of_signals_still_stops_the_process(spawn, module_router, namespace, what):
    """A handler that took a lock (Event.set, logging) re-entered itself when a second signal landed
    while the first was still being handled: a RecursionError, or a deadlock on the lock its own
    thread held, and the process outlived its parent for ever."""
    for attempt in range(3):  # the deadlock needs a signal inside a handler's critical section
        if what == "router":
            proc = spawn(arroch("router", "--listen", f"tcp/127.0.0.1:{free_tcp_port()}"), name="router")
            proc.wait_for("router ready", timeout=20)
        else:
            proc = start_serve(spawn, "--connect", module_router, "--namespace", namespace)
        started = time.monotonic()
        storm = threading.Thread(target=signal_storm, args=(proc.popen.pid,), daemon=True)
        storm.start()
        try:
            code = proc.wait(10)
        except subprocess.TimeoutExpired:
            pytest.fail(f"attempt {attempt}: {what} still runs 10 s into a storm of SIGTERMs")
        finally:
            storm.join(12)
        assert time.monotonic() - started < 3.0
        # It stopped in order. A signal can still land after the interpreter put the default
        # handlers back on its way out: then the exit status says SIGTERM, harmlessly.
        assert code in (0, -signal.SIGTERM), proc.output
        assert "stopped" in proc.output
        assert not any(word in proc.output for word in ("Traceback", "Error", "Exception")), proc.output


def test_sigusr1_prints_every_threads_stack_and_the_service_goes_on(spawn, module_router, namespace):
    proc = start_serve(spawn, "--connect", module_router, "--namespace", namespace)
    os.kill(proc.popen.pid, signal.SIGUSR1)  # what a sweep does to the services of a trial that timed out
    proc.wait_for("most recent call first", timeout=10)
    proc.wait_for('File "', timeout=10)  # the frames follow the thread's line
    check_summary(run_send("--connect", module_router, "--namespace", namespace, "--count", "5", "--rate", "0"), 5)
