"""What the running services declare on Zenoh is what protocol/graph.py says they declare.

The planner, the restrictor, the simulator in lockstep, the recorder and the AR client run as real
processes against a router whose Zenoh admin space is readable. The router lists every publisher,
subscriber and queryable each client session declared (``@/<router>/router/{publisher,subscriber,
queryable}/<key>``, with the declaring sessions' ids); a session is told from the others by the
``stats/<service>/<instance>`` queryable every Service declares. Beside that, every sample put in the
namespace is heard and its sender (the envelope's ``src``) and message type noted, so a publication
made with ``session.put`` (no publisher declared) is caught too, and so is a wrong type.

For each service:

- everything it declared (and every sample it put) is in its declaration, with the right type;
- everything its declaration says it uses unconditionally (or under a condition this run meets) was
  declared. Declarations are patterns: ``camera/*/frame`` covers ``camera/tablet/frame``.

Queries (``session.get``) leave no trace in the admin space and are not checked here.
"""

from __future__ import annotations

import json
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import pytest
import zenoh

from protocol.graph import (
    AR,
    AR_SIM_SOURCE,
    BY_NAME,
    FRAMES_ARRIVING,
    PLANNER,
    RECORDER,
    RESTRICTOR,
    SIM,
    SIM_CAMERA,
    SIM_CLOCK,
    SIM_HOLD,
    WITH_FEEDBACK,
    ServiceNode,
)
from runtime.transport import free_tcp_port
from tests.procs import Proc, arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

DECLARED = ("publisher", "subscriber", "queryable")  # the admin space's words
DIRECTION = {"publisher": "pub", "subscriber": "sub", "queryable": "serve"}
OBSERVE_TIMEOUT = 90.0  # wall s for every declared use to show (the first overlay comes within ~10 s)
ADMIN_TIMEOUT = 5.0  # wall s for one query of the router's admin space


@dataclass(frozen=True)
class Run:
    """A service as this test starts it: its declaration, its command line, and the conditions of the
    declaration (``Endpoint.when``) its command line meets."""

    node: ServiceNode
    argv: Callable[[str, str, Path], list[str]]  # (namespace, router endpoint, a folder of its own)
    conditions: frozenset[str] = frozenset()


SIM_CAMERA_ARGS = ("--camera", "tablet", "--camera-hold", "60", "--camera-every", "60")


def _connection(namespace: str, router: str) -> list[str]:
    return ["--namespace", namespace, "--connect", router]


# Started in this order; the simulator last, so the others hear the whole mission.
RUNS: tuple[Run, ...] = (
    Run(
        RESTRICTOR,
        lambda ns, router, folder: arroch(
            "restrictor", *_connection(ns, router), "--state-dir", str(folder), "--fresh"
        ),
        frozenset({SIM_CLOCK}),
    ),
    Run(PLANNER, lambda ns, router, folder: arroch("planner", *_connection(ns, router))),
    Run(
        RECORDER,
        lambda ns, router, folder: arroch("record", *_connection(ns, router), "--out", str(folder / "run.mcap")),
    ),
    Run(
        AR,
        lambda ns, router, folder: arroch("ar", *_connection(ns, router)),
        frozenset({SIM_CLOCK, WITH_FEEDBACK, AR_SIM_SOURCE, FRAMES_ARRIVING}),
    ),
    # The camera makes the frame, truth and overlay keys used; few frames, to keep rendering short.
    Run(
        SIM,
        lambda ns, router, folder: arroch(
            "sim", *_connection(ns, router), "--mode", "lockstep", "--seed", "1", *SIM_CAMERA_ARGS
        ),
        frozenset({SIM_CAMERA, SIM_HOLD}),
    ),
)


class _Envelope(msgspec.Struct):
    type: str = ""
    src: str = ""


_read_envelope = msgspec.msgpack.Decoder(_Envelope).decode


@dataclass
class Heard:
    """Samples put in the namespace: (relative key, message type) per sender."""

    by_src: dict[str, set[tuple[str, str]]] = field(default_factory=lambda: defaultdict(set))
    unreadable: list[str] = field(default_factory=list)  # keys of payloads with no ARROCH envelope
    lock: threading.Lock = field(default_factory=threading.Lock)


@pytest.fixture
def admin_router() -> Iterator[tuple[str, zenoh.Session]]:
    """A router (zenoh-python in router mode, as ``arroch router``) whose admin space may be read."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    config = {
        "mode": "router",
        "listen": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "adminspace": {"enabled": True, "permissions": {"read": True, "write": False}},
    }
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(config)))
    try:
        yield endpoint, session
    finally:
        session.close()


def _listen(session: zenoh.Session, prefix: str) -> tuple[Heard, zenoh.Subscriber]:
    heard = Heard()

    def on_sample(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr).removeprefix(prefix)
        try:
            envelope = _read_envelope(sample.payload.to_bytes())
        except msgspec.DecodeError:
            with heard.lock:
                heard.unreadable.append(key)
            return
        with heard.lock:
            heard.by_src[envelope.src].add((key, envelope.type))

    return heard, session.declare_subscriber(f"{prefix}**", on_sample)


def _bounded_get(session: zenoh.Session, selector: str, timeout: float) -> list[zenoh.Reply]:
    """The replies to ``selector`` that came within ``timeout`` (+1 s). The reply channel's iterator
    waits for the query's end: a callback and a deadline cannot keep a failing run waiting."""
    replies: list[zenoh.Reply] = []
    done = threading.Event()
    # The call itself on a thread of its own too: it was once seen to block (a deadlock in the
    # router's session); then the test fails on what it could not see instead of hanging.
    asking = threading.Thread(
        target=session.get,
        args=(selector,),
        kwargs={"handler": zenoh.handlers.Callback(replies.append, done.set), "timeout": timeout},
        daemon=True,
    )
    asking.start()
    done.wait(timeout + 1.0)
    return list(replies)


def _declarations(session: zenoh.Session, prefix: str) -> dict[str, dict[str, set[str]]]:
    """Per client session id: per admin word (publisher, ...), the relative keys it declared."""
    out: dict[str, dict[str, set[str]]] = defaultdict(lambda: defaultdict(set))
    for word in DECLARED:
        for reply in _bounded_get(session, f"@/{session.zid()}/router/{word}/**", ADMIN_TIMEOUT):
            if reply.ok is None:
                continue
            key = str(reply.ok.key_expr).split(f"/router/{word}/", 1)[1]
            if not key.startswith(prefix):
                continue
            for zid in json.loads(reply.ok.payload.to_bytes())["clients"]:
                out[zid][word].add(key.removeprefix(prefix))
    return out


def _includes(pattern: str, key: str) -> bool:
    return zenoh.KeyExpr(pattern).includes(zenoh.KeyExpr(key))


@dataclass
class Mismatches:
    """How what one service did on Zenoh differs from its declaration."""

    extra: list[str] = field(default_factory=list)  # done, but not in the declaration
    missing: list[str] = field(default_factory=list)  # in the declaration (for this run), not done (yet)


def _compare(run: Run, declared: dict[str, set[str]], heard: set[tuple[str, str]]) -> Mismatches:
    node, found = run.node, Mismatches()
    arroch_endpoints = [e for e in node.endpoints if not e.is_ros2]
    framework_prefix = f"stats/{node.name}/"  # every Service's own queryable (protocol.graph.FRAMEWORK)
    for word, keys in declared.items():
        direction = DIRECTION[word]
        for key in sorted(keys):
            if direction == "serve" and key.startswith(framework_prefix):
                continue
            if not any(e.direction == direction and _includes(e.key, key) for e in arroch_endpoints):
                found.extra.append(f"{node.name} declared a {word} on {key!r}, which protocol/graph.py does not list")
    for key, type_name in sorted(heard):
        matching = [e for e in arroch_endpoints if e.direction == "pub" and _includes(e.key, key)]
        if not matching:
            found.extra.append(f"{node.name} put a {type_name} on {key!r}, which protocol/graph.py does not list")
        elif all(isinstance(e.payload, type) and e.payload_name != type_name for e in matching):
            listed = sorted({e.payload_name for e in matching})
            found.extra.append(f"{node.name} put a {type_name} on {key!r}; protocol/graph.py lists {listed}")
    for e in arroch_endpoints:
        if e.direction == "query" or (e.when and e.when not in run.conditions):
            continue
        word = next(w for w, d in DIRECTION.items() if d == e.direction)
        if not any(_includes(e.key, key) for key in declared.get(word, ())):
            found.missing.append(f"{node.name}: protocol/graph.py lists {e.direction} {e.key!r} ({e.purpose})")
    return found


def _observe(session: zenoh.Session, prefix: str, heard: Heard) -> Mismatches:
    """One look at the admin space and what was heard so far, compared with every run's declaration."""
    declared = _declarations(session, prefix)
    # Each session's stats queryable names its service: stats/<service>/<instance>.
    service_of_zid: dict[str, str] = {}
    service_of_src: dict[str, str] = {}
    for zid, words in declared.items():
        for key in words.get("queryable", ()):
            if key.startswith("stats/"):
                _, name, instance = key.split("/")
                service_of_zid[zid], service_of_src[instance] = name, name
    assert sorted(service_of_zid.values()) == sorted(run.node.name for run in RUNS), service_of_zid
    found = Mismatches()
    heard_by_service: dict[str, set[tuple[str, str]]] = defaultdict(set)
    with heard.lock:
        for src, samples in heard.by_src.items():
            if src in service_of_src:
                heard_by_service[service_of_src[src]] |= samples
            else:
                found.extra.append(f"samples from {src!r}, no service of this run: {sorted(samples)}")
        found.extra += [f"a payload with no ARROCH envelope on {key!r}" for key in heard.unreadable]
    for run in RUNS:
        (zid,) = [z for z, name in service_of_zid.items() if name == run.node.name]
        one = _compare(run, declared[zid], heard_by_service[run.node.name])
        found.extra += one.extra
        found.missing += one.missing
    return found


def test_conditions_named_here_exist_in_the_graph() -> None:
    for run in RUNS:
        unknown = run.conditions - run.node.conditions
        assert not unknown, f"{run.node.name}: conditions {sorted(unknown)} are not in protocol/graph.py"
        assert BY_NAME[run.node.name] is run.node


def test_running_services_declare_what_the_graph_says(
    admin_router: tuple[str, zenoh.Session],
    spawn: Callable[..., Proc],
    namespace: str,
    tmp_path: Path,
    request: pytest.FixtureRequest,
) -> None:
    endpoint, session = admin_router
    prefix = f"arroch/{namespace}/"
    # What the services send is heard on a client session of its own: a Python callback on the
    # router's session, run for every camera frame, once deadlocked the router's admin queries.
    listener_session = zenoh.open(
        zenoh.Config.from_json5(
            json.dumps(
                {"mode": "client", "connect": {"endpoints": [endpoint]}, "scouting": {"multicast": {"enabled": False}}}
            )
        )
    )
    request.addfinalizer(listener_session.close)
    heard, listener = _listen(listener_session, prefix)
    # undeclared before its session closes (finalizers run last first): closing a session with a
    # Python callback still declared hung this test's teardown for 25 minutes beside a loaded suite
    request.addfinalizer(listener.undeclare)
    for run in RUNS:
        folder = tmp_path / run.node.name
        folder.mkdir()
        proc = spawn(run.argv(namespace, endpoint, folder), name=run.node.name)
        proc.wait_for("up on namespace", timeout=60)
    # Poll until every declared use has shown (publishers are declared at their first message);
    # anything undeclared seen on the way fails the test, even if it is gone by the end.
    extra: set[str] = set()
    deadline = time.monotonic() + OBSERVE_TIMEOUT
    while True:
        found = _observe(session, prefix, heard)
        extra.update(found.extra)
        if not found.missing or time.monotonic() > deadline:
            break
        time.sleep(1.0)
    missing = [f"{line}: not declared within {OBSERVE_TIMEOUT:g} s" for line in found.missing]
    assert not extra and not missing, "\n".join([*sorted(extra), *missing])
