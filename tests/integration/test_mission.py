"""The default mission end to end with the real services: ``arroch up`` starts a router, the
planner, the restrictor and the simulator, in lockstep and at 20x real time, and the mission must
finish.

Regressions it guards: a planner that sends ``opendoor`` again and again for a door the human has
already opened (each is done at once, so world versions climb while sim time stands still), and
first commands lost because the planner published them before the simulator subscribed (lockstep
then waits for them forever). At a fixed rate, where the planner plans while the world moves on:
a robot waiting at a door that was sent the same ``approach`` hundreds of times.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

import pytest

from tests.procs import arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TIMEOUT = 120.0  # wall s; the mission takes about 3 s in lockstep, 36 s at 20x, on two cores
# The most times one robot may end the same action (same arguments). The regression this guards sent
# one approach hundreds of times. At 20x a replan of 0.5-1 wall s is 10-20 site s, so a robot queued at
# d_storage can miss the human's 20 s opening and ask again: 10-13 on a quiet machine (before and after
# the shared executor), 23 at CI's load.
REPEATS = 40


@pytest.mark.parametrize(
    "mode", [["--mode", "lockstep"], ["--mode", "rate", "--rate", "20"]], ids=["lockstep", "rate20"]
)
def test_default_mission_completes(spawn, tmp_path: Path, mode: list[str]):
    run_dir = tmp_path / "runs"
    proc = spawn(
        arroch(
            "up",
            "--services",
            "planner,restrictor,sim",
            *mode,
            "--seed",
            "1",
            "--until-done",
            "--run-dir",
            str(run_dir),
            "--progress",
            "off",
            "--no-record",  # outcomes are checked; a recorder doubles the poses sent (docs/services/sim.md)
        ),
        name="up",
    )
    deadline = time.monotonic() + TIMEOUT
    while proc.alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not proc.alive(), f"mission not done within {TIMEOUT} s:\n{proc.output[-4000:]}"
    assert proc.popen.returncode == 0, proc.output[-4000:]
    (run,) = [p for p in run_dir.iterdir() if p.is_dir()]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["completed"] is True
    delivered = [o for r in metrics["robots"].values() for o in r["delivered"]]
    assert len(delivered) == 9 == len(set(delivered))
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    kinds = Counter(e["kind"] for e in events)
    assert kinds["mission_done"] == 1 and kinds["delivered"] == 9
    # robot-robot contacts are counted, each once, and filed under a place; in lockstep (the same
    # mission every run) there are none
    overlaps = metrics["robot_overlaps"]
    assert overlaps == kinds["robot_overlap"] == sum(metrics["robot_overlaps_by_place"].values())
    if "lockstep" in mode:
        assert overlaps == 0, metrics["robot_overlaps_by_place"]
    # robot-wall contacts likewise; the motion planner's clearance (runtime/clearance.py) keeps every
    # disc off the walls in lockstep (7 contacts, 8 mm deep, with the old 0.02 m clearance), and the
    # wall guard bounds the depth whatever happens at a fixed rate
    walls = metrics["wall_contacts"]
    assert walls == kinds["wall_contact"] == sum(metrics["wall_contacts_by_place"].values())
    assert metrics["wall_depth_max"] <= metrics["params"]["robot_motion"]["wall_tolerance"] + 1e-6
    if "lockstep" in mode:
        assert walls == 0 and metrics["wall_depth_max"] == 0.0, metrics["wall_contacts_by_place"]
    failed = [e["data"] for e in events if e["kind"] == "action_failed"]
    if "lockstep" in mode:
        assert failed == []
    else:
        # At 20x on a loaded machine a command is planned from poses and objects some wall tenths of a
        # second (several site seconds) old. It can start metres from the robot, or (the robot has gone
        # round a corner or through a doorway since) its way from the robot to the trajectory's start
        # crosses a wall: the sim refuses it (its safety check) and the planner plans anew. Where it
        # starts in the room the robot has just left, past a jamb, the wall guard holds the drive until
        # it fails (30 s), or a shut door's gap does; a load can name an object another robot has
        # picked up meanwhile. Robots that make way for one another move while parked, so this happens
        # several times a run on a loaded machine. In real time robots also meet where lockstep keeps
        # them apart, and a robot kept back 12 s by others fails its action by design (it never pushes
        # through; the planner plans again). Each ends in a replan; anything else failing is a bug.
        # How many depends on the machine's load (12-17 with three missions side by side, 0-3 on a
        # quiet machine); the kinds are what matters, the count only bounds a run gone wrong.
        stale = (
            "trajectory starts",
            "crosses a wall",
            "kept back by robots",
            "held beside a wall",
            "held beside a shut door's gap",
            "is carried by",
        )
        assert len(failed) <= 30 and all(any(s in f.get("reason", "") for s in stale) for f in failed), [
            (f.get("action"), f.get("args"), f.get("reason")) for f in failed
        ]
    # about 100 actions for 9 loads; thousands mean robots repeat an action without progress
    assert kinds["action_done"] < 300
    ended = Counter(
        (e["robot"], e["data"].get("action"), tuple(e["data"].get("args") or ()))
        for e in events
        if e["kind"] == "action_done"
    )
    assert max(ended.values()) <= REPEATS, ended.most_common(3)
    opendoors = Counter(
        (e["robot"], e["stamp"]) for e in events if e["kind"] == "action_done" and e["data"].get("action") == "opendoor"
    )
    assert all(n == 1 for n in opendoors.values())
    assert "lockstep stalled" not in proc.output
