"""A trial's outcome as CSV cells: every figure from the sim's metrics, in fixed formats."""

from __future__ import annotations

from services.experiments.design import SweepSpec, TrialKey
from services.experiments.record import TIMING_FIELDS, TRIAL_FIELDS, key_of, timing_row, trial_row
from services.experiments.trial import TrialOutcome

SPEC = SweepSpec(kind="robots", methods=("arroch",), robots=(2,), objects=1, ps=(0.5,), trials=1, seed=0)
KEY = TrialKey("arroch", 2, 1, 0.5, 600.0, 15.0, 0)

# The shape of the sim's metrics (services/sim/metrics.py), with made-up numbers.
METRICS = {
    "completed": True,
    "time": 642.15,
    "team_completion_time": 642.1,
    "agent_completion_times": {"r0": 301.25, "r1": 412.0000001, "human": 642.1},
    "human_door_openings": 3,
    "door_openings": {"d_storage": {"human": 3}},
    "feedback": {"sent": 2, "accepted": 1, "refused": 1, "unanswered": 0},
    "actions": {"done": 20, "failed": 0},
    "world_versions": 27,
    "robots": {"r0": {"wait_time": 12.5}, "r1": {"wait_time": 0.25}},
    "human": {
        "door_trips": 4,
        "time_away": 31.5,
        "task_duration": 598.25,
        "interruptions": 2,
        "time_lost": 30.0,
        "declarations": 1,
    },
    "run": {"wall_time": 9.87, "realtime_factor": 65.06},
}


def test_trial_row() -> None:
    outcome = TrialOutcome(KEY, "ok", "", METRICS, {"wall": 12.3456, "plans": 30, "solve_time": 1.5}, code="abc123")
    row = trial_row(SPEC, outcome)
    assert tuple(row) == TRIAL_FIELDS
    assert key_of(row) == KEY
    assert row["site_seed"] == str(SPEC.site_seed(KEY)) and row["seed"] == str(SPEC.sim_seed(KEY))
    assert (row["task_mean"], row["interruption_cost"]) == ("600", "15")
    assert row["team_completion_time"] == "642.100"
    assert row["sum_of_times"] == "1355.350"  # 301.25 + 412.0000001 + 642.1, rounded once
    assert (row["human_task_time"], row["human_interruptions"], row["human_time_lost"], row["focus_declared"]) == (
        "598.250",
        "2",
        "30.000",
        "1",
    )
    assert row["slowest_robot_time"] == "412.000"
    assert row["agent_completion_times"] == "r0=301.250;r1=412.000;human=642.100"
    assert (row["door_openings"], row["human_door_trips"]) == ("3", "4")
    assert (row["feedback_sent"], row["feedback_accepted"]) == ("2", "1")
    assert row["replans"] == "27"  # 26 new world versions after the start + 1 accepted feedback
    assert row["robot_wait_time"] == "12.750"
    # Nothing measured on the wall clock reaches this file.
    assert "12.346" not in row.values() and "9.870" not in row.values()
    timing = timing_row(outcome)
    assert tuple(timing) == TIMING_FIELDS
    assert (timing["wall_time"], timing["mission_wall_time"], timing["plans"], timing["code"]) == (
        "12.346",
        "",
        "30",
        "abc123",
    )


def test_a_failed_trial_has_no_figures() -> None:
    row = trial_row(SPEC, TrialOutcome(KEY, "timeout", "no end of mission within 5 s wall (mission running)"))
    assert row["status"] == "timeout" and row["reason"].startswith("no end")
    assert row["team_completion_time"] == row["door_openings"] == ""


def test_code_fingerprint_follows_the_sources(tmp_path) -> None:  # noqa: ANN001
    from services.experiments.provenance import code_fingerprint

    (tmp_path / "services" / "planner").mkdir(parents=True)
    (tmp_path / "protocol").mkdir()
    source = tmp_path / "services" / "planner" / "rules.lp"
    source.write_text("a.\n")
    first = code_fingerprint(tmp_path)
    assert code_fingerprint(tmp_path) == first and len(first) == 12
    source.write_text("a. b.\n")
    second = code_fingerprint(tmp_path)
    assert second != first
    (tmp_path / "services" / "planner" / "notes.txt").write_text("not a source")
    assert code_fingerprint(tmp_path) == second
    (tmp_path / "runtime" / "executor").mkdir(parents=True)  # the robots' executor decides outcomes too
    (tmp_path / "runtime" / "executor" / "waiting.py").write_text("PATIENCE = 120.0\n")
    assert code_fingerprint(tmp_path) != second


def test_dependency_versions_name_python_and_what_is_installed() -> None:
    from importlib.metadata import version

    from services.experiments.provenance import dependency_versions

    versions = dependency_versions()
    assert versions["python"].count(".") == 2
    assert versions["clingo"] == version("clingo") and versions["eclipse-zenoh"] == version("eclipse-zenoh")
    assert versions["opencv-python-headless"].startswith("5.")
    assert "arroch" not in versions  # its own extras name no package of their own
    assert dependency_versions("no-such-distribution") == {"python": versions["python"]}


def test_a_point_sweeps_rows_carry_the_point_its_factors_and_the_plan_changes() -> None:
    from services.experiments.record import PLAN_FIELDS, trial_fields

    spec = SweepSpec(
        kind="detour",
        methods=("arroch",),
        robots=(2,),
        objects=3,
        ps=(0.5,),
        trials=1,
        seed=0,
        points=({"capacity": 2, "door_share": 0.5},),
        domain="detour",
    )
    (key,) = spec.keys()
    changes = {"constraint_replans": 2, "plans_changed": 1, "deliveries_reordered": 1, "door_wait_time": 12.25}
    row = trial_row(spec, TrialOutcome(key, "ok", "", {**METRICS, "plan_changes": changes}))
    assert tuple(row) == trial_fields(spec) and set(PLAN_FIELDS) < set(row)
    assert (row["point"], row["capacity"], row["door_share"]) == ("0", "2", "0.5")
    assert (row["constraint_replans"], row["plans_changed"], row["deliveries_reordered"]) == ("2", "1", "1")
    assert row["door_wait_time"] == "12.250"
    assert key_of(row) == key
    assert trial_fields(SPEC) == TRIAL_FIELDS  # the earlier sweeps keep their columns


def test_a_trials_human_file_merges_the_sweeps_the_points_and_the_config(tmp_path) -> None:  # noqa: ANN001
    import tomllib

    from protocol.site import loads_site
    from services.experiments.trial import human_text, site_text

    assert human_text(SPEC, KEY) is None  # nothing asked: the sim's defaults, no file
    config = "[human]\ntask_std = 30.0\nfocus_count = 3\n\n[calibration.declare_time]\nestimate = 2.0\n"
    spec = SweepSpec(
        kind="sensitivity",
        methods=("arroch",),
        robots=(2,),
        objects=3,
        ps=(0.5,),
        trials=1,
        seed=0,
        human_config=config,
        human={"anticipation": 20.0, "focus_count": 1},
        points=({"focus_count": 4, "capacity": 3, "declare_time": 2.5},),
        domain="detour",
    )
    (key,) = spec.keys()
    human = tomllib.loads(human_text(spec, key) or "")["human"]
    assert human == {"task_std": 30.0, "focus_count": 4, "anticipation": 20.0, "declare_time": 2.5}
    site = loads_site(site_text(spec, key), "s.toml")
    assert site.params.robot_capacity == 3
    assert sum(o.deliver_to == "storage" for o in site.objects.values()) == 3  # the detour default: half of 6
    paper = SweepSpec(kind="robots", methods=("arroch",), robots=(2,), objects=3, ps=(0.5,), trials=1, seed=0)
    (first, *_) = paper.keys()
    assert all(o.deliver_to == "storage" for o in loads_site(site_text(paper, first), "p.toml").objects.values())
