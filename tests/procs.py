"""Real processes for integration tests: start, wait for a line, stop, and never leave one behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


class Proc:
    """A child process whose output is collected on a thread (so its pipe never fills up)."""

    def __init__(self, argv: Sequence[str], *, env: dict[str, str] | None = None, name: str = "") -> None:
        self.argv = list(argv)
        self.name = name or Path(self.argv[0]).name
        full_env = dict(os.environ)
        full_env.setdefault("ARROCH_LOG_LEVEL", "INFO")
        full_env["PYTHONUNBUFFERED"] = "1"
        if env:
            full_env.update(env)
        self.popen = subprocess.Popen(
            self.argv,
            cwd=ROOT,
            env=full_env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,  # its own process group, so stop() reaches grandchildren
        )
        self.lines: deque[str] = deque(maxlen=5000)
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()

    @property
    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def wait_for(self, text: str, timeout: float = 20.0) -> str:
        """Block until a line containing ``text`` appears; return it. Fails if the process dies first."""
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                lines = list(self.lines)
                for line in lines[seen:]:
                    if text in line:
                        return line
                seen = len(lines)
                if self.popen.poll() is not None and not self._reader.is_alive():
                    raise AssertionError(
                        f"{self.name} exited ({self.popen.returncode}) before printing {text!r}:\n{self.output}"
                    )
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(f"{self.name} did not print {text!r} within {timeout} s:\n{self.output}")
                self._cond.wait(min(remaining, 0.2))

    def alive(self) -> bool:
        return self.popen.poll() is None

    def wait(self, timeout: float | None = None) -> int:
        """Wait for the exit (``subprocess.TimeoutExpired`` after ``timeout``) and for the reader to
        drain the pipe, so :attr:`output` holds the last lines; returns the exit code."""
        code = self.popen.wait(timeout)
        self._reader.join(5)  # EOF follows the exit unless a grandchild still holds the pipe
        return code

    def signal(self, sig: int) -> None:
        if self.alive():
            os.killpg(self.popen.pid, sig)

    def stop(self, timeout: float = 5.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout``; returns the exit code."""
        if self.alive():
            self.signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.signal(signal.SIGKILL)
                self.popen.wait(5)
        # A grandchild may still hold the group: make sure nothing of it survives.
        try:
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self._reader.join(2)
        return self.popen.returncode


def arroch(*args: str) -> list[str]:
    """argv running the ``arroch`` CLI with this interpreter (no reliance on PATH)."""
    return [sys.executable, "-m", "services.cli", *args]


def restrictor_argv(namespace: str, router: str, state_dir: Path, *extra: str) -> list[str]:
    """argv of a restrictor on ``namespace`` through ``router``, on the wall clock, its store in ``state_dir``."""
    connection = ("--namespace", namespace, "--connect", router)
    return arroch("restrictor", *connection, "--clock", "wall", "--state-dir", str(state_dir), *extra)
