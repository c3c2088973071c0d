"""The site clock (DESIGN §5): wall time, or the simulator's ``clock`` messages.

Every service reads time through a :class:`Clock`, so the same code runs against real robots
(wall clock, Unix seconds) and against the simulator (sim seconds from 0, possibly faster than
real time, or advancing only in lockstep).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

from .messages import Clock as ClockMessage


class Clock(Protocol):
    def now(self) -> float:
        """Seconds on the site clock."""
        ...

    @property
    def synced(self) -> bool:
        """True once the clock knows the time (always for wall time)."""
        ...


class WallClock:
    """Unix time."""

    synced = True

    def now(self) -> float:
        return time.time()


class SimClock:
    """Time from the simulator's ``clock`` messages.

    Between messages, time is extrapolated at the announced rate in ``realtime``/``rate`` modes
    (poses arrive at 20 Hz, clock messages maybe less often); in ``lockstep`` it is not, because
    sim time there only moves when the sim says so.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._time = 0.0
        self._received = 0.0  # time.monotonic() when the last message arrived
        self._rate = 1.0
        self._extrapolate = False
        self._synced = False
        self.world_version = 0
        self.mode = "realtime"

    def update(self, msg: ClockMessage) -> None:
        with self._lock:
            if self._synced and msg.time < self._time and self.mode == msg.mode:
                return  # an old message overtaken by a newer one
            self._time = msg.time
            self._received = time.monotonic()
            self._rate = msg.rate
            self._extrapolate = msg.mode in ("realtime", "rate") and not msg.paused
            self._synced = True
            self.mode = msg.mode
            self.world_version = max(self.world_version, msg.world_version)

    @property
    def synced(self) -> bool:
        return self._synced

    def now(self) -> float:
        with self._lock:
            if not self._extrapolate:
                return self._time
            # Never extrapolate more than a second past the last message: a stalled sim stops time.
            elapsed = min(time.monotonic() - self._received, 1.0)
            return self._time + elapsed * self._rate


def make_clock(kind: str) -> WallClock | SimClock:
    if kind == "wall":
        return WallClock()
    if kind == "sim":
        return SimClock()
    raise ValueError(f"clock {kind!r} is not 'wall' or 'sim'")
