"""A host's link cut for 10 s mid-mission, on the multi-host layout (network namespaces, plain TCP).

planning host: ``arroch up`` with the router, the planner and the restrictor; sim host: ``arroch up
--no-router --services sim`` (the lockstep mission) connecting to the router across the LAN. Once a
few objects are delivered the sim host's link goes down for 10 s (its processes keep running, its
traffic goes nowhere): the planning host hears nothing from the sim while it is down. After the
link is healed the mission must go on and complete, every object delivered once, and no robot may
ever have been in the doorway of a closed door.

Fails (does not skip) when namespaces cannot be made; ``ARROCH_SKIP_NETNS=1`` deselects it.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.deploy.netns import Lan, require_netns

from .missions import UpMission, assert_mission_completed

pytestmark = [pytest.mark.netns, pytest.mark.integration, pytest.mark.slow]
PORT = 7447  # each namespace has its own ports
CUT = 10.0  # wall s the sim host is off the LAN
MID_DELIVERIES = 3


@pytest.fixture
def lan() -> Iterator[Lan]:
    require_netns()
    with Lan(["planning", "sim"]) as network:
        yield network


def test_the_mission_completes_after_the_sim_hosts_link_is_cut_for_10_s(lan: Lan, namespace: str, tmp_path: Path):
    router = f"tcp/{lan.hub.address}:{PORT}"
    planning = UpMission(
        lambda argv, name="": lan.spawn("planning", argv, name="planning"),
        tmp_path / "planning",
        namespace,
        services="planner,restrictor",
        extra=("--router-listen", router),
    )
    planning.wait(
        lambda: bool(planning.lines("planner is up")) and bool(planning.lines("restrictor is up")),
        "planner and restrictor up",
        timeout=60,
    )
    sim = UpMission(
        lambda argv, name="": lan.spawn("sim", argv, name="sim"),
        tmp_path / "sim",
        namespace,
        services="sim",
        extra=("--no-router", "--connect", router),
    )
    planning.wait(lambda: len(planning.delivered()) >= MID_DELIVERIES, f"{MID_DELIVERIES} deliveries", timeout=120)

    lan.cut("sim")
    cut_wall = time.time()
    seen = len(planning.events())
    time.sleep(CUT)
    silent = [e for e in planning.events()[seen:] if cut_wall + 1.0 < e["received"]]
    lan.heal("sim")
    healed = time.monotonic()
    last_before = max(float(e["stamp"]) for e in planning.events())
    # The mission moves on: an event from later in the mission than anything heard before the cut.
    planning.wait(lambda: planning.site_time() > last_before, "progress after the link came back", timeout=60)
    recovered = time.monotonic() - healed
    sim_outcome = sim.finish()
    planning_outcome = planning.finish()

    assert not silent, f"the planning host heard the sim while its link was down: {silent[:3]}"
    for outcome in (sim_outcome, planning_outcome):
        assert_mission_completed(outcome)
    assert planning_outcome.metrics == sim_outcome.metrics  # one mission, seen from both hosts
    # Nothing crashed: the link came back, the processes did not restart.
    assert (
        planning_outcome.starts("planner")
        == planning_outcome.starts("restrictor")
        == planning_outcome.starts("router")
        == 1
    )
    assert sim_outcome.starts("sim") == 1
    print(
        f"\nfault table | sim host's link cut for {CUT:.0f} s (after {MID_DELIVERIES}+ deliveries) | planning host "
        "hears "
        f"nothing while cut; progress resumes after heal; no restarts | mission completed | {recovered:.2f} s after "
        "heal"
    )
