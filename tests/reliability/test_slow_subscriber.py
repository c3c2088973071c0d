"""A subscriber that stops reading for 8 s (a recorder starved of CPU, say) loses nothing: the router's
blocked send to it waits, and does not close its session after Zenoh's default 5 s.
A sender that drains before it closes loses nothing either (runtime.service.Service.drain).

With Zenoh's default the router closed the stalled session and 2,605 of 3,000 messages sent meanwhile
were lost (measured with this test's set-up and ``wait_before_close`` at 5 s)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest
import zenoh

from runtime.service import Service, publisher_options
from runtime.transport import ZenohOptions, open_session

pytestmark = [pytest.mark.integration]

MESSAGES, PAYLOAD = 3000, b"x" * 4000  # 12 MB: far more than the router's queue to the subscriber holds
STALL = 8.0  # wall s the subscriber's first callback keeps Zenoh's thread: longer than Zenoh's 5 s default


def send_burst(put: Callable[[bytes], None]) -> float:
    """Once the subscription has reached the router, put MESSAGES payloads as fast as ``put`` lets
    them go; returns the seconds that took (how long the sends were held back)."""
    time.sleep(1.0)
    started = time.monotonic()
    for _ in range(MESSAGES):
        put(PAYLOAD)
    return time.monotonic() - started


def wait_for_all(received: Callable[[], int], seconds: float) -> None:
    """Until ``received()`` counts MESSAGES, or ``seconds`` have passed."""
    deadline = time.monotonic() + seconds
    while received() < MESSAGES and time.monotonic() < deadline:
        time.sleep(0.2)


def test_a_subscriber_that_stalls_8_s_gets_every_message_a_blocking_publisher_sent(router: str):
    subscriber = open_session(ZenohOptions(mode="client", connect=[router]))
    publisher = open_session(ZenohOptions(mode="client", connect=[router]))
    received, stalled = 0, threading.Event()

    def on_sample(_sample: zenoh.Sample) -> None:
        nonlocal received
        if not stalled.is_set():
            stalled.set()
            time.sleep(STALL)
        received += 1

    try:
        subscriber.declare_subscriber("slow/sub", on_sample)
        put = publisher.declare_publisher("slow/sub", **publisher_options()).put
        blocked = send_burst(put)
        wait_for_all(lambda: received, 60)
    finally:
        subscriber.close()
        publisher.close()
    assert stalled.is_set() and blocked > STALL / 2  # the publisher was held back by the stalled reader
    assert received == MESSAGES


def test_a_service_that_drains_before_it_closes_loses_nothing_to_a_slow_reader(router: str):
    """Zenoh's close drops what its send queues hold; a slow reader keeps them full. Service.drain waits
    until its barrier query has come back through the router, so closing right after loses nothing.
    (Closed without it, 270, 526 and 513 of the 3,000 were lost in three runs.)"""
    subscriber = open_session(ZenohOptions(mode="client", connect=[router]))
    received = 0

    def on_sample(_sample: zenoh.Sample) -> None:
        nonlocal received
        received += 1
        time.sleep(0.001)  # a reader that keeps up with 1,000 messages a second, not with a burst

    sender = Service("drainer", "slow", ZenohOptions(mode="client", connect=[router]))
    try:
        subscriber.declare_subscriber("slow/drain", on_sample)
        sender.open()
        send_burst(sender.advertise("slow/drain").put)
        behind = MESSAGES - received  # what was still on its way when the last put returned
        drained = sender.drain(30.0)
        sender.close()
        wait_for_all(lambda: received, 30)
    finally:
        subscriber.close()
        sender.close()
    assert behind > 100 and drained  # a burst the reader could not keep up with, and drain() saw it out
    assert received == MESSAGES
