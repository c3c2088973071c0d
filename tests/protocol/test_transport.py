"""Zenoh options: defaults → JSON5 file → environment → command line, and a real session from a file."""

from __future__ import annotations

import argparse
import json
import socket
import threading
import time

import pytest
import zenoh

from runtime.transport import (
    DEFAULT_ROUTER,
    ZenohOptions,
    add_zenoh_arguments,
    build_config,
    free_tcp_port,
    load_config_file,
    on_zenoh_thread,
    open_session,
    options_from,
)


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser)
    return parser.parse_args(list(argv))


def get(config: zenoh.Config, key: str):
    return json.loads(config.get_json(key))


# A JSON5 file with everything JSON does not allow: comments, unquoted keys, trailing commas,
# single quotes.
JSON5_FILE = """{
  // written by hand, as deployments do
  mode: 'peer',
  listen: { endpoints: ["tcp/127.0.0.1:%(port)d",], },
  scouting: { multicast: { enabled: %(multicast)s, }, },
  /* a block comment */
  transport: { shared_memory: { enabled: false } },
}
"""


@pytest.fixture
def json5_file(tmp_path):
    def make(port: int = 7448, name: str = "zenoh.json5", multicast: bool = True) -> str:
        path = tmp_path / name
        path.write_text(JSON5_FILE % {"port": port, "multicast": json.dumps(multicast)})
        return str(path)

    return make


def test_defaults():
    opts = options_from(parse(), env={})
    assert (opts.mode, opts.connect, opts.listen, opts.multicast, opts.shared_memory, opts.config_file) == (
        "client",
        [],
        [],
        False,
        False,
        None,
    )
    config = build_config(opts)
    assert get(config, "mode") == "client"
    assert get(config, "connect/endpoints") == [DEFAULT_ROUTER]  # client mode needs somewhere to go
    assert get(config, "scouting/multicast/enabled") is False
    assert get(config, "transport/shared_memory/enabled") is False  # unlike Zenoh's default: it lost payloads
    # unlike Zenoh's 5 s: a router closed a stalled subscriber's session, losing what it sent meanwhile
    assert get(config, "transport/link/tx/queue/congestion_control/block/wait_before_close") == 60_000_000
    assert get(build_config(options_from(parse(), env={"ARROCH_ZENOH_SHM": "1"})), "transport/shared_memory/enabled")


def test_environment_overrides_defaults():
    env = {
        "ARROCH_ZENOH_MODE": "peer",
        "ARROCH_ZENOH_CONNECT": "tcp/127.0.0.1:1, tcp/127.0.0.1:2",
        "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:3",
        "ARROCH_ZENOH_MULTICAST": "1",
        "ARROCH_ZENOH_SHM": "0",
    }
    opts = options_from(parse(), env=env)
    assert (opts.mode, opts.connect, opts.listen, opts.multicast, opts.shared_memory) == (
        "peer",
        ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"],
        ["tcp/127.0.0.1:3"],
        True,
        False,
    )
    config = build_config(opts)
    assert get(config, "mode") == "peer"
    assert get(config, "connect/endpoints") == ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"]
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:3"]
    assert get(config, "scouting/multicast/enabled") is True
    assert get(config, "transport/shared_memory/enabled") is False


def test_options_override_environment():
    env = {
        "ARROCH_ZENOH_MODE": "peer",
        "ARROCH_ZENOH_CONNECT": "tcp/127.0.0.1:1",
        "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:3",
    }
    opts = options_from(
        parse("--mode", "client", "--connect", "tcp/127.0.0.1:9", "--listen", "tcp/127.0.0.1:8"), env=env
    )
    assert (opts.mode, opts.connect, opts.listen) == ("client", ["tcp/127.0.0.1:9"], ["tcp/127.0.0.1:8"])
    assert get(build_config(opts), "connect/endpoints") == ["tcp/127.0.0.1:9"]


def test_bad_mode_refused():
    with pytest.raises(ValueError, match="not one of"):
        options_from(parse(), env={"ARROCH_ZENOH_MODE": "satellite"})


def test_json5_file_is_taken_as_it_is(json5_file):
    config = build_config(options_from(parse("--zenoh-config", json5_file(7448)), env={}))
    assert get(config, "mode") == "peer"  # the file's word beats the built-in default (client)
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:7448"]
    assert get(config, "scouting/multicast/enabled") is True
    assert get(config, "transport/shared_memory/enabled") is False
    assert get(config, "connect/endpoints") == []  # no default router forced onto a file


def test_environment_overrides_the_file(json5_file):
    env = {
        "ARROCH_ZENOH_CONFIG": json5_file(7448),
        "ARROCH_ZENOH_MODE": "client",
        "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:5",
        "ARROCH_ZENOH_MULTICAST": "0",
    }
    config = build_config(options_from(parse(), env=env))
    assert get(config, "mode") == "client"  # an explicit "client" counts, though it is the default
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:5"]
    assert get(config, "scouting/multicast/enabled") is False


def test_options_override_environment_and_file(json5_file, tmp_path):
    other = tmp_path / "other.json5"
    other.write_text("{ mode: 'router' }")
    env = {"ARROCH_ZENOH_CONFIG": str(other), "ARROCH_ZENOH_MODE": "router"}
    opts = options_from(
        parse("--zenoh-config", json5_file(7448), "--mode", "client", "--listen", "tcp/127.0.0.1:6"), env=env
    )
    config = build_config(opts)
    assert opts.config_file == json5_file(7448)  # the option's file, not the environment's
    assert get(config, "mode") == "client"
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:6"]


def test_config_file_with_another_name_is_read_as_json5(json5_file):
    config = load_config_file(json5_file(7448, name="zenoh.conf"))
    assert get(config, "mode") == "peer"


def test_missing_or_broken_config_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        build_config(ZenohOptions(config_file=str(tmp_path / "nope.json5")))
    broken = tmp_path / "broken.json5"
    broken.write_text("{ mode: ")
    with pytest.raises(ValueError, match="broken.json5"):
        build_config(ZenohOptions(config_file=str(broken)))


def test_free_tcp_port_is_bindable():
    port = free_tcp_port()
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", port))


def test_sessions_from_a_json5_file_talk(json5_file):
    """A listening peer configured only by a JSON5 file, a client of it configured by options."""
    port = free_tcp_port()
    # Multicast scouting stays off: a test must not go looking for other peers on this machine.
    listener = open_session(options_from(parse("--zenoh-config", json5_file(port, multicast=False)), env={}))
    try:
        talker = open_session(ZenohOptions(mode="client", connect=[f"tcp/127.0.0.1:{port}"]))
        try:
            got: list[bytes] = []
            sub = listener.declare_subscriber("arroch/t/json5", lambda s: got.append(s.payload.to_bytes()))
            deadline = time.monotonic() + 10
            while not got and time.monotonic() < deadline:
                talker.put("arroch/t/json5", b"hello")
                time.sleep(0.05)
            sub.undeclare()
            assert got and got[0] == b"hello"
        finally:
            talker.close()
    finally:
        listener.close()


def test_zenoh_thread_callbacks_keep_their_thread_state():
    """on_zenoh_thread runs the callback on Zenoh's own thread (not on the caller's, not through
    zenoh-python's hand-off thread) and that thread keeps its Python state between samples: a
    thread-local set by one sample is still there for the next one on the same thread."""
    port = free_tcp_port()
    listener = open_session(ZenohOptions(mode="peer", listen=[f"tcp/127.0.0.1:{port}"], shared_memory=False))
    try:
        talker = open_session(ZenohOptions(mode="peer", connect=[f"tcp/127.0.0.1:{port}"], shared_memory=False))
        try:
            local = threading.local()
            calls: list[tuple[int, bool]] = []  # (thread, whether its thread-local was already set)

            def on_sample(sample: zenoh.Sample) -> None:
                calls.append((threading.get_ident(), getattr(local, "seen", False)))
                local.seen = True

            callback = on_zenoh_thread(on_sample)
            assert callback.indirect is False
            sub = listener.declare_subscriber("arroch/t/thread", callback)
            deadline = time.monotonic() + 10
            while not calls and time.monotonic() < deadline:
                talker.put("arroch/t/thread", b"first")
                time.sleep(0.05)
            assert calls, "no sample arrived"
            before = len(calls)
            for _ in range(30):
                talker.put("arroch/t/thread", b"more")
            while len(calls) < before + 30 and time.monotonic() < deadline:
                time.sleep(0.01)
            sub.undeclare()
        finally:
            talker.close()
    finally:
        listener.close()
    assert len(calls) >= before + 30
    assert threading.get_ident() not in {ident for ident, _ in calls}
    # Every call after a thread's first found the state its first call left.
    firsts: set[int] = set()
    for ident, seen in calls:
        assert seen == (ident in firsts), (ident, seen)
        firsts.add(ident)
    assert len(firsts) < len(calls)  # some thread ran several callbacks, so the check above bit
