"""Services killed mid-mission (SIGKILL, as a crash): the planner, the restrictor, the AR client and
the Zenoh router, each in its own lockstep mission of the default office site under ``arroch up``.

Each time the supervisor must report the crash and restart the process, the mission must still
complete (every object delivered once) with no robot ever in the doorway of a closed door (the
simulator's ``closed_door_crossings``), and the restarted process must have rebuilt its state:

- planner: its first plan starts from the live world (nothing delivered planned again, nothing
  carried loaded again, action ids going on) and respects the active constraints it fetched;
- restrictor: the ConstraintSet it publishes first is the one it had (same version, same
  constraints, from its SQLite state), and later constraints get new ids;
- AR client: overlays come again, localised, with the robots and the door states;
- router: restarted on the same endpoint, every service reconnects (no service restarts).

And feedback sent while the restrictor is down is retried until acknowledged, and applied once.
Each test prints one ``fault table`` line (what was checked, the outcome, the time to recover).
"""

from __future__ import annotations

import logging
import re
import time
from pathlib import Path

import pytest

from protocol.messages import ConstraintSet, Overlay, TeamPlan
from runtime.feedback_client import send_feedback

from .missions import SITE, UpMission, assert_mission_completed
from .watch import Watch, observing

pytestmark = [pytest.mark.integration, pytest.mark.slow]

MID_DELIVERIES = 3  # of 9: a kill after this many is mid-mission (the mission is ~690 s of site time)
MARGIN = 30.0  # site s a constraint must still have to run when a kill is decided (the sim may run on meanwhile)
SERVICE_IDS = re.compile(r"\b(planner|restrictor|sim|ar)-(\d+)\b")


def table_line(fault: str, checked: str, recovered_in: float) -> None:
    print(f"\nfault table | {fault} | {checked} | mission completed | {recovered_in:.2f} s")


def active(cs: ConstraintSet | None, now: float, margin: float = 0.0) -> list:
    """The constraints of ``cs`` in force at site time ``now`` (and still ``margin`` s after it)."""
    return [c for c in cs.constraints if c.start <= now and now + margin < c.end] if cs is not None else []


def world_version(events: list[dict]) -> int:
    return max((int(e["data"].get("world_version", 0)) for e in events if isinstance(e.get("data"), dict)), default=0)


def test_planner_killed_mid_mission_replans_from_the_live_world_and_the_active_constraints(
    spawn, tmp_path: Path, namespace: str
):
    mission = UpMission(spawn, tmp_path, namespace)
    with observing(mission) as client:
        plans = Watch(client, client.keys.plan(), TeamPlan)
        sets = Watch(client, client.keys.constraints(), ConstraintSet)
        # Mid-mission, while one of the human's constraints is active: the new planner must find it.
        mission.wait(
            lambda: len(mission.delivered()) >= MID_DELIVERIES and active(sets.latest(), mission.site_time(), MARGIN),
            f"{MID_DELIVERIES} deliveries with a constraint active",
            timeout=120,
        )
        kill = mission.kill("planner")
        new_pid = mission.wait_restart(kill)
        t_first, first = plans.first(lambda p: p.src == f"planner-{new_pid}", "plan from the restarted planner")
        outcome = mission.finish()

    before = [e for e in outcome.events if e["received"] <= kill.wall]
    cs = [m for t, m in sets.items() if t <= t_first][-1]  # the set in force when that plan was made
    assert first.constraints_version == cs.version
    assert first.world_version >= world_version(before) > 0, "the first plan answers the live world version"
    # Nothing delivered is planned again; nothing carried is loaded again.
    delivered = set(kill.delivered)
    loaded = {e["object"] for e in before if e["kind"] == "loaded"} - delivered
    steps = [(rid, s) for rid, robot_steps in first.robots.items() for s in robot_steps]
    assert not [s for _, s in steps if s.action in ("load", "unload") and s.args[0] in delivered], delivered
    assert not [s for _, s in steps if s.action == "load" and s.args[0] in loaded], loaded
    todo = {SITE.objects[o].robot for o in SITE.objects if o not in delivered}
    assert todo <= {rid for rid, robot_steps in first.robots.items() if robot_steps}
    # Action ids go on from what the robots executed (a robot's running action may be kept).
    for rid, robot_steps in first.robots.items():
        done = [e["data"]["action_id"] for e in before if e["kind"] == "action_done" and e["robot"] == rid]
        if robot_steps and done:
            assert robot_steps[0].action_id >= max(done), (rid, robot_steps[0], max(done))
    # The active constraints hold: no opening the human cannot give.
    for c in active(cs, kill.site_time):
        if c.kind == "door_unavailable":
            door = c.params["door"]
            assert not [o for o in first.openings if o.door == door and c.start <= o.start < c.end], (c, first.openings)

    assert_mission_completed(outcome)
    assert outcome.starts("planner") == 2 and outcome.starts("sim") == outcome.starts("restrictor") == 1
    assert mission.lines("planner was killed by SIGKILL") and mission.lines(f"restarted planner (pid {new_pid}")
    table_line(
        f"planner SIGKILL (after {len(kill.delivered)} deliveries, site t={kill.site_time:.0f} s)",
        "restart reported; first plan: live world version, nothing delivered replanned, ids go on, "
        "active door_unavailable respected",
        t_first - kill.at,
    )


def test_restrictor_killed_mid_mission_restores_its_constraint_set(spawn, tmp_path: Path, namespace: str):
    mission = UpMission(spawn, tmp_path, namespace)
    with observing(mission) as client:
        sets = Watch(client, client.keys.constraints(), ConstraintSet)
        mission.wait(
            lambda: len(mission.delivered()) >= MID_DELIVERIES and active(sets.latest(), mission.site_time(), MARGIN),
            f"{MID_DELIVERIES} deliveries with a constraint active",
            timeout=120,
        )
        kill = mission.kill("restrictor")
        new_pid = mission.wait_restart(kill)
        t_first, restored = sets.first(lambda s: s.src == f"restrictor-{new_pid}", "set from the restarted restrictor")
        # New feedback after the restart gets a new constraint id.
        ack = send_feedback(client, "door_unavailable", {"door": "d_storage", "minutes": 1}, timeout=30, retry=0.5)
        outcome = mission.finish()

    old = sets.messages(lambda s: s.src == f"restrictor-{kill.pid}")
    new = sets.messages(lambda s: s.src == f"restrictor-{new_pid}")
    last = old[-1]
    assert active(last, kill.site_time), "the restrictor died holding an active constraint"
    # What it publishes first is what it had: the persisted set, version and constraints.
    assert restored.version >= last.version
    assert [(c.id, c.kind, c.params, c.start, c.end, c.asp) for c in restored.constraints] == [
        (c.id, c.kind, c.params, c.start, c.end, c.asp) for c in last.constraints
    ]
    assert restored.asp == last.asp
    # From then on versions only grow, and a constraint id is never given twice.
    versions = [s.version for s in new]
    assert versions == sorted(versions) and len(set(versions)) == len(versions)
    seen_before = {c.id for s in old for c in s.constraints}
    for s in new:
        for c in s.constraints:
            assert c.id not in seen_before or any(c == b for b in last.constraints), c
    assert ack is not None and ack.accepted and ack.src == f"restrictor-{new_pid}", ack
    number = int(ack.constraint_id[1:])
    assert ack.constraint_id not in seen_before and number > max(int(c[1:]) for c in seen_before), (
        ack.constraint_id,
        seen_before,
    )
    assert ack.constraints_version > restored.version
    assert_mission_completed(outcome)
    fb = outcome.metrics["feedback"]
    assert fb["sent"] >= 2 and fb["accepted"] == fb["sent"] and fb["unanswered"] == 0, fb
    assert outcome.starts("restrictor") == 2 and outcome.starts("planner") == 1
    table_line(
        f"restrictor SIGKILL (site t={kill.site_time:.0f} s, {len(last.constraints)} constraint(s) active, "
        f"version {last.version})",
        "restart reported; first set after restart = the persisted one; versions grow, ids not reused; "
        "the human's feedback all accepted",
        t_first - kill.at,
    )


def test_feedback_sent_while_the_restrictor_is_down_is_acknowledged_after_its_restart_and_applied_once(
    spawn, tmp_path: Path, namespace: str, caplog: pytest.LogCaptureFixture
):
    mission = UpMission(spawn, tmp_path, namespace)
    with observing(mission) as client:
        sets = Watch(client, client.keys.constraints(), ConstraintSet)
        mission.wait(lambda: len(mission.delivered()) >= 1, "a delivery", timeout=120)
        kill = mission.kill("restrictor")
        assert not mission.lines("restarted restrictor"), "sent while the restrictor is down"
        # As the human model sends hers: one Feedback (one src and seq), re-sent until acknowledged.
        with caplog.at_level(logging.INFO, logger="arroch.feedback"):
            ack = send_feedback(client, "door_unavailable", {"door": "d_storage", "minutes": 1}, timeout=60, retry=0.5)
        acked_at = time.monotonic()
        new_pid = mission.pid("restrictor")
        outcome = mission.finish()

    assert ack is not None and ack.accepted, ack
    assert new_pid != kill.pid and mission.lines(f"restarted restrictor (pid {new_pid}")
    assert "sending again (attempt 2)" in caplog.text, "the first attempt found no restrictor"
    assert ack.src == f"restrictor-{new_pid}", "acknowledged by the restarted restrictor"
    mine = {c.id: c for s in sets.messages() for c in s.constraints if c.origin == client.src}
    assert len(mine) == 1, mine  # applied once, however many times it was sent
    ((cid, constraint),) = mine.items()
    assert cid == ack.constraint_id and constraint.params == {"door": "d_storage", "minutes": 1}
    new = sets.messages(lambda s: s.src == f"restrictor-{new_pid}")
    with_it = [s for s in new if cid in {c.id for c in s.constraints}]
    assert with_it and with_it[0].version == ack.constraints_version
    index = new.index(with_it[0])
    assert index > 0 and with_it[0].version == new[index - 1].version + 1, [
        (s.version, [c.id for c in s.constraints]) for s in new
    ]
    assert_mission_completed(outcome)
    table_line(
        "feedback sent while the restrictor is down",
        "re-sent until acked by the restarted restrictor; one constraint, version +1 once",
        acked_at - kill.at,
    )


def test_ar_client_killed_mid_mission_comes_back_with_overlays_of_the_live_world(spawn, tmp_path: Path, namespace: str):
    mission = UpMission(spawn, tmp_path, namespace, services="planner,restrictor,sim,ar", extra=("--camera", "tablet"))
    with observing(mission) as client:
        overlays = Watch(client, client.keys.overlay("tablet"), Overlay)
        mission.wait(lambda: len(mission.delivered()) >= MID_DELIVERIES, f"{MID_DELIVERIES} deliveries", timeout=120)
        kill = mission.kill("ar")
        new_pid = mission.wait_restart(kill)
        src = f"ar-{new_pid}"
        t_first, _ = overlays.first(lambda o: o.src == src, "overlay from the restarted AR client")
        # Localised again, with every door's state known (leaves drawn open or closed, not grey)...
        t_ok, good = overlays.first(
            lambda o: (
                o.src == src
                and o.ok
                and any(p.layer == "door" for p in o.primitives)
                and all(p.color != [160, 160, 160, 255] for p in o.primitives if p.layer == "door")
            ),
            "localised overlay with known door states",
            timeout=60,
        )
        # ...and the robots drawn where the world says they are (their poses and statuses came again).
        overlays.first(
            lambda o: o.src == src and any(p.layer.startswith("robot:") for p in o.primitives),
            "overlay showing a robot",
            timeout=60,
        )
        outcome = mission.finish()

    assert_mission_completed(outcome)
    before = overlays.messages(lambda o: o.src == f"ar-{kill.pid}")
    assert any(o.ok for o in before), "the AR client localised before the kill too"
    assert outcome.starts("ar") == 2 and outcome.starts("sim") == outcome.starts("planner") == 1
    table_line(
        f"AR client SIGKILL (after {len(kill.delivered)} deliveries)",
        "restart reported; overlays again: localised, door states known, robots drawn",
        t_ok - kill.at,
    )


def test_router_killed_mid_mission_is_restarted_on_its_endpoint_and_every_service_reconnects(
    spawn, tmp_path: Path, namespace: str
):
    mission = UpMission(spawn, tmp_path, namespace)
    mission.wait(lambda: len(mission.delivered()) >= MID_DELIVERIES, f"{MID_DELIVERIES} deliveries", timeout=120)
    endpoint = mission.router_endpoints()[0]
    pids = {name: mission.pid(name) for name in ("planner", "restrictor", "sim")}
    kill = mission.kill("router")
    mission.wait_restart(kill)

    def reconnected() -> set[str]:
        """Services whose liveliness the supervisor saw again after the restart."""
        out = mission.proc.output
        after = out[out.index("restarted router (pid") :]
        return {
            m.group(1)
            for m in SERVICE_IDS.finditer("\n".join(line for line in after.splitlines() if " is up (" in line))
            if int(m.group(2)) == pids.get(m.group(1))
        }

    mission.wait(lambda: reconnected() == set(pids), "every service back on the restarted router", timeout=60)
    recovered = time.monotonic() - kill.at
    outcome = mission.finish()

    assert mission.router_endpoints() == [endpoint, endpoint], "restarted on the same endpoint"
    assert_mission_completed(outcome)
    assert outcome.starts("router") == 2
    assert all(outcome.starts(name) == 1 for name in pids), "the services reconnected: none was restarted"
    table_line(
        f"router SIGKILL (after {len(kill.delivered)} deliveries)",
        "restarted on the same endpoint; planner, restrictor, sim reconnected (not restarted)",
        recovered,
    )
