"""When sim time may advance: the three clock modes (DESIGN §5).

- ``realtime`` and ``rate``: sim time follows the wall clock, ``rate`` sim seconds per wall
  second (1 for realtime). :class:`WallPacer` says how many ticks are due; if the sim falls more
  than ``max_lag`` behind (a slow machine, a stall) it drops the backlog instead of sprinting to
  catch up, so time never jumps and the lag is reported.
- ``lockstep``: sim time advances only while the gate of the lockstep handshake is open
  (:class:`runtime.lockstep.LockstepGate`: the latest TeamPlan answers the current
  ``world_version`` and the ``constraints_version`` an accepted feedback produced, the commands it
  starts with have arrived, no feedback of the human awaits its ack). Time then runs as fast as the
  machine allows, or at most ``rate`` times real time (a :class:`WallPacer` caps it).

The pacer is pure (the wall time is passed in), so it is tested without a clock.
"""

from __future__ import annotations

import math

MODES = ("realtime", "rate", "lockstep")


class WallPacer:
    def __init__(self, rate: float, tick: float, *, max_lag: float = 0.5) -> None:
        if not rate > 0:
            raise ValueError("rate must be > 0")
        self.rate = rate
        self.tick = tick
        self.max_lag = max_lag  # wall seconds of backlog tolerated before it is dropped
        self._anchor_wall: float | None = None
        self._anchor_sim = 0.0
        self.dropped = 0.0  # sim seconds skipped because the sim could not keep up

    def due(self, sim_time: float, wall: float) -> int:
        """Ticks to run now to bring ``sim_time`` up to the wall clock."""
        if self._anchor_wall is None:
            self.resync(sim_time, wall)
        target = self._anchor_sim + (wall - self._anchor_wall) * self.rate  # type: ignore[operator]
        n = math.floor((target - sim_time) / self.tick + 1e-9)
        if n * self.tick > self.max_lag * self.rate:
            self.dropped += n * self.tick
            self.resync(sim_time, wall)
            return 1
        return max(n, 0)

    def resync(self, sim_time: float, wall: float) -> None:
        """Start counting from here (the first call, after a pause or a dropped backlog)."""
        self._anchor_wall = wall
        self._anchor_sim = sim_time
