"""Watching a running mission from the test: a Zenoh client on the mission's router that keeps every
message of a key with the wall time it arrived (fault tests time their recoveries with it)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Generic, TypeVar

import zenoh

from protocol.messages import Message
from tests.conftest import TestClient

from .missions import UpMission

M = TypeVar("M", bound=Message)


@contextmanager
def observing(mission: UpMission, timeout: float = 30.0) -> Iterator[TestClient]:
    """A client of the mission's router, in its namespace (once the router is up), closed at the end."""
    mission.wait(lambda: bool(mission.router_endpoints()), "router", timeout)
    client = TestClient(mission.namespace, mission.router_endpoints()[0])
    client.open()
    try:
        yield client
    finally:
        client.close()


class Watch(Generic[M]):
    """Every valid message on ``key`` as ``(time.monotonic() on arrival, message)``, in arrival order."""

    def __init__(self, client: TestClient, key: str, msg_type: type[M]) -> None:
        self._lock = threading.Lock()
        self._items: list[tuple[float, M]] = []

        def on_sample(sample: zenoh.Sample) -> None:
            message = client.decode_or_count(sample.payload.to_bytes(), msg_type, str(sample.key_expr))
            if message is not None:
                with self._lock:
                    self._items.append((time.monotonic(), message))

        client._declared.append(client.session.declare_subscriber(key, on_sample))

    def items(self) -> list[tuple[float, M]]:
        with self._lock:
            return list(self._items)

    def messages(self, predicate: Callable[[M], bool] = lambda m: True) -> list[M]:
        return [m for _, m in self.items() if predicate(m)]

    def latest(self) -> M | None:
        items = self.items()
        return items[-1][1] if items else None

    def first(self, predicate: Callable[[M], bool], what: str, timeout: float = 30.0) -> tuple[float, M]:
        """The first message (and its arrival time) satisfying ``predicate``, waiting up to ``timeout``."""
        deadline = time.monotonic() + timeout
        while True:
            for item in self.items():
                if predicate(item[1]):
                    return item
            if time.monotonic() > deadline:
                raise AssertionError(f"no {what} within {timeout:.0f} s")
            time.sleep(0.02)
