"""Log times on the wall clock: the run's start on the wall clock plus site time.

Site time (the simulator's clock, from 0) is what every message carries in ``stamp``; a file whose log
times were site seconds would start on 1970-01-01 and line up with nothing else. Every log time (and
every timestamp inside a message) is ``origin + stamp`` instead, where ``origin`` is the wall time
(Unix nanoseconds) at which site time was 0. A lockstep run still plays at its site pace: only the
origin is the wall clock's.

The origin is fixed once, by the first message the recorder hears: its wall time of arrival minus
its ``stamp`` (a run recorded from its start: the wall time of the simulator's start, within a few
milliseconds). On the wall clock (``--clock wall``: stamps are Unix times already) it is 0. What is
written before it is known (the scene at the start, the first lines of a log) is stamped with the
wall clock itself, which is exactly "before site time 0". The file keeps the origin in its metadata
(:data:`CLOCK_METADATA`), so a reader turns log times back into site time.
"""

from __future__ import annotations

import time

CLOCK_METADATA = "arroch.clock"  # MCAP metadata record: {"site_time_origin_ns": "<int>", "site_clock": ...}
ORIGIN_KEY = "site_time_origin_ns"


def ns(seconds: float) -> int:
    return int(round(seconds * 1e9))


class Timebase:
    """Site seconds → log time (Unix nanoseconds) once the origin is known."""

    def __init__(self, origin_ns: int | None = None) -> None:
        self.origin_ns = origin_ns

    @property
    def fixed(self) -> bool:
        return self.origin_ns is not None

    def fix(self, stamp: float, wall_ns: int | None = None) -> bool:
        """Fix the origin from a message stamped ``stamp`` heard at ``wall_ns`` (default: now);
        True when this call fixed it."""
        if self.origin_ns is not None:
            return False
        self.origin_ns = (time.time_ns() if wall_ns is None else wall_ns) - ns(stamp)
        return True

    def at(self, stamp: float) -> int:
        """The log time of site time ``stamp`` (the wall clock now, while the origin is unknown)."""
        if self.origin_ns is None:
            return time.time_ns()
        return max(self.origin_ns + ns(stamp), 0)

    def site(self, log_time: int) -> float:
        """The site time of a log time."""
        return (log_time - (self.origin_ns or 0)) / 1e9

    def metadata(self, site_clock: str) -> dict[str, str]:
        return {ORIGIN_KEY: str(self.origin_ns or 0), "site_clock": site_clock}
