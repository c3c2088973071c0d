"""Fixtures of the deployment tests: a certificate set, per-role configs, a secure router."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from runtime.transport import free_tcp_port
from tests.deploy.netns import Lan, require_netns
from tests.deploy.secure import RoleClient, make_pki, render_configs, role_clients
from tests.procs import Proc, arroch


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "netns: builds Linux network namespaces (root, iproute2); ARROCH_SKIP_NETNS=1 or -m 'not netns' deselects",
    )


@pytest.fixture
def lan() -> Iterator[Lan]:
    """Three network namespaces (planning, sim, ar) on one bridge; fails when they cannot be made."""
    require_netns()
    with Lan(["planning", "sim", "ar"]) as network:
        yield network


@pytest.fixture(scope="session")
def pki(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(our certificates, a foreign authority's), made once per test session."""
    return make_pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def router_port() -> int:
    return free_tcp_port()


@pytest.fixture(scope="module")
def secure_configs(pki: tuple[Path, Path], router_port: int, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rendered configs for a TLS router on a free localhost port (``router.json5``, ``<role>.json5``, ...)."""
    certs, foreign = pki
    endpoint = f"tls/127.0.0.1:{router_port}"
    return render_configs(certs, foreign, tmp_path_factory.mktemp("zenoh"), router=endpoint, listen=endpoint)


@pytest.fixture(scope="module")
def secure_router(secure_configs: Path) -> Iterator[Proc]:
    """``arroch router`` with the rendered secure config (TLS, mTLS, access control)."""
    proc = Proc(arroch("router", "--zenoh-config", str(secure_configs / "router.json5")), name="secure-router")
    try:
        proc.wait_for("router ready", timeout=20)
        yield proc
    finally:
        proc.stop()


@pytest.fixture
def join(secure_router: Proc, secure_configs: Path, namespace: str) -> Iterator[Callable[[str], RoleClient]]:
    """``join("planner")`` opens a client with that config's identity; all are closed at teardown."""
    with role_clients(namespace, secure_configs) as join:
        yield join
