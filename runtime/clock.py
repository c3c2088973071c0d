"""The site clock (DESIGN §5): wall time, or the simulator's ``clock`` messages.

Every service reads time through a :class:`Clock`, so the same code runs against real robots
(wall clock, Unix seconds) and against the simulator (sim seconds from 0, possibly faster than
real time, or advancing only in lockstep).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

from protocol.messages import Clock as ClockMessage

EXTRAPOLATED_MODES = ("realtime", "rate", "wall")  # modes in which time runs between messages
MAX_EXTRAPOLATION = 1.0  # seconds: a stalled sim stops time rather than letting it run away


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

    Between messages, time is extrapolated at the announced rate in ``realtime``/``rate``/``wall``
    modes (poses arrive at 20 Hz, clock messages maybe less often), never more than a second past
    the last message; in ``lockstep`` (or while paused) it is not, because sim time there only
    moves when the sim says so.

    A message from the same sender with a lower ``seq`` than the last one is an old message
    overtaken by a newer one, and is ignored. A message from another sender (a restarted sim has a
    new ``src``) is taken as it is, even if its time is earlier: the clock follows the new source.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._time = 0.0
        self._received = 0.0  # time.monotonic() when the last message arrived
        self._rate = 1.0
        self._extrapolate = False
        self._synced = False
        self._src = ""
        self._seq = 0
        self.world_version = 0
        self.mode = "realtime"

    def update(self, msg: ClockMessage) -> None:
        with self._lock:
            same_source = self._synced and msg.src == self._src
            if same_source:
                if msg.src and msg.seq and msg.seq <= self._seq:
                    return  # an old (or repeated) message overtaken by a newer one
                if not msg.src and msg.time < self._time and self.mode == msg.mode:
                    return  # unstamped messages: only time tells their order
            self._time = msg.time
            self._received = time.monotonic()
            self._rate = msg.rate
            self._extrapolate = msg.mode in EXTRAPOLATED_MODES and not msg.paused
            self._synced = True
            self._src, self._seq = msg.src, msg.seq
            self.mode = msg.mode
            # A new source starts its own count; the same source's count never goes back.
            self.world_version = max(self.world_version, msg.world_version) if same_source else msg.world_version

    @property
    def synced(self) -> bool:
        return self._synced

    def now(self) -> float:
        with self._lock:
            if not self._extrapolate:
                return self._time
            elapsed = min(time.monotonic() - self._received, MAX_EXTRAPOLATION)
            return self._time + elapsed * self._rate


def make_clock(kind: str) -> WallClock | SimClock:
    if kind == "wall":
        return WallClock()
    if kind == "sim":
        return SimClock()
    raise ValueError(f"clock {kind!r} is not 'wall' or 'sim'")
