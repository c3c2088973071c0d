"""Fixtures of the protocol tests: one router per test module (each test still gets its own
namespace, so tests never hear each other), and in-process services run on a worker thread."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from runtime.service import Service
from runtime.transport import ZenohOptions, free_tcp_port
from tests.conftest import TestClient
from tests.procs import Proc, arroch


@pytest.fixture(scope="module")
def module_router() -> Iterator[str]:
    """An `arroch router` on a free port shared by one test module; returns its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = Proc(arroch("router", "--listen", endpoint), name="router")
    try:
        proc.wait_for("router ready", timeout=20)
        yield endpoint
    finally:
        proc.stop()


@pytest.fixture
def peer(module_router: str, namespace: str) -> Iterator[TestClient]:
    """A test client on the module's router, in this test's namespace."""
    c = TestClient(namespace, module_router).open()
    yield c
    c.close()


class Running:
    """A service whose run() loop is on a background thread (signals stay with pytest)."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.thread: threading.Thread | None = None

    def start(self) -> Running:
        self.thread = threading.Thread(target=self.service.run, name=f"run-{self.service.name}", daemon=True)
        self.thread.start()
        return self

    def stop(self) -> None:
        self.service.stop()
        if self.thread is not None:
            self.thread.join(5)
            assert not self.thread.is_alive(), "service loop did not stop"
        self.service.close()


@pytest.fixture
def make_service(module_router: str, namespace: str) -> Iterator[Callable[..., Running]]:
    """``make_service(cls, *args, **kwargs)`` opens a Service (class ``cls``) on the module's router in
    this test's namespace; every one is stopped and closed at teardown. Call ``.start()`` to run it."""
    made: list[Running] = []

    def _make(cls: type[Service], *args, **kwargs) -> Running:
        service = cls(
            *args, namespace=namespace, zenoh_options=ZenohOptions(mode="client", connect=[module_router]), **kwargs
        )
        service.open()
        made.append(Running(service))
        return made[-1]

    yield _make
    for running in made:
        running.stop()


def eventually(check: Callable[[], bool], timeout: float = 10.0, what: str = "condition") -> None:
    """Wait until ``check()`` is true (Zenoh delivery is asynchronous)."""
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not reached within {timeout} s")
        time.sleep(0.01)
