"""Stop signals noted without taking a lock.

A Python signal handler runs on the main thread between two bytecodes, possibly while that thread
holds a lock, and a second signal can land while the first handler is still running. A handler that
calls ``threading.Event.set()`` (or logs) then waits for a lock its own thread holds: the process
hangs for ever instead of stopping. That is not hypothetical: a child tied to its parent with
``PR_SET_PDEATHSIG`` gets one signal per parent *thread* that exits, so killing a sweep with many
threads sends each of its routers a burst of SIGTERMs.

So handlers here only assign attributes; the main loop polls :attr:`StopSignals.first` and does the
logging and the waking of other threads itself.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Iterable
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """Which stop signal came first, and how many came, set by handlers that touch no lock."""

    def __init__(self) -> None:
        self.first: int | None = None
        self.count = 0  # a nested handler may lose an increment: only "one or more than one" matters

    def handle(self, signum: int, _frame: Any = None) -> None:
        self.count += 1
        if self.first is None:
            self.first = signum

    def install(self, signals: Iterable[int] = STOP_SIGNALS) -> dict[int, Any]:
        """Handle ``signals`` here (main thread only); returns the handlers they had, for :func:`restore`."""
        return {int(sig): signal.signal(sig, self.handle) for sig in signals}

    @property
    def received(self) -> bool:
        return self.first is not None

    @property
    def name(self) -> str:
        """The first signal's name (``SIGTERM``), or an empty string."""
        return signal.Signals(self.first).name if self.first is not None else ""

    def wait(self, poll: float = 0.1) -> int:
        """Sleep until a stop signal arrives and return it, at most ``poll`` s after it arrived (a
        sleep resumes after the handler ran, PEP 475)."""
        while self.first is None:
            time.sleep(poll)
        return self.first


def restore(previous: dict[int, Any]) -> None:
    """Put back the handlers :meth:`StopSignals.install` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)
