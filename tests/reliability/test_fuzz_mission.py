"""Bad input during a mission: at least 100 000 seeded bad payloads on every key a service subscribes
to, while ``arroch up`` runs the default lockstep mission with the planner, the restrictor, the sim and
the AR client.

Every payload is checked with the codec before it is sent, so the test knows how many bad messages
each service must count on each key; it asserts exactly that number, per service and key expression,
from the services' own ``stats`` queryables, and that nothing was dropped or lost on the way. Beside
the garbage: Feedback that decodes but smuggles ASP through every parameter (each must be refused,
and no constraint set may ever carry it), camera frames that decode but hold no usable picture (the
AR client's ``bad_frames``), and bad Feedback queries (each answered with a refusal). No service may
die or restart, and the mission must complete: every robot delivers its objects, no action fails,
the simulated human's feedback is all accepted.

The fuzzed mission's metrics are not compared with an unfuzzed run's: lockstep fixes the order of
the simulation, not the planner's wall-clock solver budget and replan bursts, so the same seed run
beside two busy-looping processes (no fuzz at all) already ends with other action counts and waiting
times (docs/reliability.md).
"""

from __future__ import annotations

import json
import random
import signal
import threading
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import zenoh

from protocol.codec import decode, encode
from protocol.errors import ProtocolError
from protocol.messages import CameraFrame, Clock, ConstraintSet, Event, Feedback, FeedbackAck
from protocol.site import load_site
from runtime.asp_check import check_program
from runtime.service import MAX_KEYED_COUNTERS
from runtime.transport import free_tcp_port
from services.restrictor.library import load_library
from tests.procs import Proc, arroch
from tests.reliability.fuzzing import (
    KEY_TYPES,
    SUBSCRIPTIONS,
    FuzzClient,
    Mutator,
    bad_frames,
    counted,
    hostile_feedback,
    is_valid,
    pattern_of,
    receivers,
)
from tests.reliability.missions import PACE
from tests.restrictor.test_validate import INJECTIONS, NUMERIC_INJECTIONS

pytestmark = [pytest.mark.integration, pytest.mark.slow(seconds=40)]  # wall s on two quiet cores

SERVICES = "planner,restrictor,sim,ar"
MISSION_SEED = 1
FUZZ_SEED = 20_261_121
PAYLOADS = 100_000  # bad payloads put on subscribed keys (queries, hostile feedback and frames come on top)
# The fuzz keeps pace with the mission (which lasts about 700 s of site time): by site time t at most
# t / FUZZ_BY of it is out, so it is spread over the first half of the mission, and done well before
# the end unless the machine cannot carry it that fast.
FUZZ_BY = 300.0
HEAD_START = 0.05  # the part sent before the site clock moves
QUERIES = 200  # bad Feedback queries to the restrictor
BAD_FRAMES = 300  # CameraFrames that decode but hold no usable picture
OVERSIZED = 2  # payloads just past the size limit, per key expression (1 MiB each; 16 MiB for frames: skipped)
MISSION_TIMEOUT = 120.0  # wall s for the mission: a guard only (about 10 s unfuzzed on two quiet cores)
SETTLE = 20.0  # wall s for the counters to show every payload sent
INJECTED_NAMES = ["door).\nhuman_opens(d_storage, 1", "t0", "t1", "kind", "#include", "${door}"]
# The injection corpus sampled for the mission (each refusal is a database write, about 20 ms): the
# whole corpus goes through the query path in test_security_smuggling.py.
MISSION_INJECTIONS = INJECTIONS[::4]
MISSION_NUMBERS = NUMERIC_INJECTIONS[::3]
SITE = load_site()
REAL_IDS = {"robot": sorted(SITE.robots), "door": sorted(SITE.doors), "intent": sorted(SITE.robots)}


@dataclass
class Plan:
    """What will be sent, and so what each service must count."""

    puts: list[tuple[str, bytes]] = field(default_factory=list)  # (relative key, payload), in sending order
    queries: list[bytes] = field(default_factory=list)
    hostile: list[bytes] = field(default_factory=list)  # encoded Feedback the restrictor must refuse
    frames: list[bytes] = field(default_factory=list)  # encoded CameraFrames without a usable picture
    kinds: Counter = field(default_factory=Counter)
    # service -> key expression -> bad messages it must count
    expected: dict[str, Counter] = field(default_factory=lambda: defaultdict(Counter))


def concrete_key(pattern: str, rng: random.Random) -> str:
    """A key under ``pattern``: the site's ids mostly, ids no site has otherwise (bounded counters)."""
    if "*" not in pattern:
        return pattern
    head = pattern.split("/")[0]
    chunk = rng.choice(REAL_IDS[head]) if rng.random() < 0.7 else f"fz{rng.randrange(16**6):06x}"
    return pattern.replace("*", chunk)


def make_plan(client_src: str) -> Plan:
    rng = random.Random(FUZZ_SEED)
    mutator = Mutator(FUZZ_SEED)
    plan = Plan()
    patterns = list(KEY_TYPES)
    for i in range(PAYLOADS):
        pattern = patterns[i % len(patterns)]
        kind, payload = mutator.invalid(KEY_TYPES[pattern])
        plan.puts.append((concrete_key(pattern, rng), payload))
        plan.kinds[kind] += 1
    for pattern in patterns:
        if KEY_TYPES[pattern] is not CameraFrame:
            for _ in range(OVERSIZED):
                plan.puts.insert(
                    rng.randrange(len(plan.puts)),
                    (concrete_key(pattern, rng), mutator.oversized_payload(KEY_TYPES[pattern])),
                )
                plan.kinds["oversized_payload"] += 1
    for key, payload in plan.puts:
        assert not is_valid(payload, KEY_TYPES[pattern_of(key)])
        for service in receivers(key):
            plan.expected[service][pattern_of(key)] += 1
    for _ in range(QUERIES):
        plan.queries.append(mutator.invalid(Feedback)[1])
        plan.expected["restrictor"]["feedback"] += 1
    library = load_library()
    for seq, (kind, params) in enumerate(
        hostile_feedback(library, SITE, MISSION_INJECTIONS, MISSION_NUMBERS, INJECTED_NAMES), start=1
    ):
        try:
            payload = encode(Feedback(kind=kind, params=params, src=client_src, seq=seq, stamp=0.0))
        except (TypeError, ValueError, OverflowError):
            continue  # not even encodable (e.g. an int past 64 bits): nothing a peer could send as Feedback
        if is_valid(payload, Feedback):
            plan.hostile.append(payload)
        else:  # too long for the wire: a bad message like the others
            plan.puts.append(("feedback", payload))
            plan.expected["restrictor"]["feedback"] += 1
    jpeg = cv2.imencode(".jpg", np.zeros((480, 640, 3), np.uint8))[1].tobytes()
    cases = bad_frames(rng, jpeg)
    for seq in range(1, BAD_FRAMES + 1):
        _, fields = next(cases)
        frame = CameraFrame(
            camera="tablet",
            jpeg=jpeg,
            width=640,
            height=480,
            intrinsics=[500.0, 500.0, 320.0, 240.0],
            src=client_src,
            seq=seq,
            stamp=0.0,
        )
        for name, value in fields.items():
            setattr(frame, name, value)
        plan.frames.append(encode(frame))
    return plan


def start_mission(spawn, run_dir: Path, endpoint: str, namespace: str) -> Proc:
    # --no-record: the fuzz counts what the mission's services drop; a recorder hears every key.
    # --linger: the services stay up after the mission until the counters have been read (the
    # mission's second half can be shorter than the time the counters take to settle).
    proc = spawn(
        arroch(
            "up",
            "--services",
            SERVICES,
            "--mode",
            "lockstep",
            "--rate",
            str(PACE),
            "--seed",
            str(MISSION_SEED),
            "--until-done",
            "--linger",
            "--no-record",
            "--run-dir",
            str(run_dir),
            "--progress",
            "off",
            "--router-listen",
            endpoint,
            "--namespace",
            namespace,
            "--timeout",
            str(MISSION_TIMEOUT),
        ),
        name="up",
    )
    proc.wait_for("router ready", timeout=30)
    return proc


def finish(proc: Proc, run_dir: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """Wait for the mission's end, then stop the lingering ``up`` as Ctrl-C does; (metrics.json, run.json)."""
    proc.wait_for("stay up until Ctrl-C (--linger)", timeout=MISSION_TIMEOUT + 10)
    proc.signal(signal.SIGINT)
    deadline = time.monotonic() + 20
    while proc.alive() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not proc.alive(), f"arroch up did not stop on SIGINT after the mission:\n{proc.output[-3000:]}"
    assert proc.popen.returncode == 0, proc.output[-3000:]
    (run,) = [p for p in run_dir.iterdir() if p.is_dir()]
    return json.loads((run / "metrics.json").read_text()), json.loads((run / "run.json").read_text())


class Watch:
    """What the services say during the fuzz: liveliness tokens (a service that dies loses its token),
    the mission's end, and every constraint set the planner was sent. Only remote publications are
    heard: the fuzzer's own garbage on ``event`` and ``constraints`` stays out."""

    def __init__(self, client: FuzzClient) -> None:
        self.lost: list[str] = []
        self.sets: list[ConstraintSet] = []
        self.site_time = 0.0
        self.mission_done_at: float | None = None
        self.done_by = ""  # what said the mission was over (for a failure's message)
        self._lock = threading.Lock()
        session, remote = client.session, zenoh.Locality.REMOTE
        client._declared += [
            session.liveliness().declare_subscriber(client.keys.liveliness("*", "*"), self._token, history=True),
            session.declare_subscriber(client.keys.event(), self._event, allowed_origin=remote),
            session.declare_subscriber(client.keys.constraints(), self._constraints, allowed_origin=remote),
            session.declare_subscriber(client.keys.clock(), self._clock, allowed_origin=remote),
        ]

    def _token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if sample.kind != zenoh.SampleKind.DELETE or self.mission_done_at is not None:
            return
        with self._lock:
            if "/supervisor/" in key:
                # `up` leaves first once the mission is done, before stopping the services: from here
                # on tokens go away by design (and this may arrive before the mission_done event).
                self.mission_done_at = time.monotonic()
                self.done_by = f"{key} left at site time {self.site_time:.1f} s"
            else:
                self.lost.append(key)

    def _event(self, sample: zenoh.Sample) -> None:
        try:
            kind = decode(sample.payload.to_bytes(), Event).kind
        except ProtocolError:
            return  # one of the fuzzer's own bad events: the services count those
        if kind == "mission_done" and self.mission_done_at is None:
            self.mission_done_at = time.monotonic()
            self.done_by = f"mission_done event at site time {self.site_time:.1f} s"

    def _clock(self, sample: zenoh.Sample) -> None:
        self.site_time = max(self.site_time, decode(sample.payload.to_bytes(), Clock).time)

    def _constraints(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.sets.append(decode(sample.payload.to_bytes(), ConstraintSet))


def wait_for_services(client: FuzzClient, timeout: float = 40.0) -> dict[str, dict[str, Any]]:
    deadline = time.monotonic() + timeout
    while True:
        stats = client.stats()
        if set(SUBSCRIPTIONS) <= set(stats):
            return stats
        assert time.monotonic() < deadline, f"services up: {sorted(stats)}"
        time.sleep(0.2)


def send(client: FuzzClient, plan: Plan, watch: Watch) -> list[Any]:
    """Everything in ``plan``, in step with the mission (FUZZ_BY); returns the pending replies of the
    Feedback queries."""
    extras: list[tuple[str, bytes]] = (
        [("query", q) for q in plan.queries]
        + [("feedback", h) for h in plan.hostile]
        + [("camera/tablet/frame", f) for f in plan.frames]
    )
    every = max(1, len(plan.puts) // max(1, len(extras)))
    replies: list[Any] = []
    feedback_key = client.keys.feedback()
    total = len(plan.puts)
    for i, (key, payload) in enumerate(plan.puts):
        client.put_raw(key, payload)
        if i % every == 0 and extras:
            what, data = extras.pop()
            if what == "query":
                replies.append(client.session.get(feedback_key, payload=data, timeout=20.0))
            else:
                client.put_raw(what, data)
        if i % 500 == 0:
            while i > total * max(HEAD_START, watch.site_time / FUZZ_BY) and watch.mission_done_at is None:
                time.sleep(0.005)
    for what, data in extras:
        if what == "query":
            replies.append(client.session.get(feedback_key, payload=data, timeout=20.0))
        else:
            client.put_raw(what, data)
    return replies


def mismatches(
    stats: dict[str, dict[str, Any]], before: dict[str, dict[str, Any]], plan: Plan, prefix: str
) -> list[str]:
    """Every (service, key expression) whose bad-message count is not what was sent to it, every
    payload dropped for want of room on the way, and smuggling feedback not (yet) refused."""
    problems = []
    refused = stats["restrictor"].get("feedback_refused", 0) - before["restrictor"].get("feedback_refused", 0)
    if refused != len(plan.hostile):
        problems.append(f"restrictor refused {refused} feedbacks, sent {len(plan.hostile)} smuggling ASP")
    for service, patterns in SUBSCRIPTIONS.items():
        for pattern in dict.fromkeys(patterns):
            got = counted(stats[service], "bad_messages", prefix, pattern) - counted(
                before[service], "bad_messages", prefix, pattern
            )
            if got != plan.expected[service][pattern]:
                problems.append(
                    f"{service} counted {got} bad messages on {pattern}, sent {plan.expected[service][pattern]}"
                )
        dropped = stats[service].get("dropped_inbox_full", 0)
        if dropped:
            problems.append(f"{service} dropped {dropped} payloads with a full inbox")
    ar = stats["ar"]
    frames = ar.get("bad_frames", 0) + counted(ar, "superseded", prefix, "camera/tablet/frame")
    if frames != len(plan.frames) or ar.get("frames", 0):
        problems.append(
            f"ar: {ar.get('bad_frames', 0)} bad frames + {frames - ar.get('bad_frames', 0)} superseded, "
            f"{ar.get('frames', 0)} processed; sent {len(plan.frames)} frames without a picture"
        )
    return problems


def test_a_mission_survives_100k_bad_payloads_and_counts_every_one(spawn, tmp_path: Path, namespace: str) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    client_src = f"fuzzer-{namespace}"
    # made before the mission starts: at PACE the whole mission takes seconds of wall time, and a plan
    # made while it ran (slower on a loaded machine) let it get past FUZZ_BY before the first payload
    plan = make_plan(client_src)
    mission = start_mission(spawn, tmp_path, endpoint, namespace)
    assert len(plan.puts) >= PAYLOADS and set(plan.kinds) >= set(Mutator.KINDS)
    assert {p for s in plan.expected.values() for p, n in s.items() if n} == set(KEY_TYPES)
    client = FuzzClient(namespace, endpoint, instance=client_src)
    client.open()
    try:
        watch = Watch(client)
        before = wait_for_services(client)
        started, started_at_site_time = time.monotonic(), watch.site_time
        replies = send(client, plan, watch)
        sent_for = time.monotonic() - started
        assert watch.mission_done_at is None, (
            f"the mission ended before the fuzz did ({sent_for:.1f} s of sending from site time "
            f"{started_at_site_time:.0f} s; {watch.done_by})"
        )
        sent_at_site_time = watch.site_time

        # Every query gets its refusal: the restrictor names what is wrong rather than leave it waiting.
        for reply_handler in replies:
            (reply,) = [r for r in reply_handler if r.ok is not None]
            ack = decode(reply.ok.payload.to_bytes(), FeedbackAck)
            assert not ack.accepted and ack.to == "" and ack.reason.startswith("not a valid Feedback"), ack

        prefix = client.keys.prefix
        deadline = time.monotonic() + SETTLE
        while True:
            stats = client.stats()
            problems = (
                mismatches(stats, before, plan, prefix)
                if set(SUBSCRIPTIONS) <= set(stats)
                else ["a service is missing"]
            )
            if not problems or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert not problems, "\n".join([*problems, f"liveliness lost: {watch.lost}", mission.output[-3000:]])
        for service, data in stats.items():  # per-key counters stay bounded
            assert sum(":" in name for name in data) <= MAX_KEYED_COUNTERS + 3 * len(SUBSCRIPTIONS[service]), service
        restrictor = stats["restrictor"]
        metrics, run = finish(mission, tmp_path)
    finally:
        client.close()

    # The mission completed as any run of it does, with no service lost on the way.
    assert not watch.lost, f"services lost their liveliness during the mission: {watch.lost}"
    for name, child in run["children"].items():
        assert child["starts"] == 1 and child["last_exit"] == 0, (name, child)
    assert metrics["completed"] is True and metrics["actions"]["failed"] == 0
    assert (
        metrics["actions"]["done"] < 300
    )  # about 100 for 9 loads: thousands would mean actions repeated without progress
    for rid, robot in metrics["robots"].items():
        assert sorted(robot["delivered"]) == sorted(o.id for o in SITE.objects.values() if o.robot == rid)
    human = metrics["feedback"]
    assert human["sent"] == human["accepted"] >= 1 and human["refused"] == human["unanswered"] == 0

    # Smuggled ASP: every attempt refused; every constraint the planner was sent is the human model's.
    refused = restrictor.get("feedback_refused", 0) - before["restrictor"].get("feedback_refused", 0)
    assert refused == len(plan.hostile)
    assert (
        restrictor.get("feedback_accepted", 0) <= human["accepted"]
    )  # read before the mission's end: maybe not all yet
    assert watch.sets, "no constraint set seen"
    for constraint_set in watch.sets:
        for constraint in constraint_set.constraints:
            assert constraint.origin.startswith("sim-") and constraint.kind in (
                "door_unavailable",
                "forbid_room",
                "door_available_now",
            ), constraint
            check_program(constraint.asp)
    print(
        f"\nfuzz: {len(plan.puts)} bad puts, {len(plan.queries)} bad queries, {len(plan.hostile)} smuggling feedbacks, "
        f"{len(plan.frames)} bad frames in {sent_for:.1f} s (site time {started_at_site_time:.0f} to "
        f"{sent_at_site_time:.0f} s); "
        f"mission time {metrics['team_completion_time']:.1f} s, actions {metrics['actions']}; kinds {dict(plan.kinds)}"
    )
