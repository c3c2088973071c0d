"""Zenoh options: defaults → JSON5 file → environment → command line, and a real session from a file."""

from __future__ import annotations

import argparse
import json
import socket
import time

import pytest
import zenoh

from protocol.transport import (
    DEFAULT_ROUTER,
    ZenohOptions,
    add_zenoh_arguments,
    build_config,
    free_tcp_port,
    load_config_file,
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
        "client", [], [], False, None, None)
    config = build_config(opts)
    assert get(config, "mode") == "client"
    assert get(config, "connect/endpoints") == [DEFAULT_ROUTER]  # client mode needs somewhere to go
    assert get(config, "scouting/multicast/enabled") is False


def test_environment_overrides_defaults():
    env = {"ARROCH_ZENOH_MODE": "peer", "ARROCH_ZENOH_CONNECT": "tcp/127.0.0.1:1, tcp/127.0.0.1:2",
           "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:3", "ARROCH_ZENOH_MULTICAST": "1", "ARROCH_ZENOH_SHM": "0"}
    opts = options_from(parse(), env=env)
    assert (opts.mode, opts.connect, opts.listen, opts.multicast, opts.shared_memory) == (
        "peer", ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"], ["tcp/127.0.0.1:3"], True, False)
    config = build_config(opts)
    assert get(config, "mode") == "peer"
    assert get(config, "connect/endpoints") == ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"]
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:3"]
    assert get(config, "scouting/multicast/enabled") is True
    assert get(config, "transport/shared_memory/enabled") is False


def test_options_override_environment():
    env = {"ARROCH_ZENOH_MODE": "peer", "ARROCH_ZENOH_CONNECT": "tcp/127.0.0.1:1", "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:3"}
    opts = options_from(parse("--mode", "client", "--connect", "tcp/127.0.0.1:9", "--listen", "tcp/127.0.0.1:8"), env=env)
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
    env = {"ARROCH_ZENOH_CONFIG": json5_file(7448), "ARROCH_ZENOH_MODE": "client", "ARROCH_ZENOH_LISTEN": "tcp/127.0.0.1:5",
           "ARROCH_ZENOH_MULTICAST": "0"}
    config = build_config(options_from(parse(), env=env))
    assert get(config, "mode") == "client"  # an explicit "client" counts, though it is the default
    assert get(config, "listen/endpoints") == ["tcp/127.0.0.1:5"]
    assert get(config, "scouting/multicast/enabled") is False


def test_options_override_environment_and_file(json5_file, tmp_path):
    other = tmp_path / "other.json5"
    other.write_text("{ mode: 'router' }")
    env = {"ARROCH_ZENOH_CONFIG": str(other), "ARROCH_ZENOH_MODE": "router"}
    opts = options_from(parse("--zenoh-config", json5_file(7448), "--mode", "client", "--listen", "tcp/127.0.0.1:6"), env=env)
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
