"""Poses on the site clock in lockstep: 20 Hz of site time while a service outside the mission's own
loop (a recorder, a viewer, the AR client, the tablet page) is up, so recordings are smooth; 1 Hz
between world versions while nobody watches (a sweep's trial), where they would only cost time."""

from __future__ import annotations

from dataclasses import dataclass

import zenoh

from protocol.messages import RobotPose
from protocol.site import load_site
from runtime.transport import ZenohOptions
from services.sim.service import SimOptions, SimService

SITE_SECONDS = 10.0


@dataclass
class Token:
    key_expr: str
    kind: zenoh.SampleKind


def poses_per_site_second(sim: SimService) -> float:
    """Poses of robot r0 published over SITE_SECONDS of ticks (no world change: idle robots)."""
    sent: list[RobotPose] = []
    sim.publish = lambda key, msg, **kw: sent.append(msg) if isinstance(msg, RobotPose) else None  # type: ignore[method-assign]
    start = sim.engine.time
    while sim.engine.time < start + SITE_SECONDS:
        sim.engine.step()
        sim._publish_tick(force_poses=False)
    return len([p for p in sent if p.robot == "r0"]) / SITE_SECONDS


def test_lockstep_poses_are_dense_while_watched_and_sparse_otherwise():
    sim = SimService(load_site(None), SimOptions(mode="lockstep"), ZenohOptions())
    sim.engine.start()
    live = "arroch/office/@liveliness/{}/{}-1"
    for service in ("planner", "restrictor", "supervisor", "sim"):  # the mission's own loop watches nothing
        sim._on_liveliness(Token(live.format(service, service), zenoh.SampleKind.PUT))
    assert poses_per_site_second(sim) <= 2.0
    sim._on_liveliness(Token(live.format("recorder", "recorder"), zenoh.SampleKind.PUT))
    assert poses_per_site_second(sim) >= 19.0
    sim._on_liveliness(Token(live.format("recorder", "recorder"), zenoh.SampleKind.DELETE))
    assert poses_per_site_second(sim) <= 2.0


def test_other_modes_send_poses_at_the_pose_rate_whoever_listens():
    sim = SimService(load_site(None), SimOptions(mode="rate", rate=10.0), ZenohOptions())
    sim.engine.start()
    assert poses_per_site_second(sim) >= 19.0
