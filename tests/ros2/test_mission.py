"""The default mission with every robot driven through ROS 2: ``arroch sim --ros2-bases`` plays
three ROS 2 mobile bases (Twist in on ``/<rid>/cmd_vel``, Odometry out on ``/<rid>/odom``), and
three ``arroch robot --ros2`` processes drive them, under ``arroch up`` with the real planner and
restrictor, in lockstep, once per key format. The simulator moves a robot only as the Twists
it receives say, so a mission that completes was driven by the drivers."""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

import pytest

from protocol.site import load_site
from tests.procs import arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow(seconds=120)]  # wall s on two quiet cores

TIMEOUT = 300.0  # wall s, a guard: the mission takes 30-60 s alone on two cores, up to 150 s beside another test's
SITE = load_site()


@pytest.mark.parametrize("key_format", ["rmw_zenoh", "ros2dds"])
def test_default_mission_through_ros2(spawn, tmp_path: Path, key_format: str):
    run_dir = tmp_path / "runs"
    ros2 = f"--key-format {key_format} --domain 7"
    drivers = [
        f"--child={rid}={{python}} -m services.cli robot --ros2 --robot {rid} {ros2}" for rid in sorted(SITE.robots)
    ]
    proc = spawn(
        arroch(
            "up",
            "--services",
            "planner,restrictor",
            "--mode",
            "lockstep",
            "--seed",
            "1",
            "--until-done",
            "--run-dir",
            str(run_dir),
            "--progress",
            "off",
            "--timeout",
            f"{TIMEOUT:g}",
            f"--child=world={{python}} -m services.cli sim --mode lockstep --seed 1 --ros2-bases {ros2}",
            *drivers,
        ),
        name="up",
    )
    deadline = time.monotonic() + TIMEOUT + 20
    while proc.alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not proc.alive(), f"mission not done within {TIMEOUT} s:\n{proc.output[-4000:]}"
    assert proc.popen.returncode == 0, proc.output[-4000:]
    for rid in SITE.robots:
        assert f"robot {rid}: cmd_vel on /{rid} ({key_format}, domain 7)" in proc.output
    (run,) = [p for p in run_dir.iterdir() if p.is_dir()]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["completed"] is True
    delivered = [o for r in metrics["robots"].values() for o in r["delivered"]]
    assert sorted(delivered) == sorted(SITE.objects)
    assert metrics["closed_door_crossings"] == 0
    # The drivers keep the bases apart (the simulator only integrates their Twists and counts contacts).
    assert metrics["robot_overlaps"] == 0, metrics["robot_overlaps_by_place"]
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    kinds = Counter(e["kind"] for e in events)
    assert kinds["mission_done"] == 1 and kinds["delivered"] == 9 and kinds["closed_door_crossing"] == 0
    # The drivers run in wall time beside a lockstep sim: a command can be planned from a pose a few
    # tenths of a second old, and the driver's safety check then refuses it (the planner plans anew).
    # Seen once in CI (a gothrough whose trajectory missed the doorway). The drivers keep the robots
    # apart by the simulator's traffic rules from news a tick or two late, so a wait among robots
    # may end as the simulator's own robots' last resort does (kept back, the planner plans anew).
    # Anything else is a bug.
    failed = [e["data"] for e in events if e["kind"] == "action_failed"]
    stale = ("trajectory starts", "does not cross", "kept back by robots")
    assert len(failed) <= 3 and all(any(r in f.get("reason", "") for r in stale) for f in failed), failed
    assert kinds["action_done"] < 300  # about 110 for 9 deliveries: no action repeated without progress
    assert "lockstep stalled" not in proc.output
