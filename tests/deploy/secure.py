"""The secure profile for tests: certificates and per-role configs made with the project's own tools.

Identities: every role of the access-control table, plus ``intruder`` (a valid certificate from our
authority whose name is no role) and ``foreign/planner`` (a "planner" certificate from another
authority). Configs: ``<role>.json5`` as ``arroch deploy render`` writes them, plus two made by
taking a rendered one apart: ``nocert.json5`` (trusts the router but presents no certificate) and
``foreign.json5`` (presents the foreign planner certificate).
"""

from __future__ import annotations

import contextlib
import re
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

from runtime.certs import make_certs, parse_hosts
from runtime.clock import WallClock
from runtime.service import Service
from runtime.transport import ZenohOptions
from services.supervisor.deployment import acl
from services.supervisor.deployment.render import Request, render
from tests.conftest import TestClient

ROLES = [*acl.ROLES, *acl.INFRASTRUCTURE]
INTRUDER = "intruder"


def make_pki(directory: Path, sans: list[str] | None = None) -> tuple[Path, Path]:
    """(our certificate directory, a foreign authority's directory)."""
    ours, foreign = directory / "certs", directory / "foreign"
    make_certs(ours, parse_hosts([*ROLES, INTRUDER], sans or []))
    make_certs(foreign, parse_hosts(["planner"], []))
    return ours, foreign


def render_configs(certs: Path, foreign: Path, out: Path, *, router: str, listen: str) -> Path:
    """Write ``<role>.json5`` for every role, ``intruder``, ``nocert`` and ``foreign`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    for role in ROLES:
        request = Request(
            "secure",
            role,
            certs=certs,
            connect=[] if role == "router" else [router],
            listen=[listen] if role == "router" else [],
        )
        (out / f"{role}.json5").write_text(render(request))
    # An identity the router's rules do not know: rendered as an AR client presenting its own certificate.
    (out / f"{INTRUDER}.json5").write_text(
        render(Request("secure", "ar", certs=certs, name=INTRUDER, connect=[router]))
    )
    planner = (out / "planner.json5").read_text()
    nocert = re.sub(r"^\s*connect_(certificate|private_key):.*\n", "", planner, flags=re.M)
    (out / "nocert.json5").write_text(nocert.replace("enable_mtls: true", "enable_mtls: false"))
    (out / "foreign.json5").write_text(
        planner.replace(str(certs.resolve() / "planner."), str(foreign.resolve() / "planner."))
    )
    return out


class RoleClient(TestClient):
    """A test client that joins with one of the rendered configs (so with that role's identity)."""

    def __init__(self, namespace: str, config_file: Path, label: str) -> None:
        # TestClient's own constructor dials a plain endpoint; this one takes a whole config file.
        # Wall clock: these tests put raw payloads on every key, the clock key included.
        Service.__init__(
            self,
            "testclient",
            namespace,
            ZenohOptions(config_file=str(config_file)),
            instance=f"test-{label}-{uuid.uuid4().hex[:6]}",
            clock=WallClock(),
        )
        self.queues = {}


@contextlib.contextmanager
def role_clients(namespace: str, configs: Path) -> Iterator[Callable[[str], RoleClient]]:
    """``join("planner")`` opens a client with ``configs/planner.json5``'s identity; all are closed
    on leaving (the ``join`` fixtures of the deploy and reliability tests)."""
    clients: list[RoleClient] = []

    def join(identity: str) -> RoleClient:
        client = RoleClient(namespace, configs / f"{identity}.json5", identity)
        client.open()
        clients.append(client)
        return client

    try:
        yield join
    finally:
        for client in reversed(clients):
            client.close()
