"""A detour trial against the real services: the plan measures are recorded, and the same trial gives the same row."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.experiments.test_runner import finish, rows, start, wait_gone

pytestmark = [pytest.mark.integration, pytest.mark.slow]

# Not the paper's model (a quick mission for tests only): a 120 s task with one one-minute focus interval, always
# declared, so the planner gets a constraint to answer.
HUMAN = """[human]
task_mean = 120.0
task_std = 5.0
focus_count = 1
focus_min_minutes = 1
focus_max_minutes = 1
declare_probability = 1.0
"""
ONE = ["detour", "--robots", "1", "--objects", "2", "--capacities", "1", "--trials", "1", "--seed", "3"]


def test_a_detour_trial_records_how_feedback_changed_its_plans_the_same_way_twice(tmp_path: Path) -> None:
    human = tmp_path / "human.toml"
    human.write_text(HUMAN, encoding="utf-8")
    outs = []
    for run in ("a", "b"):
        out = tmp_path / run
        proc = start([*ONE, "--methods", "arroch", "--out", str(out), "--trial-timeout", "90"], human)
        code, output = finish(proc, 240)
        assert wait_gone(proc.pid) == []
        assert code == 0, output[-3000:]
        outs.append(out)
    (row,) = rows(outs[0])
    assert (row["status"], row["point"], row["capacity"], row["door_share"]) == ("ok", "0", "1", "0.5")
    assert int(row["feedback_accepted"]) >= 1
    assert int(row["constraint_replans"]) >= 1  # the accepted a2(N) was answered by a plan
    assert int(row["plans_changed"]) <= int(row["constraint_replans"])
    assert float(row["door_wait_time"]) <= float(row["robot_wait_time"]) + 1e-6
    # Everything in trials.csv follows from the seeds, the plan measures included.
    assert (outs[0] / "trials.csv").read_bytes() == (outs[1] / "trials.csv").read_bytes()
