"""Child processes of ``arroch up``: start, watch, restart with backoff, stop without leftovers.

Each child runs in its own process group (``start_new_session``), so a terminal's Ctrl-C reaches
only the supervisor, which then stops the children in order, and a signal sent to the group also
reaches anything the child started. Children are started through :mod:`.pdeath`, which asks the
kernel to SIGTERM them if the supervisor dies without cleaning up (even by SIGKILL).
"""

from __future__ import annotations

import collections
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

log = logging.getLogger("arroch.up")

CONFIG_ERROR = 2  # run_service's exit code for bad configuration: restarting cannot help


@dataclass
class RestartPolicy:
    """Exponential backoff between restarts, and a cap on restarts per minute.

    The n-th consecutive quick failure waits ``initial * factor**(n-1)`` (at most ``max_delay``); a
    child that ran ``stable_after`` seconds before failing starts the series afresh. More than
    ``max_per_minute`` restarts within 60 s means the child cannot run here: give up.
    """

    initial: float = 0.5
    factor: float = 2.0
    max_delay: float = 30.0
    max_per_minute: int = 5
    stable_after: float = 30.0
    _streak: int = 0
    _recent: collections.deque = field(default_factory=collections.deque)

    def next_delay(self, now: float, ran_for: float) -> float | None:
        """Seconds to wait before restarting, or None to give up."""
        while self._recent and now - self._recent[0] > 60.0:
            self._recent.popleft()
        if len(self._recent) >= self.max_per_minute:
            return None
        self._streak = 1 if ran_for >= self.stable_after else self._streak + 1
        self._recent.append(now)
        return min(self.initial * self.factor ** (self._streak - 1), self.max_delay)

    @property
    def restarts_last_minute(self) -> int:
        return len(self._recent)


def describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with code {code}"


class Child:
    """One supervised process. ``on_line(name, line)`` receives its merged stdout/stderr."""

    def __init__(
        self,
        name: str,
        argv: list[str],
        *,
        env: dict[str, str] | None = None,
        on_line: Callable[[str, str], None],
        cwd: str | None = None,
        policy: RestartPolicy | None = None,
        restart: bool = True,
    ) -> None:
        self.name = name
        self.argv = argv
        self.env = env or {}
        self.on_line = on_line
        self.cwd = cwd
        self.policy = policy or RestartPolicy()
        self.restart = restart
        self.popen: subprocess.Popen[str] | None = None
        self.started_at = 0.0
        self.starts = 0
        self.restart_at: float | None = None  # monotonic time of a scheduled restart
        self.gave_up = False
        self.exit_reported = False
        self._reader: threading.Thread | None = None
        self._ready_text: str | None = None
        self.ready = threading.Event()

    # ------------------------------------------------------------------ start

    def start(self, ready_text: str | None = None) -> None:
        """Start (or restart). ``ready_text``: a line marking readiness (sets :attr:`ready`)."""
        from . import pdeath  # the wrapper module, run as a script in the child

        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"  # lines as they happen, not when a buffer fills
        env.update(self.env)
        self._ready_text = ready_text
        self.ready.clear()
        wrapped = [sys.executable, pdeath.__file__, str(os.getpid()), "--", *self.argv]
        self.popen = subprocess.Popen(
            wrapped,
            cwd=self.cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            errors="replace",
            start_new_session=True,
        )
        self.started_at = time.monotonic()
        self.starts += 1
        self.restart_at = None
        self.exit_reported = False
        self._reader = threading.Thread(target=self._pump, args=(self.popen,), name=f"log-{self.name}", daemon=True)
        self._reader.start()

    def _pump(self, popen: subprocess.Popen[str]) -> None:
        assert popen.stdout is not None
        for raw in popen.stdout:
            line = raw.rstrip("\n")
            if self._ready_text and self._ready_text in line:
                self.ready.set()
            self.on_line(self.name, line)

    # ------------------------------------------------------------------ state

    @property
    def pid(self) -> int | None:
        return self.popen.pid if self.popen else None

    def running(self) -> bool:
        return self.popen is not None and self.popen.poll() is None

    def returncode(self) -> int | None:
        return None if self.popen is None else self.popen.poll()

    def ran_for(self) -> float:
        return time.monotonic() - self.started_at

    def flush_output(self, timeout: float = 1.0) -> None:
        """Wait for the last lines of an exited child to be passed on."""
        if self._reader is not None:
            self._reader.join(timeout)

    # ------------------------------------------------------------------ stop

    def signal(self, sig: int) -> None:
        if self.popen is not None:
            try:
                os.killpg(self.popen.pid, sig)
            except (ProcessLookupError, PermissionError):
                pass

    def wait(self, timeout: float) -> bool:
        """True once the child has exited (within ``timeout`` seconds)."""
        if self.popen is None:
            return True
        try:
            self.popen.wait(timeout)
            return True
        except subprocess.TimeoutExpired:
            return False

    def reap_group(self) -> None:
        """After the child's exit, nothing of its process group may survive it."""
        self.signal(signal.SIGKILL)
        self.flush_output()


def stop_all(children: list[Child], timeout: float, hurry: Callable[[], bool] | None = None) -> list[str]:
    """SIGTERM every running child at once, wait up to ``timeout`` s, then SIGKILL what is left.

    Returns the names of children that had to be killed. ``hurry()`` turning true (a second Ctrl-C)
    cuts the wait short.
    """
    running = [child for child in children if child.running()]
    for child in running:
        child.signal(signal.SIGTERM)
    deadline = time.monotonic() + timeout
    while any(child.running() for child in running) and time.monotonic() < deadline:
        if hurry is not None and hurry():
            log.warning("asked again to stop: killing %s now", ", ".join(c.name for c in running if c.running()))
            break
        time.sleep(0.05)
    killed = [child.name for child in running if child.running()]
    for child in children:
        if child.running():
            child.signal(signal.SIGKILL)
            child.wait(5.0)
        child.restart_at = None
        child.reap_group()
    return killed
