"""The default mission across three "hosts" (network namespaces on a private LAN), secure profile.

planning host: ``arroch up`` — the router (TLS, mutual authentication, access control), planner,
restrictor; AR host: ``arroch up --no-router --services ar`` (the AR client); sim host: ``arroch up
--no-router --services sim --camera tablet --until-done`` (robots, doors, the simulated human, the
tablet camera). Each service holds its role's certificate; every message crosses the LAN through
the router. The mission must complete (9/9 delivered) and the AR host must draw the sim host's
camera frames. Meanwhile a peer on the sim host tries to command a robot without the right to:
with no certificate, with another authority's, with a valid certificate that names no role, and as
the AR role; a planner identity sends the same kind of command as the control. The sim counts every
command it receives: it must have counted the control's, and none of the others.

Fails (does not skip) when namespaces cannot be made; ``ARROCH_SKIP_NETNS=1`` deselects it.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.deploy.netns import Lan
from tests.deploy.secure import make_pki, render_configs
from tests.deploy.test_multihost import PORT, established
from tests.procs import Proc, arroch

pytestmark = [pytest.mark.netns, pytest.mark.slow]
MISSION_TIMEOUT = 150.0  # wall s for the whole mission; about 30 s on two cores not busy with other work
UNAUTHORISED = ("nocert", "foreign", "intruder", "ar")


def up(lan: Lan, host: str, configs: Path, runs: Path, namespace: str, *args: str) -> Proc:
    return lan.spawn(
        host,
        arroch(
            "up",
            "--namespace",
            namespace,
            "--progress",
            "off",
            "--zenoh-config-dir",
            str(configs),
            "--run-dir",
            str(runs / host),
            *args,
        ),
        name=host,
    )


def the_run(runs: Path) -> Path:
    (run,) = [p for p in runs.iterdir() if p.is_dir()]
    return run


def test_the_mission_completes_across_hosts_and_unauthorised_commands_never_reach_the_sim(
    lan: Lan, namespace: str, tmp_path: Path
):
    hub = lan.hub.address
    certs, foreign = make_pki(tmp_path, sans=[f"router={hub}"])
    configs = render_configs(certs, foreign, tmp_path / "zenoh", router=f"tls/{hub}:{PORT}", listen=f"tls/{hub}:{PORT}")
    runs = tmp_path / "runs"

    planning = up(lan, "planning", configs, runs, namespace, "--services", "planner,restrictor")
    planning.wait_for("restrictor is up (", timeout=40)
    planning.wait_for("planner is up (", timeout=40)
    ar = up(lan, "ar", configs, runs, namespace, "--no-router", "--services", "ar")
    planning.wait_for("ar is up (", timeout=40)
    # The peer joins first (its start-up is slow), then acts as soon as the sim answers.
    peer = lan.spawn(
        "sim",
        [
            sys.executable,
            "-m",
            "tests.deploy.peer",
            "--configs",
            str(configs),
            "--namespace",
            namespace,
            "--try",
            ",".join(UNAUTHORISED),
            "--control",
            "planner",
        ],
        name="peer",
    )
    sim = up(
        lan,
        "sim",
        configs,
        runs,
        namespace,
        "--no-router",
        "--services",
        "sim",
        "--camera",
        "tablet",
        "--mode",
        "lockstep",
        "--seed",
        "1",
        "--until-done",
        "--timeout",
        str(MISSION_TIMEOUT),
        "--no-record",  # what crosses the LAN is checked, not a recording
    )
    planning.wait_for("sim is up (", timeout=40)
    for host in ("sim", "ar"):  # real LAN links to the router's address, not loopback
        assert f"{hub}:{PORT}" in established(lan, host), established(lan, host)

    report = json.loads(peer.wait_for('"sim_stats"', timeout=60))
    try:
        code = sim.wait(MISSION_TIMEOUT + 10)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"the mission did not end:\n{sim.output[-3000:]}") from None
    assert code == 0, sim.output[-3000:]

    # The mission, across the hosts.
    metrics = json.loads((the_run(runs / "sim") / "metrics.json").read_text())
    assert metrics["completed"] is True
    assert sorted(o for r in metrics["robots"].values() for o in r["delivered"]) == [f"o{i}" for i in range(9)]
    planning.wait_for("mission done at t=", timeout=10)  # the planning host's supervisor heard it too
    overlays = list((the_run(runs / "ar") / "overlays").glob("*.png"))
    assert overlays, "the AR host drew none of the sim host's camera frames"

    # Nobody without the right got a command through; the control did.
    attempts = report["attempts"]
    assert attempts["nocert"].startswith("cannot connect") and attempts["foreign"].startswith("cannot connect"), (
        attempts
    )
    assert attempts["intruder"].startswith("published") and attempts["ar"] == "published", attempts
    assert report["control"] == "published"
    assert report["sim_stats"].get("commands_refused") == report["repeats"], report[
        "sim_stats"
    ]  # the control's, no more
    assert "command for robot 'control' arrived on 'r0''s key" in sim.output
    for name in ("intruder", "ar"):
        assert f"command for robot '{name}'" not in sim.output

    for proc in (ar, planning):
        proc.signal(signal.SIGINT)
        assert proc.wait(20) == 0, proc.output[-3000:]
