"""Zenoh session configuration for every ARROCH process.

Precedence, lowest first: built-in defaults → a Zenoh JSON5 config file (taken as it is) →
environment variables → command-line options. Defaults: ``client`` mode connecting to a router
on ``tcp/127.0.0.1:7447`` (what ``arroch router`` and ``arroch up`` start), multicast scouting off.

It also has :func:`on_zenoh_thread`, the one way ARROCH runs a Python callback on Zenoh's own
receive thread (the Service's inline subscriptions, and the raw baselines that are compared with them).

Environment variables (each overrides the file, and is overridden by the matching option):

===========================  ======================================================
``ARROCH_ZENOH_CONFIG``       path of a Zenoh JSON5 config file
``ARROCH_ZENOH_MODE``         ``peer``, ``client`` or ``router``
``ARROCH_ZENOH_CONNECT``      comma-separated endpoints to connect to
``ARROCH_ZENOH_LISTEN``       comma-separated endpoints to listen on
``ARROCH_ZENOH_MULTICAST``    ``1`` to turn multicast scouting on
``ARROCH_ZENOH_SHM``          ``1`` to turn shared-memory transport on
===========================  ======================================================

Shared memory is off by default, unlike Zenoh's own default. Measured with eclipse-zenoh 1.10 on a
loaded 2-core machine: payloads of 3 KiB and more (Zenoh puts those through shared memory: plans,
commands with trajectories, camera frames, overlays) were lost. A ``--fast`` replay of a 4,295-message
mission lost 4-34 of them in each of 3 runs with it on, none in 7 runs with it off; and a sweep trial
hung in lockstep when a planner's plan, its repeats and its reply to a query for it never arrived,
while its small messages did (one trial in 216).

A blocked send waits up to 60 s before Zenoh closes the link (``BLOCK_WAIT_BEFORE_CLOSE_US``; Zenoh's
own default is 5 s, rmw_zenoh's session default 60 s). ARROCH's publishers block rather than drop, so
a router whose queue to a slow subscriber stays full for 5 s closes that subscriber's session, and
everything sent until the client reconnects is lost: a subscriber that stalled 8 s lost 2,605 of
3,000 messages with 5 s and none with 60 s (``tests/reliability/test_slow_subscriber.py``).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import socket
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import zenoh

T = TypeVar("T")

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
MODES = ("peer", "client", "router")


@dataclass
class ZenohOptions:
    mode: str = "client"
    connect: list[str] = field(default_factory=list)
    listen: list[str] = field(default_factory=list)
    config_file: str | None = None
    multicast: bool = False
    shared_memory: bool = False  # off: large payloads were lost through it (module docstring)
    # Names of the settings an environment variable or a command-line option gave explicitly
    # ("mode", "connect", ...). With a config file only these override the file, so an explicit
    # ``--zenoh-mode client`` beats a file's ``mode: "peer"`` while the default "client" does not.
    explicit: set[str] = field(default_factory=set)

    def effective_connect(self) -> list[str]:
        """Client mode with nothing to connect to would be useless: default to the local router."""
        if self.connect or self.mode != "client" or self.config_file:
            return self.connect
        return [DEFAULT_ROUTER]


def _split(value: str | None) -> list[str]:
    return [part.strip() for part in (value or "").split(",") if part.strip()]


class _DeprecatedZenohMode(argparse.Action):
    """``--mode`` for the Zenoh mode: works as ``--zenoh-mode`` does, with a warning on stderr."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option: Any = None):
        print(f"{parser.prog}: --mode {values} is deprecated here: use --zenoh-mode {values}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_zenoh_arguments(parser: argparse.ArgumentParser) -> None:
    """The Zenoh options every service's command line has."""
    group = parser.add_argument_group("zenoh transport")
    group.add_argument(
        "--zenoh-config", metavar="FILE", help="Zenoh JSON5 config file, used as it is (env ARROCH_ZENOH_CONFIG)"
    )
    group.add_argument("--zenoh-mode", choices=MODES, help="Zenoh session mode (default client; env ARROCH_ZENOH_MODE)")
    # The old spelling, kept working: elsewhere (arroch sim, up, demo) --mode is the site clock's mode.
    group.add_argument("--mode", choices=MODES, dest="zenoh_mode", action=_DeprecatedZenohMode, help=argparse.SUPPRESS)
    group.add_argument(
        "--connect",
        metavar="ENDPOINTS",
        help=f"comma-separated endpoints to connect to (default {DEFAULT_ROUTER} in client mode; env "
        "ARROCH_ZENOH_CONNECT)",
    )
    group.add_argument(
        "--listen", metavar="ENDPOINTS", help="comma-separated endpoints to listen on (env ARROCH_ZENOH_LISTEN)"
    )
    group.add_argument(
        "--multicast",
        action="store_true",
        default=None,
        help="turn multicast scouting on (off by default; env ARROCH_ZENOH_MULTICAST=1)",
    )


def options_from(args: argparse.Namespace | None = None, env: dict[str, str] | None = None) -> ZenohOptions:
    """Merge environment variables and parsed command-line options (options win)."""
    env = dict(os.environ) if env is None else env
    opts = ZenohOptions()
    opts.config_file = env.get("ARROCH_ZENOH_CONFIG") or None
    if env.get("ARROCH_ZENOH_MODE"):
        opts.mode = env["ARROCH_ZENOH_MODE"]
        opts.explicit.add("mode")
    if env.get("ARROCH_ZENOH_CONNECT"):
        opts.connect = _split(env["ARROCH_ZENOH_CONNECT"])
        opts.explicit.add("connect")
    if env.get("ARROCH_ZENOH_LISTEN"):
        opts.listen = _split(env["ARROCH_ZENOH_LISTEN"])
        opts.explicit.add("listen")
    if env.get("ARROCH_ZENOH_MULTICAST") is not None:
        opts.multicast = env["ARROCH_ZENOH_MULTICAST"] == "1"
        opts.explicit.add("multicast")
    if env.get("ARROCH_ZENOH_SHM") is not None:
        opts.shared_memory = env["ARROCH_ZENOH_SHM"] == "1"
        opts.explicit.add("shared_memory")
    if args is not None:
        if getattr(args, "zenoh_config", None):
            opts.config_file = args.zenoh_config
        if getattr(args, "zenoh_mode", None):
            opts.mode = args.zenoh_mode
            opts.explicit.add("mode")
        if getattr(args, "connect", None):
            opts.connect = _split(args.connect)
            opts.explicit.add("connect")
        if getattr(args, "listen", None):
            opts.listen = _split(args.listen)
            opts.explicit.add("listen")
        if getattr(args, "multicast", None):
            opts.multicast = True
            opts.explicit.add("multicast")
    if opts.mode not in MODES:
        raise ValueError(f"zenoh mode {opts.mode!r} is not one of {', '.join(MODES)}")
    return opts


def load_config_file(path: str | Path) -> zenoh.Config:
    """A Zenoh config file as it is: ``.json``, ``.json5``, ``.yaml`` as Zenoh reads them, any other
    name (``zenoh.conf``) as JSON5, which Zenoh itself would refuse for its extension alone."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"zenoh config file {path} does not exist")
    try:
        if path.suffix.lower() in (".json", ".json5", ".yaml"):
            return zenoh.Config.from_file(str(path))
        return zenoh.Config.from_json5(path.read_text())
    except Exception as exc:  # zenoh raises its own ZError; callers report ValueError in one line
        raise ValueError(f"zenoh config file {path}: {exc}") from None


BLOCK_WAIT_BEFORE_CLOSE_US = 60_000_000  # see the module's docstring


def build_config(opts: ZenohOptions) -> zenoh.Config:
    """A zenoh.Config from the options; a config file is loaded as it is, then options applied."""
    if opts.config_file:
        config = load_config_file(opts.config_file)
        # A file is the deployment's word: only what env/options gave explicitly overrides it
        # (a non-default value set in code counts as explicit too).
        if "mode" in opts.explicit or opts.mode != "client":
            config.insert_json5("mode", json.dumps(opts.mode))
        if "multicast" in opts.explicit or opts.multicast:
            config.insert_json5("scouting/multicast/enabled", json.dumps(opts.multicast))
        if "shared_memory" in opts.explicit or opts.shared_memory:
            config.insert_json5("transport/shared_memory/enabled", json.dumps(opts.shared_memory))
    else:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(opts.mode))
        config.insert_json5("scouting/multicast/enabled", json.dumps(opts.multicast))
        config.insert_json5("transport/shared_memory/enabled", json.dumps(opts.shared_memory))
        config.insert_json5(
            "transport/link/tx/queue/congestion_control/block/wait_before_close", str(BLOCK_WAIT_BEFORE_CLOSE_US)
        )
    connect = opts.effective_connect()
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(connect))
    if opts.listen:
        config.insert_json5("listen/endpoints", json.dumps(opts.listen))
    return config


def open_session(opts: ZenohOptions) -> zenoh.Session:
    return zenoh.open(build_config(opts))


def free_tcp_port() -> int:
    """A TCP port free on 127.0.0.1 right now (for tests and local runs)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# Zenoh threads that keep a Python thread state between callbacks (see on_zenoh_thread).
_kept_threads: set[int] = set()
_gilstate_ensure = ctypes.pythonapi.PyGILState_Ensure


def keep_thread_state() -> None:
    """Give the calling thread (one of Zenoh's, not made by Python) a Python thread state for good.

    zenoh-python takes the GIL for a callback with ``PyGILState_Ensure`` and gives it back with
    ``PyGILState_Release``; on a thread Python did not create, the release deletes the thread state
    the ensure had just made. Every callback then builds a thread state anew (and, on its first frame,
    a fresh frame stack) and finds every ``threading.local`` empty: 15-30 µs per
    sample measured on a busy 2-core machine. One ensure that is never released keeps the state
    (and its thread-locals) for the thread's lifetime; the state is
    reclaimed with the interpreter. Idempotent per thread; call it with the GIL held."""
    ident = threading.get_ident()
    if ident not in _kept_threads:
        _kept_threads.add(ident)
        _gilstate_ensure()


def on_zenoh_thread(fn: Callable[[T], object]) -> zenoh.handlers.Callback:
    """``fn`` as a Zenoh callback that runs on Zenoh's own receive thread, as soon as a sample arrives.

    A plain Python callable given to zenoh-python runs on a Python thread of its own, fed by Zenoh's
    thread through a channel (``Callback(..., indirect=True)``, the default): safe for slow code,
    but each sample then costs a thread wake-up. Here the hand-off is skipped, so ``fn`` must be
    quick (it holds up everything behind it on that link) and thread-safe (Zenoh may call it from
    several threads). The thread keeps its Python thread state between calls
    (:func:`keep_thread_state`)."""
    kept, get_ident = _kept_threads, threading.get_ident

    def call(arg: T) -> None:
        if get_ident() not in kept:
            keep_thread_state()
        fn(arg)

    return zenoh.handlers.Callback(call, indirect=False)


class NoRouter(ConnectionError):
    """No Zenoh router answers where a client would connect (the message says what to start)."""


def router_answers(endpoint: str, timeout: float = 0.5) -> bool | None:
    """Whether something accepts TCP connections at a ``tcp/HOST:PORT`` (or ``tls/...``) endpoint;
    None for other kinds of endpoint, which cannot be checked this way."""
    proto, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    if proto not in ("tcp", "tls") or not port.isdigit():
        return None
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            return True
    except OSError:
        return False


def through_local_router(opts: ZenohOptions, *, become: bool) -> tuple[ZenohOptions, str]:
    """Options for a client that joins through a router, checked before Zenoh is asked (whose own
    error would be a raw one): unchanged when a router answers, or when they cannot be checked (a
    config file, another mode, endpoints other than TCP).

    When none answers: with ``become`` and the default endpoint (no ``--connect``), this process
    becomes the router there (router mode, listening on it: other processes connect to it as to
    ``arroch router``), and the second value says so in one line; otherwise :class:`NoRouter`."""
    if opts.config_file or opts.mode != "client":
        return opts, ""
    endpoints = opts.effective_connect()
    answers = [router_answers(endpoint) for endpoint in endpoints]
    if not endpoints or any(a is not False for a in answers):
        return opts, ""
    where = ", ".join(endpoints)
    if become and "connect" not in opts.explicit:
        routing = ZenohOptions(
            mode="router",
            listen=list(endpoints),
            multicast=opts.multicast,
            shared_memory=opts.shared_memory,
            explicit={"mode", "listen"},
        )
        return routing, f"no Zenoh router answers on {where}: this process is the router there until it stops"
    raise NoRouter(
        f"no Zenoh router answers on {where}: start one (`arroch router --listen {endpoints[0]}`, or `arroch up`, "
        "or `arroch view`, which becomes one), or give --connect"
    )
