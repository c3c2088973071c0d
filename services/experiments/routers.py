"""Zenoh routers for trials: an ``arroch router`` child process plus the runner's session on it.

Trials never hear each other however routers are shared, because each trial has its own key
namespace. How many routers a sweep starts is a speed question only (``--router``):

- ``worker``: one per worker, reused by its trials (default: no router start-up per trial, and no
  router carries more than one trial's traffic at a time);
- ``shared``: one for the whole sweep;
- ``trial``: a fresh router per trial (the most isolated, and the slowest to start).

The router is started through :class:`runtime.launch.children.Child`, like ``arroch up``
starts it: its own process group, tied to the thread that started it by the parent-death signal.
"""

from __future__ import annotations

import collections
import logging
import os
import time

from runtime.launch.catalog import Launch, router_argv
from runtime.launch.children import Child, describe_exit, stop_all
from runtime.transport import free_tcp_port

from .monitor import RouterMonitor

log = logging.getLogger("arroch.experiment")

ROUTER_MODES = ("worker", "shared", "trial")
ROUTER_READY = "router ready"  # what `arroch router` prints once it listens
START_ATTEMPTS = 3  # a free port can be taken between picking it and binding it: try another
# Set in the environment of every process a sweep starts (the sweep's pid): `grep` /proc/*/environ
# for it to find them (tests check that none outlives the sweep, even one killed with SIGKILL).
RUN_ENV = "ARROCH_EXPERIMENT_RUN"


def child_env() -> dict[str, str]:
    return {RUN_ENV: str(os.getpid())}


class RouterError(RuntimeError):
    """A router could not be started."""


class Router:
    """A running router on a free localhost port, with a monitor session connected to it."""

    def __init__(self, log_level: str | None = None, *, start_timeout: float = 20.0) -> None:
        self.log_level = log_level
        self.start_timeout = start_timeout
        self.child: Child | None = None
        self.monitor: RouterMonitor | None = None
        self.endpoint = ""
        self._output: collections.deque[str] = collections.deque(maxlen=50)

    def start(self) -> Router:
        last = ""
        for _ in range(START_ATTEMPTS):
            self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
            argv = router_argv(Launch(namespace="-", log_level=self.log_level), self.endpoint)
            self.child = Child(
                "router", argv, env=child_env(), on_line=lambda _name, line: self._output.append(line), restart=False
            )
            self.child.start(ROUTER_READY)
            deadline = time.monotonic() + self.start_timeout
            while not self.child.ready.wait(0.05):
                if not self.child.running() or time.monotonic() > deadline:
                    break
            if self.child.ready.is_set():
                try:
                    self.monitor = RouterMonitor(self.endpoint)
                except Exception as exc:
                    self.stop()
                    raise RouterError(f"cannot join the router on {self.endpoint}: {exc}") from None
                log.debug("router up on %s (pid %s)", self.endpoint, self.child.pid)
                return self
            code = self.child.returncode()
            last = (
                f"the router {describe_exit(code)}"
                if code is not None
                else f"the router did not report ready within {self.start_timeout:.0f} s"
            )
            stop_all([self.child], 2.0)
            tail = " | ".join(list(self._output)[-3:])
            log.debug("router on %s failed: %s (%s)", self.endpoint, last, tail)
        raise RouterError(f"{last} (last output: {' | '.join(list(self._output)[-3:]) or 'none'})")

    def alive(self) -> bool:
        return self.child is not None and self.child.running()

    def stop(self) -> None:
        if self.monitor is not None:
            self.monitor.close()
            self.monitor = None
        if self.child is not None:
            stop_all([self.child], 3.0)
            self.child = None
