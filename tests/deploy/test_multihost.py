"""Three "hosts" (network namespaces on a private LAN), the secure profile, messages across them.

planning host: the router (TLS, mTLS, access control) and the supervisor, via ``arroch up``;
AR host: ``arroch up --no-router`` running a service (the ping echo server, as the ``ar`` identity);
sim host: ``arroch ping send`` with the ``sim`` identity. A pose from the sim host reaches the AR host
through the router and its echo comes back: two LAN crossings each way, over TLS.

Fails (does not skip) when namespaces cannot be made; ``ARROCH_SKIP_NETNS=1`` deselects it.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

from tests.deploy.netns import Lan
from tests.deploy.secure import make_pki, render_configs
from tests.procs import arroch

pytestmark = pytest.mark.netns
PORT = 7447  # each namespace has its own ports: the standard one is free in the hub


def established(lan: Lan, host: str) -> str:
    """The host's established TCP connections, as ``ss`` shows them inside it."""
    return subprocess.run(
        lan[host].argv(["ss", "-Htn", "state", "established"]), capture_output=True, text=True, check=True
    ).stdout


def test_messages_cross_hosts_through_the_tls_router_and_an_intruder_gets_nothing(
    lan: Lan, namespace: str, tmp_path: Path
):
    hub = lan.hub.address
    certs, foreign = make_pki(tmp_path, sans=[f"router={hub}"])
    configs = render_configs(certs, foreign, tmp_path / "zenoh", router=f"tls/{hub}:{PORT}", listen=f"tls/{hub}:{PORT}")
    # The ping echo server runs under `arroch up`, which names its config after the service.
    shutil.copy(configs / "ar.json5", configs / "ping.json5")

    planning = lan.spawn(
        "planning",
        arroch(
            "up",
            "--services",
            "",
            "--namespace",
            namespace,
            "--progress",
            "off",
            "--zenoh-config-dir",
            str(configs),
            "--run-dir",
            str(tmp_path / "runs-planning"),
        ),
    )
    planning.wait_for("supervising", timeout=30)
    ar = lan.spawn(
        "ar",
        arroch(
            "up",
            "--no-router",
            "--services",
            "ping",
            "--namespace",
            namespace,
            "--progress",
            "off",
            "--zenoh-config-dir",
            str(configs),
            "--run-dir",
            str(tmp_path / "runs-ar"),
        ),
    )
    ar.wait_for("[ping] ping serve ready", timeout=30)

    sender = lan.spawn(
        "sim",
        arroch(
            "ping",
            "send",
            "--zenoh-config",
            str(configs / "sim.json5"),
            "--namespace",
            namespace,
            "--count",
            "200",
            "--rate",
            "100",
            "--json",
        ),
        name="sim-ping",
    )
    summary = json.loads(sender.wait_for('"sent"', timeout=60))
    assert summary["received"] == summary["sent"] == 200, summary
    print(
        f"\ncross-host round trip over TLS (sim host -> router -> AR host and back): "
        f"p50 {summary['p50_us']:.0f} us, p90 {summary['p90_us']:.0f} us, p99 {summary['p99_us']:.0f} us"
    )
    # The links really are LAN links to the router's address, not loopback.
    for host in ("ar",):
        assert f"{hub}:{PORT}" in established(lan, host), established(lan, host)

    # A valid certificate that names no role: it joins, but its poses go nowhere and nothing answers.
    intruder = lan.spawn(
        "sim",
        arroch(
            "ping",
            "send",
            "--zenoh-config",
            str(configs / "intruder.json5"),
            "--namespace",
            namespace,
            "--count",
            "5",
            "--wait",
            "3",
        ),
        name="intruder",
    )
    intruder.wait_for("no ping server answered", timeout=30)
    assert intruder.wait(10) == 1

    for proc in (ar, planning):
        proc.signal(signal.SIGINT)
        assert proc.wait(20) == 0, proc.output
