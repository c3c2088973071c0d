"""The restrictor as a process, over Zenoh with a real router: feedback → ack → ConstraintSet, published
and queryable; duplicates; bad input; restarts (also after SIGKILL); expiry on the sim clock; the CLI."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from protocol.codec import decode, encode
from protocol.messages import Clock, ConstraintSet, Event, Feedback, FeedbackAck
from tests.conftest import TestClient, wait_for_message
from tests.procs import ROOT, arroch
from tests.restrictor.conftest import LAB

pytestmark = pytest.mark.integration

SETTLE = 0.4  # seconds for a new subscription to reach the router


@pytest.fixture
def start_restrictor(spawn, router, namespace, tmp_path, client):
    """``start_restrictor(clock="wall", state_dir=None)`` runs ``arroch restrictor`` and waits until it
    is up and the router routes queries to it: its log line comes before the router has its queryables
    (a query then gets no reply at all; seen on a loaded machine)."""

    def _start(*, clock: str = "wall", state_dir=None, name: str = "restrictor"):
        proc = spawn(
            arroch(
                "restrictor",
                "--site",
                str(LAB),
                "--namespace",
                namespace,
                "--connect",
                router,
                "--clock",
                clock,
                "--state-dir",
                str(state_dir or tmp_path / "state"),
            ),
            name=name,
        )
        proc.wait_for("up on namespace", timeout=30)
        wait_until_served(client)
        return proc

    return _start


def wait_until_served(client: TestClient, timeout: float = 10.0) -> None:
    """Until the restrictor answers on ``constraints``, its last queryable (the feedback one is
    declared before it on the same session, so the router has both)."""
    deadline = time.monotonic() + timeout
    while not client.query(client.keys.constraints(), ConstraintSet, timeout=1.0):
        assert time.monotonic() < deadline, f"the restrictor answered no query within {timeout:g} s"
        time.sleep(0.05)


def query_set(client: TestClient) -> ConstraintSet:
    # A restrictor just up may not be reachable through the router yet: ask again until it answers.
    deadline = time.monotonic() + 15.0
    while not (replies := client.query(client.keys.constraints(), ConstraintSet, timeout=3.0)):
        assert time.monotonic() < deadline, "no restrictor answered the constraints query"
    [current] = replies
    return current


def ask(client: TestClient, kind: str, **params) -> FeedbackAck:
    """Feedback as a query: the reply is the ack."""
    [ack] = client.query(client.keys.feedback(), FeedbackAck, payload=Feedback(kind=kind, params=params), timeout=5.0)
    return ack


def stats(client: TestClient) -> dict:
    [event] = client.query(client.keys.stats("restrictor", "*"), Event, timeout=3.0)
    return event.data


def test_feedback_is_acknowledged_and_the_set_published_and_served(start_restrictor, client) -> None:
    proc = start_restrictor()
    sets = client.collect(client.keys.constraints(), ConstraintSet)
    acks = client.collect(client.keys.feedback_ack(client.src), FeedbackAck)
    time.sleep(SETTLE)
    assert query_set(client).version == 0

    # 1. published feedback: the ack comes on feedback/ack/<src>, the new set on constraints
    sent = client.stamp(Feedback(kind="door_unavailable", params={"door": "d_storage", "minutes": 4}))
    client.publish(client.keys.feedback(), sent, stamp=False)
    ack = wait_for_message(acks, lambda a: a.feedback_seq == sent.seq)
    assert ack.accepted and (ack.to, ack.constraint_id, ack.constraints_version) == (client.src, "c1", 1)
    published = wait_for_message(sets, lambda s: s.version == 1)
    [c1] = published.constraints
    assert (c1.id, c1.kind, c1.params, c1.origin) == (
        "c1",
        "door_unavailable",
        {"door": "d_storage", "minutes": 4},
        client.src,
    )
    assert c1.end - c1.start in (240.0, 241.0)  # four minutes, widened to whole seconds
    assert (
        published.asp == f"human_unavailable(d_storage, {c1.start:.0f}, {c1.end:.0f}).\n"
        f":- human_opens(d_storage, T), T >= {c1.start:.0f}, T < {c1.end:.0f}.\n"
    )

    # 2. feedback as a query: the reply is the ack (published on the ack key as well)
    ack2 = ask(client, "forbid_room", room="lab", minutes=2)
    assert ack2.accepted and ack2.constraint_id == "c2" and ack2.constraints_version == 2
    assert wait_for_message(acks, lambda a: a.feedback_seq == ack2.feedback_seq) == ack2

    # 3. late joiners get the current set from the queryable
    current = query_set(client)
    assert current.version == 2 and [c.id for c in current.constraints] == ["c1", "c2"]
    assert current.asp == "".join(c.asp for c in current.constraints)
    assert wait_for_message(sets, lambda s: s.version == 2) == current

    # 4. refusals carry the reason and change nothing; injected text never reaches the set
    for kind, params, reason in [
        ("door_unavailable", {"door": "d_lab", "minutes": 4}, "door d_lab is not human-operated"),
        ("forbid_room", {"room": 'lab).\n#include "/etc/passwd".\n:- x(', "minutes": 4}, "site lab has no room"),
        ("forbid_room", {"room": "lab", "minutes": True}, "minutes must be an integer, got a boolean"),
        ("#script (python)", {}, "unknown constraint kind"),
        ("cancel", {"constraint_id": "c9"}, "no active constraint c9"),
    ]:
        refused = ask(client, kind, **params)
        assert not refused.accepted and reason in refused.reason and refused.constraints_version == 2
    assert query_set(client) == current

    # 5. duplicates (the same bytes, e.g. a retry): applied once, answered twice the same
    payload = encode(client.stamp(Feedback(kind="forbid_room", params={"room": "room_a", "minutes": 1})))
    client.session.put(client.keys.feedback(), payload)
    client.session.put(client.keys.feedback(), payload)
    dup_seq = decode(payload, Feedback).seq
    first = wait_for_message(acks, lambda a: a.feedback_seq == dup_seq)
    second = wait_for_message(acks, lambda a: a.feedback_seq == dup_seq)
    replies = [
        decode(r.ok.payload.to_bytes(), FeedbackAck)
        for r in client.session.get(client.keys.feedback(), payload=payload, timeout=3.0)
    ]
    assert first.accepted and first.constraint_id == "c3"
    for again in (second, *replies):
        assert (again.accepted, again.reason, again.constraint_id, again.constraints_version) == (
            first.accepted,
            first.reason,
            first.constraint_id,
            first.constraints_version,
        )
    assert query_set(client).version == 3

    # 6. garbage: the service keeps running, counts it, and a querier is told what is wrong
    client.session.put(client.keys.feedback(), b"\xc1 not msgpack")
    client.session.put(client.keys.feedback(), encode(ConstraintSet(version=99)))  # the wrong message type
    [bad] = [
        decode(r.ok.payload.to_bytes(), FeedbackAck)
        for r in client.session.get(client.keys.feedback(), payload=b"\x93\x01", timeout=3.0)
    ]
    assert not bad.accepted and bad.reason.startswith("not a valid Feedback")
    counters = stats(client)
    assert counters["bad_messages"] >= 3 and counters["feedback_accepted"] == 3
    assert counters["feedback_duplicate"] == 2 and counters["feedback_refused"] == 5
    assert query_set(client).version == 3 and proc.alive()

    # 7. SIGINT: a clean stop
    proc.signal(signal.SIGINT)
    assert proc.wait(10) == 0
    assert "restrictor" in proc.wait_for("stopped", timeout=1)


def test_send_feedback_counts_forged_acks_and_keeps_waiting_for_the_real_one(
    start_restrictor, client, router, namespace
) -> None:
    """A bad payload on the sender's ack key is counted as a bad message (not silently skipped),
    and the sender still gets the restrictor's real ack once one is up."""
    from concurrent.futures import ThreadPoolExecutor

    from runtime.feedback_client import send_feedback

    forger = TestClient(namespace, router).open()
    try:
        with ThreadPoolExecutor(1) as pool:
            pending = pool.submit(
                send_feedback, client, "door_unavailable", {"door": "d_storage", "minutes": 2}, timeout=30.0, retry=0.5
            )
            time.sleep(1.0)  # its ack subscription is declared and has reached the router
            for payload in (b"\xc1 not msgpack", encode(ConstraintSet(version=3)), b"\x93\x01"):
                forger.session.put(forger.keys.feedback_ack(client.src), payload)
            deadline = time.monotonic() + 5
            while client.counters["bad_messages"] < 3 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert client.counters["bad_messages"] == 3 and not pending.done()
            start_restrictor()  # only now: the forged acks came first
            ack = pending.result(timeout=30)
    finally:
        forger.close()
    assert ack is not None and ack.accepted and ack.constraint_id == "c1" and ack.to == client.src
    assert any(
        key.startswith("bad_messages:") and key.endswith(client.keys.feedback_ack(client.src))
        for key in client.counters
    )


def test_a_restart_restores_exactly_the_active_set(
    start_restrictor, spawn, router, namespace, client, tmp_path
) -> None:
    first = start_restrictor()
    assert ask(client, "door_unavailable", door="d_storage", minutes=30).accepted
    assert ask(client, "forbid_room", room="lab", minutes=30).accepted
    assert ask(client, "cancel", constraint_id="c1").accepted
    payload = encode(client.stamp(Feedback(kind="forbid_room", params={"room": "room_a", "minutes": 30})))
    [before_ack] = [
        decode(r.ok.payload.to_bytes(), FeedbackAck)
        for r in client.session.get(client.keys.feedback(), payload=payload, timeout=3.0)
    ]
    before = query_set(client)
    assert before.version == 4 and [c.id for c in before.constraints] == ["c2", "c3"]

    first.signal(signal.SIGKILL)  # no chance to save anything on the way out
    first.wait(5)
    second = start_restrictor(name="restrictor-2")
    sets = client.collect(client.keys.constraints(), ConstraintSet)
    time.sleep(SETTLE)
    after = query_set(client)
    assert (after.version, after.constraints, after.asp) == (before.version, before.constraints, before.asp)
    # the retry of feedback answered before the crash is recognised, and gets the same answer
    [again] = [
        decode(r.ok.payload.to_bytes(), FeedbackAck)
        for r in client.session.get(client.keys.feedback(), payload=payload, timeout=3.0)
    ]
    assert (again.accepted, again.constraint_id, again.constraints_version, again.reason) == (
        before_ack.accepted,
        before_ack.constraint_id,
        before_ack.constraints_version,
        before_ack.reason,
    )
    # and the next change continues the versions and ids
    ack = ask(client, "door_available_now", door="d_storage")
    assert (ack.constraint_id, ack.constraints_version) == ("c4", 5)
    assert wait_for_message(sets, lambda s: s.version == 5).constraints[-1].id == "c4"
    assert "2 active constraint(s), version 4" in second.output
    second.signal(signal.SIGTERM)
    assert second.wait(10) == 0

    # --fresh (a new mission): the same directory, an empty set, the version goes on
    third = spawn(
        arroch(
            "restrictor",
            "--site",
            str(LAB),
            "--namespace",
            namespace,
            "--connect",
            router,
            "--clock",
            "wall",
            "--state-dir",
            str(tmp_path / "state"),
            "--fresh",
        ),
        name="restrictor-3",
    )
    third.wait_for("up on namespace", timeout=30)
    emptied = query_set(client)
    assert emptied.constraints == [] and emptied.version == 6


def test_constraints_expire_on_the_sim_clock(start_restrictor, client) -> None:
    start_restrictor(clock="sim")
    sets = client.collect(client.keys.constraints(), ConstraintSet)
    time.sleep(SETTLE)
    early = ask(client, "forbid_room", room="lab", minutes=1)
    assert not early.accepted and "site clock is not known yet" in early.reason

    # a paused sim clock does not run on between messages, so the window edges are exact
    client.publish(client.keys.clock(), Clock(time=100.0, mode="rate", rate=10.0, paused=True))
    time.sleep(0.3)
    assert ask(client, "forbid_room", room="lab", minutes=1).accepted  # [100, 160)
    assert ask(client, "forbid_room", room="room_a", minutes=2).accepted  # [100, 220)
    current = wait_for_message(sets, lambda s: s.version == 2)
    assert [(c.start, c.end) for c in current.constraints] == [(100.0, 160.0), (100.0, 220.0)]

    client.publish(client.keys.clock(), Clock(time=159.0, mode="rate", rate=10.0, paused=True))
    time.sleep(0.6)  # several expiry checks: nothing is due yet
    assert query_set(client).version == 2
    client.publish(client.keys.clock(), Clock(time=160.0, mode="rate", rate=10.0, paused=True))
    expired = wait_for_message(sets, lambda s: s.version == 3, timeout=5)
    assert [c.id for c in expired.constraints] == ["c2"] and "lab" not in expired.asp
    client.publish(client.keys.clock(), Clock(time=500.0, mode="rate", rate=10.0, paused=True))
    assert wait_for_message(sets, lambda s: s.version == 4, timeout=5).constraints == []


def test_in_lockstep_windows_start_at_the_feedbacks_stamp_and_expire_only_with_feedback(
    start_restrictor, client
) -> None:
    """The clock heard here lags the simulator's by what is still on the way: a lockstep feedback's
    window starts at its own stamp, and nothing expires on a timer (a set published between two world
    versions would reach the planner at a moment of the machine's choosing)."""
    start_restrictor(clock="sim")
    sets = client.collect(client.keys.constraints(), ConstraintSet)
    client.publish(client.keys.clock(), Clock(time=100.0, mode="lockstep"))
    time.sleep(SETTLE)
    acks = client.collect(client.keys.feedback_ack("sim-test"), FeedbackAck)
    time.sleep(SETTLE)
    stamped = Feedback(kind="forbid_room", params={"room": "lab", "minutes": 1})
    stamped.src, stamped.seq, stamped.stamp = "sim-test", 1, 103.0  # the simulator's time, ahead of the clock heard
    client.publish(client.keys.feedback(), stamped, stamp=False)
    assert wait_for_message(acks).accepted
    first = wait_for_message(sets, lambda s: s.version == 1)
    assert [(c.start, c.end) for c in first.constraints] == [(103.0, 163.0)]
    # a stamp far ahead of the clock (this client stamps with the wall clock) is not trusted
    assert ask(client, "forbid_room", room="room_a", minutes=1).accepted
    second = wait_for_message(sets, lambda s: s.version == 2)
    assert [(c.start, c.end) for c in second.constraints] == [(103.0, 163.0), (100.0, 160.0)]

    client.publish(client.keys.clock(), Clock(time=400.0, mode="lockstep"))
    time.sleep(1.0)  # several expiry periods: in lockstep nothing expires on the timer
    assert query_set(client).version == 2
    # the next feedback takes the expired ones with it, in one new version
    ask(client, "forbid_room", room="lab", minutes=2)
    after = wait_for_message(sets, lambda s: s.version >= 3, timeout=5)
    assert [(c.start, c.end) for c in after.constraints] == [(400.0, 520.0)]


def run_cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(arroch(*args), cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_the_command_line_sends_feedback_and_shows_the_set(start_restrictor, spawn, router, namespace) -> None:
    common = ["--site", str(LAB), "--namespace", namespace, "--connect", router]
    # sent before any restrictor is up: the sender retries until one answers
    early = spawn(
        arroch(
            "feedback",
            "send",
            *common,
            "--timeout",
            "40",
            "--retry",
            "0.5",
            "--kind",
            "door_unavailable",
            "--door",
            "d_storage",
            "--minutes",
            "4",
        ),
        name="feedback-send",
    )
    time.sleep(1.5)
    start_restrictor()
    assert early.wait(40) == 0, early.output
    assert "accepted: added c1: door_unavailable(door=d_storage, minutes=4) during [" in early.output
    assert "sending again" in early.output  # it did retry, with the same seq: c1 was added once

    refused = run_cli("feedback", "send", *common, "--kind", "door_unavailable", "--door", "d_lab", "--minutes", "4")
    assert refused.returncode == 1
    assert (
        refused.stdout.strip()
        == "refused: door_unavailable: door d_lab is not human-operated (robots open it themselves); choices: d_storage"
    )
    typed = run_cli("feedback", "send", *common, "--kind", "forbid_room", "--room", "lab", "--minutes", "four")
    assert typed.returncode == 1 and "minutes must be an integer, got the text 'four'" in typed.stdout
    # the command's own options are understood after --kind too
    late_option = run_cli(
        "feedback",
        "send",
        "--kind",
        "forbid_room",
        "--room",
        "room_a",
        "--namespace",
        namespace,
        "--minutes=2",
        "--connect",
        router,
        "--json",
        "--site",
        str(LAB),
    )
    assert late_option.returncode == 0, late_option.stderr
    assert '"constraint_id": "c2"' in late_option.stdout

    show = run_cli("constraints", "show", *common)
    assert show.returncode == 0, show.stderr
    lines = show.stdout.splitlines()
    assert lines[0] == "constraints version 2: 2 active"
    assert lines[1].startswith("  c1  door_unavailable  door=d_storage minutes=4  [")
    assert lines[2].startswith("  c2  forbid_room  room=room_a minutes=2  [")
    assert "human_unavailable(d_storage, " in show.stdout

    nobody = ["--site", str(LAB), "--namespace", namespace + "x", "--connect", router]
    silent = run_cli(
        "feedback", "send", *nobody, "--timeout", "1", "--kind", "forbid_room", "--room", "lab", "--minutes", "1"
    )
    assert silent.returncode == 3 and "no answer from a restrictor" in silent.stderr
    assert run_cli("constraints", "show", *nobody, "--timeout", "1").returncode == 3
    unknown = run_cli("feedback", "send", *common, "--kind", "paint_walls", "--colour", "red")
    assert unknown.returncode == 2 and "unknown constraint kind 'paint_walls'" in unknown.stderr
    stray = run_cli(
        "feedback", "send", *common, "--kind", "forbid_room", "--room", "lab", "--minutes", "1", "--time", "3"
    )
    assert stray.returncode == 2
    assert (
        "--time is neither an option of this command nor a parameter of forbid_room (it takes: --room, --minutes)"
        in stray.stderr
    )


def test_bad_configuration_is_reported_before_starting(tmp_path) -> None:
    bad_library = tmp_path / "lib.toml"
    bad_library.write_text("[[entry]]\nid = 'x'\n")
    out = run_cli("restrictor", "--site", str(LAB), "--library", str(bad_library), "--state-dir", str(tmp_path / "s"))
    assert out.returncode == 2 and "lib.toml: entry[0] (id 'x'): label: required" in out.stderr
    out = run_cli("restrictor", "--site", str(tmp_path / "missing.toml"), "--state-dir", str(tmp_path / "s"))
    assert out.returncode == 2 and "missing.toml" in out.stderr
    help_text = run_cli("restrictor", "--help")
    assert help_text.returncode == 0 and "--state-dir" in help_text.stdout and "--library" in help_text.stdout
    as_module = subprocess.run(
        [sys.executable, "-m", "services.restrictor", "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert as_module.returncode == 0 and as_module.stdout == help_text.stdout
