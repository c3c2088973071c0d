"""Fixtures shared by every test folder: a Zenoh router on a free port, process spawning with
guaranteed clean-up, and an in-test Zenoh client built on the same Service base as the services."""

from __future__ import annotations

import queue
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import pytest

from protocol.messages import Message
from runtime.service import Service
from runtime.transport import ZenohOptions, free_tcp_port
from tests.procs import Proc, arroch

M = TypeVar("M", bound=Message)

_SKIPPED = pytest.StashKey[dict[str, int]]()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Files with a ``slow`` test first, the longest first (``slow(seconds=S)``: the wall seconds the
    file takes, where it is long enough to say), then the rest: ``make test`` hands whole files to its
    workers in this order, so the long missions start early and the workers finish together instead
    of one running a long file alone at the end."""
    seconds: dict[Path, float] = {}  # file -> its longest declared seconds
    for item in items:
        marker = item.get_closest_marker("slow")
        if marker is not None:
            seconds[item.path] = max(seconds.get(item.path, 0.0), float(marker.kwargs.get("seconds", 0.0)))
    # a stable sort keeps each file's own order of tests
    items.sort(key=lambda item: (item.path not in seconds, -seconds.get(item.path, 0.0)))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """Note why tests were skipped; :func:`pytest_unconfigure` says it as the run's very last lines."""
    reasons: dict[str, int] = {}
    for report in terminalreporter.stats.get("skipped", []):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        reason = reason.removeprefix("Skipped: ")
        reasons[reason] = reasons.get(reason, 0) + 1
    terminalreporter.config.stash[_SKIPPED] = reasons


def pytest_unconfigure(config: pytest.Config) -> None:
    """After the summary line, loudly: a passing run that skipped tests did not test everything."""
    reasons = config.stash.get(_SKIPPED, {})
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if not reasons or reporter is None:
        return
    total = sum(reasons.values())
    reporter.write_sep("!", f"SKIPPED {total} test(s): these parts were NOT tested", red=True, bold=True)
    for reason, count in sorted(reasons.items(), key=lambda item: -item[1]):
        reporter.write_line(f"  {count} x {reason}", red=True, bold=True)


@pytest.fixture
def spawn() -> Iterator[Callable[..., Proc]]:
    """``spawn(argv, env=None, name="")`` starts a process; all are stopped at teardown."""
    procs: list[Proc] = []

    def _spawn(argv: list[str], *, env: dict[str, str] | None = None, name: str = "") -> Proc:
        proc = Proc(argv, env=env, name=name)
        procs.append(proc)
        return proc

    yield _spawn
    for proc in reversed(procs):
        proc.stop()


@pytest.fixture
def router(spawn: Callable[..., Proc]) -> str:
    """A Zenoh router (``arroch router``) on a free localhost port; returns its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = spawn(arroch("router", "--listen", endpoint), name="router")
    proc.wait_for("router ready", timeout=20)
    return endpoint


@pytest.fixture
def namespace() -> str:
    """A namespace no other test uses, so tests never hear each other."""
    return f"t{uuid.uuid4().hex[:10]}"


class TestClient(Service):
    """A Service driven from the test thread: subscribe into queues, publish, query."""

    __test__ = False  # not a test class

    def __init__(self, namespace: str, endpoint: str) -> None:
        super().__init__(
            "testclient",
            namespace,
            ZenohOptions(mode="client", connect=[endpoint]),
            instance=f"test-{uuid.uuid4().hex[:6]}",
        )
        self.queues: dict[str, queue.Queue] = {}

    def collect(self, key: str, msg_type: type[M]) -> queue.Queue[tuple[M, str]]:
        """Decode messages on ``key`` straight from Zenoh's thread into a queue the test reads."""
        q: queue.Queue = queue.Queue()

        def on_sample(sample) -> None:  # noqa: ANN001
            message = self.decode_or_count(sample.payload.to_bytes(), msg_type, str(sample.key_expr))
            if message is not None:
                q.put((message, str(sample.key_expr)))

        self._declared.append(self.session.declare_subscriber(key, on_sample))
        self.queues[key] = q
        return q


def wait_for_message(q: queue.Queue, predicate: Callable[[M], bool] = lambda m: True, timeout: float = 10.0) -> M:
    """The first message from ``q`` satisfying ``predicate`` within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise AssertionError(f"no matching message within {timeout} s")
        try:
            msg, _key = q.get(timeout=remaining)
        except queue.Empty:
            raise AssertionError(f"no matching message within {timeout} s") from None
        if predicate(msg):
            return msg


@pytest.fixture
def client(router: str, namespace: str) -> Iterator[TestClient]:
    """A Zenoh client connected to ``router`` in ``namespace``, closed at teardown."""
    c = TestClient(namespace, router)
    c.open()
    yield c
    c.close()
