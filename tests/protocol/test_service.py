"""The Service base over real Zenoh (a router process, services in this process): bad messages,
latest-only delivery, inline handlers, handler failures, stats, stamping, queries."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import msgpack
import pytest
import zenoh

from protocol.codec import ENCODING, encode
from protocol.messages import Event, RobotPose, RobotStatus
from runtime import service as service_module
from runtime.service import BAD_LOG_INTERVAL, MAX_BAD_SENDERS, Service, publisher_options
from tests.protocol.conftest import Running, eventually

pytestmark = pytest.mark.integration


class Probe(Service):
    """A service whose subscriptions are given by the test; every handled message is recorded."""

    def __init__(
        self, *, namespace: str, zenoh_options, subscriptions: list[dict] | None = None, name: str = "probe", **kwargs
    ) -> None:
        self.subscriptions = subscriptions or []
        self.seen: list[tuple[Any, str, int]] = []  # (message, key, thread ident)
        super().__init__(name, namespace, zenoh_options, **kwargs)

    def setup(self) -> None:
        for spec in self.subscriptions:
            spec = dict(spec)
            handler = spec.pop("handler", self.record)
            self.subscribe(spec.pop("key"), spec.pop("type", RobotPose), handler, **spec)

    def record(self, msg: Any, key: str) -> None:
        self.seen.append((msg, key, threading.get_ident()))


def publisher_for(peer, key: str) -> zenoh.Publisher:
    """A raw publisher in the test client's session, once it reaches a subscriber (declarations
    travel through the router asynchronously)."""
    pub = peer.session.declare_publisher(key, encoding=zenoh.Encoding(ENCODING))
    peer._declared.append(pub)
    eventually(lambda: pub.matching_status.matching, what=f"a subscriber for {key}")
    return pub


def bad_pose(src: str) -> bytes:
    """A well-formed envelope from ``src`` with a bad field."""
    return msgpack.packb(
        {
            "v": 1,
            "type": "RobotPose",
            "src": src,
            "seq": 1,
            "stamp": 0.0,
            "robot": "r0",
            "x": "not a number",
            "y": 0.0,
            "theta": 0.0,
        }
    )


def good_pose(robot: str = "r0", seq: int = 1, x: float = 1.0) -> bytes:
    return encode(RobotPose(robot=robot, x=x, y=2.0, theta=0.0, src="peer-1", seq=seq, stamp=0.0))


# ---------------------------------------------------------------------------- bad messages


def test_bad_messages_counted_dropped_and_logged_once_per_sender(make_service, peer, caplog):
    caplog.set_level(logging.WARNING, logger="arroch")
    probe = make_service(Probe, subscriptions=[{"key": peer.keys.robot_pose("*")}]).start().service
    key = peer.keys.robot_pose("r0")
    pub = publisher_for(peer, key)
    for _ in range(5):
        pub.put(bad_pose("alpha"))
    for _ in range(3):
        pub.put(bad_pose("beta"))
    pub.put(b"\xff\x00garbage")
    pub.put(b"")
    pub.put(good_pose())
    eventually(lambda: probe.counters["bad_messages"] == 10 and probe.counters["received"] == 1, what="all 11 payloads")
    assert probe.counters[f"bad_messages:{key}"] == 10
    assert [m.x for m, _, _ in probe.seen] == [1.0]  # the bad ones never reached the handler
    lines = [r.getMessage() for r in caplog.records if "dropped bad message" in r.getMessage()]
    assert len(lines) == 3, lines  # alpha, beta, and the anonymous garbage: once each
    assert sum("from alpha" in line for line in lines) == 1
    assert sum("from beta" in line for line in lines) == 1
    assert sum("from unknown" in line for line in lines) == 1
    assert any("RobotPose.x: expected float, got str" in line for line in lines)


def test_bad_message_log_interval_and_memory_bound(make_service, monkeypatch, caplog):
    caplog.set_level(logging.WARNING, logger="arroch")
    probe = make_service(Probe).service
    now = [5000.0]
    monkeypatch.setattr(service_module.time, "monotonic", lambda: now[0])
    error = ValueError("bad")
    for _ in range(3):
        probe.note_bad_message("k", bad_pose("alpha"), error)
    now[0] += BAD_LOG_INTERVAL - 1
    probe.note_bad_message("k", bad_pose("alpha"), error)
    assert sum("from alpha" in r.getMessage() for r in caplog.records) == 1
    now[0] += 1  # a minute after the first line
    probe.note_bad_message("k", bad_pose("alpha"), error)
    assert sum("from alpha" in r.getMessage() for r in caplog.records) == 2
    assert probe.counters["bad_messages"] == 5
    # Forged sender ids by the thousand: remembered senders stay bounded.
    for i in range(3 * MAX_BAD_SENDERS):
        probe.note_bad_message("k", bad_pose(f"forged{i}"), error)
    assert len(probe._last_bad_log) <= MAX_BAD_SENDERS


def test_delete_samples_are_not_bad_messages(make_service, peer):
    probe = (
        make_service(
            Probe,
            subscriptions=[
                {"key": peer.keys.robot_pose("*")},
                {"key": peer.keys.robot_status("*"), "type": RobotStatus, "inline": True},
            ],
        )
        .start()
        .service
    )
    pose_pub = publisher_for(peer, peer.keys.robot_pose("r0"))
    status_pub = publisher_for(peer, peer.keys.robot_status("r0"))
    pose_pub.delete()
    status_pub.delete()
    pose_pub.put(good_pose())
    eventually(lambda: probe.counters["received"] == 1, what="the pose")
    time.sleep(0.2)
    assert probe.counters["bad_messages"] == 0


# ---------------------------------------------------------------------------- delivery modes


def test_latest_keeps_only_the_newest_payload_per_key(make_service, peer):
    only_r0: list[RobotPose] = []
    # Two latest-subscriptions overlapping on r0: each keeps its own newest payload.
    probe = make_service(
        Probe,
        subscriptions=[
            {"key": peer.keys.robot_pose("*"), "latest": True},
            {"key": peer.keys.robot_pose("r0"), "latest": True, "handler": lambda msg, key: only_r0.append(msg)},
        ],
    ).service
    pubs = {rid: publisher_for(peer, peer.keys.robot_pose(rid)) for rid in ("r0", "r1")}
    # The worker is not running yet: everything waits, and newer payloads replace older ones.
    for seq in range(1, 51):
        for rid, pub in pubs.items():
            pub.put(good_pose(rid, seq=seq, x=float(seq)))
    # 2 keys x 49 replaced on the wildcard subscription, 49 on the r0 one.
    eventually(lambda: probe.counters["superseded"] == 3 * 49, what="all 150 payloads to arrive")
    running = Running(probe).start()
    eventually(lambda: probe.counters["received"] == 3, what="the newest payloads")
    time.sleep(0.2)
    assert probe.counters["received"] == 3
    assert sorted((m.robot, m.seq, m.x) for m, _, _ in probe.seen) == [("r0", 50, 50.0), ("r1", 50, 50.0)]
    assert [(m.robot, m.seq) for m in only_r0] == [("r0", 50)]
    running.stop()


def test_worker_queue_delivers_every_message_in_order(make_service, peer):
    probe = make_service(Probe, subscriptions=[{"key": peer.keys.robot_pose("*")}]).start().service
    pub = publisher_for(peer, peer.keys.robot_pose("r0"))
    for seq in range(1, 101):
        pub.put(good_pose(seq=seq))
    eventually(lambda: len(probe.seen) == 100, what="100 messages")
    assert [m.seq for m, _, _ in probe.seen] == list(range(1, 101))
    run_thread = {ident for _, _, ident in probe.seen}
    assert len(run_thread) == 1  # one worker, one message at a time


def test_inline_handlers_run_on_zenohs_thread_without_the_worker(make_service, peer):
    probe = make_service(Probe, subscriptions=[{"key": peer.keys.robot_pose("*"), "inline": True}]).service
    # run() never called: an inline subscription does not need the worker.
    pub = publisher_for(peer, peer.keys.robot_pose("r3"))
    pub.put(good_pose("r3", seq=4))
    eventually(lambda: len(probe.seen) == 1, what="the inline delivery")
    msg, key, ident = probe.seen[0]
    assert (msg.robot, msg.seq, key) == ("r3", 4, peer.keys.robot_pose("r3"))
    assert ident != threading.get_ident()
    assert probe.counters["received"] == 1


@pytest.mark.parametrize("inline", [False, True], ids=["worker", "inline"])
def test_sample_key_off_hands_handlers_the_subscription_key(make_service, peer, inline):
    pattern = peer.keys.robot_pose("*")
    running = make_service(Probe, subscriptions=[{"key": pattern, "inline": inline, "sample_key": False}]).start()
    pub = publisher_for(peer, peer.keys.robot_pose("r5"))
    pub.put(good_pose("r5"))
    pub.put(b"not msgpack")
    probe = running.service
    eventually(lambda: len(probe.seen) == 1 and probe.counters["bad_messages"] == 1, what="both payloads")
    msg, key, _ = probe.seen[0]
    assert (msg.robot, key) == ("r5", pattern)
    assert probe.counters[f"bad_messages:{peer.keys.robot_pose('r5')}"] == 1  # still counted per sample key
    with pytest.raises(ValueError, match="sample_key"):
        probe.subscribe(pattern, RobotPose, probe.record, latest=True, sample_key=False)


def test_relay_passes_valid_payloads_on_byte_for_byte(make_service, peer):
    class Relay(Service):
        def setup(self) -> None:
            self.relay(self.keys.robot_pose("*"), RobotPose, self.keys.ping_reply())

    relay = make_service(Relay, "relay").service
    got: list[bytes] = []
    peer._declared.append(
        peer.session.declare_subscriber(peer.keys.ping_reply(), lambda s: got.append(s.payload.to_bytes()))
    )
    eventually(lambda: relay._publishers[relay.keys.ping_reply()].matching_status.matching, what="the listener")
    pub = publisher_for(peer, peer.keys.robot_pose("r0"))
    padded = encode(RobotPose(robot="r0", x=1.0, y=2.0, theta=0.0, src="peer-1", seq=9, stamp=3.0), {"pad": b"\0" * 40})
    pub.put(bad_pose("peer-1"))
    pub.put(padded)
    eventually(lambda: len(got) == 1 and relay.counters["bad_messages"] == 1, what="the relayed pose")
    time.sleep(0.2)
    assert got == [padded]  # the bytes received, unknown field and envelope included; the bad one stopped
    assert (relay.counters["received"], relay.counters["published"]) == (1, 1)


def test_publishers_use_the_shared_options(make_service, peer):
    probe = make_service(Probe).service
    publisher = probe.advertise(probe.keys.robot_pose("r0"))
    options = publisher_options()
    assert (publisher.congestion_control, publisher.priority, publisher.reliability, str(publisher.encoding)) == (
        options["congestion_control"],
        options["priority"],
        options["reliability"],
        str(options["encoding"]),
    )
    assert publisher_options(express=False)["express"] is False


def test_inline_and_latest_together_refused(make_service, peer):
    probe = make_service(Probe).service
    with pytest.raises(ValueError, match="inline"):
        probe.subscribe(peer.keys.robot_pose("*"), RobotPose, probe.record, latest=True, inline=True)


@pytest.mark.parametrize("inline", [False, True], ids=["worker", "inline"])
def test_handler_exceptions_do_not_kill_the_service(make_service, peer, inline, caplog):
    caplog.set_level(logging.ERROR, logger="arroch")
    seen: list[int] = []

    def fragile(msg: RobotPose, key: str) -> None:
        if msg.seq % 2:
            raise RuntimeError(f"odd seq {msg.seq}")
        seen.append(msg.seq)

    running = make_service(
        Probe, subscriptions=[{"key": peer.keys.robot_pose("*"), "handler": fragile, "inline": inline}]
    ).start()
    pub = publisher_for(peer, peer.keys.robot_pose("r0"))
    for seq in range(1, 11):
        pub.put(good_pose(seq=seq))
    eventually(lambda: len(seen) == 5, what="the even messages")
    assert seen == [2, 4, 6, 8, 10]
    assert running.service.counters["handler_errors"] == 5
    assert running.thread.is_alive()
    assert any("odd seq" in (r.exc_text or "") for r in caplog.records)


def test_timers_run_on_the_worker_and_survive_errors(make_service):
    probe = make_service(Probe).service
    calls: list[int] = []

    def tick() -> None:
        calls.append(threading.get_ident())
        if len(calls) == 1:
            raise RuntimeError("first tick fails")

    probe.every(0.02, tick, first=0.0)
    running_thread = threading.Thread(target=probe.run, daemon=True)
    running_thread.start()
    try:
        eventually(lambda: len(calls) >= 3, what="three ticks")
        assert probe.counters["handler_errors"] == 1
        assert set(calls) == {running_thread.ident}
    finally:
        probe.stop()
        running_thread.join(5)


# ---------------------------------------------------------------------------- stats and queries


def test_stats_queryable_answers_the_counters(make_service, peer):
    first = make_service(Probe, subscriptions=[{"key": peer.keys.robot_pose("*")}]).start().service
    second = make_service(Probe).service  # same name: a distinct instance id
    assert first.instance != second.instance and first.src != second.src
    pub = publisher_for(peer, peer.keys.robot_pose("r0"))
    pub.put(bad_pose("alpha"))
    pub.put(good_pose())
    eventually(lambda: first.counters["received"] == 1 and first.counters["bad_messages"] == 1, what="both payloads")

    [reply] = peer.query(peer.keys.stats("probe", first.instance), Event)
    assert reply.kind == "stats" and reply.src == first.src
    assert reply.data["instance"] == first.instance
    assert reply.data["received"] == 1 and reply.data["bad_messages"] == 1
    # A wildcard query gets one reply per service (each answers on its own key).
    replies = peer.query(peer.keys.stats("*", "*"), Event)
    assert sorted(r.data["instance"] for r in replies) == sorted([first.instance, second.instance, peer.instance])


def test_publish_stamps_the_envelope(make_service, peer):
    probe = make_service(Probe).service
    q = peer.collect(peer.keys.robot_pose("*"), RobotPose)
    probe.advertise(probe.keys.robot_pose("r0"))
    eventually(lambda: probe._publishers[probe.keys.robot_pose("r0")].matching_status.matching, what="the collector")
    for _ in range(3):
        probe.publish(probe.keys.robot_pose("r0"), RobotPose(robot="r0", x=1.0, y=1.0, theta=0.0))
    got = [q.get(timeout=10)[0] for _ in range(3)]
    assert [m.seq for m in got] == [1, 2, 3]
    assert {m.src for m in got} == {probe.src}
    assert probe.counters["published"] == 3


def test_a_prepared_sender_publishes_like_publish(make_service, peer):
    probe = make_service(Probe).service
    q = peer.collect(peer.keys.robot_pose("*"), RobotPose)
    send = probe.sender(probe.keys.robot_pose("r0"), RobotPose)
    keep = probe.sender(probe.keys.robot_pose("r1"), RobotPose, stamp=False)
    eventually(
        lambda: all(probe._publishers[probe.keys.robot_pose(r)].matching_status.matching for r in ("r0", "r1")),
        what="the collector",
    )
    for _ in range(2):
        send(RobotPose(robot="r0", x=1.0, y=1.0, theta=0.0))
    keep(RobotPose(robot="r1", x=2.0, y=1.0, theta=0.0, src="elsewhere-1", seq=41, stamp=5.0))
    got = sorted((q.get(timeout=10)[0] for _ in range(3)), key=lambda m: m.robot)
    assert [(m.robot, m.src, m.seq) for m in got] == [
        ("r0", probe.src, 1),
        ("r0", probe.src, 2),
        ("r1", "elsewhere-1", 41),
    ]
    assert probe.counters["published"] == 3


def test_serve_and_query(make_service, peer):
    probe = make_service(Probe).service
    probe.serve(probe.keys.plan(), lambda query: Event(kind="human_done", data={"task_duration": 1.5}))
    probe.serve(
        probe.keys.door_state("*"),
        lambda query: Event(kind="door_opened", data={"by": "human"}, door=str(query.key_expr).split("/")[3]),
    )
    probe.serve(probe.keys.constraints(), lambda query: None)  # nothing to say

    def ask(key: str) -> list[Event]:
        deadline = time.monotonic() + 10
        while True:  # the queryables may still be on their way to the router
            replies = peer.query(key, Event, timeout=1.0)
            if replies or time.monotonic() > deadline:
                return replies

    assert [r.kind for r in ask(peer.keys.plan())] == ["human_done"]
    [door] = ask(peer.keys.door_state("d7"))
    assert door.door == "d7"
    assert peer.query(peer.keys.constraints(), Event, timeout=0.5) == []
