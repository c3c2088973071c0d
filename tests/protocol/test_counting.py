"""A Service's counts stay exact when many threads count at once: the lock-free tallies behind
``received`` and ``published``, the locked counters beside them, and the per-sender ``seq``.
(No Zenoh needed: a Service counts and stamps before it is opened.)"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from protocol.messages import RobotPose
from runtime.service import Service, _Tally
from runtime.transport import ZenohOptions

THREADS, EACH = 4, 20_000


def in_threads(work: Callable[[int], None]) -> None:
    """Run ``work(k)`` on THREADS threads at once: started together, and made to hand the GIL over
    every few instructions so that their steps interleave."""
    start = threading.Barrier(THREADS)

    def run(k: int) -> None:
        start.wait()
        work(k)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(THREADS)]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)


def test_a_tally_loses_no_count_and_takes_each_once():
    tally = _Tally()
    taken: list[int] = []
    take_lock = threading.Lock()  # takes never run concurrently (the Service holds its lock)

    def work(k: int) -> None:
        for i in range(EACH):
            tally.add()
            if k == 0 and i % 1000 == 0:
                with take_lock:
                    taken.append(tally.take())

    in_threads(work)
    taken.append(tally.take())
    assert sum(taken) == THREADS * EACH
    assert tally.take() == 0  # nothing added since


def test_counters_fold_tallies_and_locked_counts_together():
    service = Service("counting", "ns", ZenohOptions())
    snapshots: list[dict[str, int]] = []

    def work(k: int) -> None:
        for i in range(EACH):
            service.count("received")  # a tally
            service.count("bad_messages")  # the locked Counter
            if i % 2000 == 0:
                snapshots.append(service.counters_snapshot())

    in_threads(work)
    assert service.counters["received"] == service.counters["bad_messages"] == THREADS * EACH
    assert service.counters_snapshot()["received"] == THREADS * EACH
    # Every snapshot saw a consistent, growing count (never more than was counted).
    assert all(0 < s["received"] <= THREADS * EACH for s in snapshots)
    service.count("received", 5)  # more than one at a time goes through the lock
    service.counters["published"] += 2  # the worker may still add to the Counter directly
    assert (service.counters["received"], service.counters["published"]) == (THREADS * EACH + 5, 2)


def test_stamps_number_each_message_once_across_threads():
    service = Service("stamping", "ns", ZenohOptions())
    seqs: list[list[int]] = [[] for _ in range(THREADS)]
    in_threads(
        lambda k: seqs[k].extend(service.stamp(RobotPose(robot="r0", x=0.0, y=0.0, theta=0.0)).seq for _ in range(EACH))
    )
    together = sorted(s for part in seqs for s in part)
    assert together == list(range(1, THREADS * EACH + 1))
    assert all(part == sorted(part) for part in seqs)  # each thread sees its own in order
