"""When to replan: one replan for a burst of triggers (debouncing), without Zenoh or a clock.

Triggers arriving together (a clock tick, a status and an event for one action) are answered by one
replan: the burst is over once SETTLE has passed without news, and at the latest MAX_DELAY after its
first trigger; at once when it holds urgent news (new constraints: the human waits for the answer).
In lockstep, news a simulator does not wait for (a robot acknowledging its command) is held for the
next world version; that version's trigger then starts a new burst.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .triggers import Trigger

SETTLE = 0.03  # s without a new trigger before replanning (one replan for a burst)
MAX_DELAY = 0.25  # s: replan at the latest this long after the first trigger


@dataclass
class ReplanScheduler:
    settle: float = SETTLE
    max_delay: float = MAX_DELAY
    pending: set[Trigger] = field(default_factory=set)
    first_at: float = 0.0  # monotonic time of the burst's first trigger
    last_at: float = 0.0  # and of its latest
    held: bool = False  # the pending news waits for the next world version (lockstep)

    def add(self, trigger: Trigger, now: float) -> None:
        if not self.pending or (self.held and trigger.answered_in_lockstep):
            self.first_at = now  # a burst starts (held news joins the one a new version starts)
            self.held = False
        self.last_at = now
        self.pending.add(trigger)

    def __bool__(self) -> bool:
        return bool(self.pending)

    def settled(self, now: float) -> bool:
        """Whether the burst is over: quiet for ``settle``, or ``max_delay`` after its start, or urgent."""
        return (
            now - self.last_at >= self.settle
            or now - self.first_at >= self.max_delay
            or any(t.urgent for t in self.pending)
        )

    def answers_nothing_awaited(self) -> bool:
        """Whether none of the pending news is something a lockstep simulator waits for a plan about.

        Such a plan - made on a robot acknowledging its command, or starting to wait at a door -
        would reach the simulator at a moment that depends on the machine's load, and the same seed
        would not give the same mission; the news is kept for the next world version."""
        return not any(t.answered_in_lockstep for t in self.pending)

    def hold(self) -> None:
        self.held = True

    def take(self) -> list[Trigger]:
        """The pending triggers, in a stable order, and a fresh start."""
        out = sorted(self.pending, key=str)
        self.pending.clear()
        return out
