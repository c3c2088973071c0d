"""``arroch study report`` on a constructed study with known effects: Q2 always two points higher
with ARROCH, Q1 always the same; the robots always faster with ARROCH; one trial incomplete and one
mission unfinished, both listed and left out where they must be."""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from services.study import report
from services.study.layout import PuzzleSpec, StudyFolder, WorldSpec, write_json
from services.study.plan import build_plan
from tests.study.helpers import run_command
from tests.study.scripted import write_trial

N = 10
INCOMPLETE = ("P03", "map")  # page closed, never resumed
UNFINISHED = ("P04", "arroch")  # the mission ran out of time: no team time
VIEW_AWAY = (100.0, 112.5)  # s: she looked at the AR view
TRIP = (200.0, 31.0)  # s: a door trip starting then, this long


def _log(human_time: float, end: float) -> list[dict]:
    def act(t: float, act: str, **kw: object) -> dict:
        return {"t": t, "type": "ParticipantAction", "participant": "P", "act": act, **kw}

    def place(t: float, where: str) -> dict:
        return {"t": t, "type": "HumanState", "place": where, "doors": ["d1"]}

    start, length = TRIP
    return [
        {"t": 0.0, "type": "Event", "kind": "mission_started"},
        place(0.0, "desk"),
        act(0.0, "view", view="puzzle"),
        act(VIEW_AWAY[0], "view", view="ar"),
        act(VIEW_AWAY[0] + 2.0, "feedback", door="d1", minutes=3, note="door_unavailable"),
        act(VIEW_AWAY[1], "view", view="puzzle"),
        act(start, "go_to_door", door="d1"),
        place(start, "to_door"),
        act(start + 10.0, "open_door", door="d1"),
        place(start + length, "desk"),
        act(human_time, "task_done"),
        {"t": end, "type": "Event", "kind": "mission_done"},
    ]


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    tmp_path = tmp_path_factory.mktemp("known")
    rng = np.random.default_rng(5)
    plan = build_plan(
        name="known",
        seed=11,
        conditions=["arroch", "map"],
        participant_ids=[f"P{i:02d}" for i in range(1, N + 1)],
        questionnaires=["arroch-q"],
        puzzle=PuzzleSpec(),
        world=WorldSpec(),
    )
    folder = StudyFolder(tmp_path / "study")
    write_json(folder.plan_file, plan)
    truth: dict[str, dict] = {}
    for p in plan.participants:
        base_q2 = int(rng.integers(1, 4))
        q1 = int(rng.integers(3, 6))
        robots_map = rng.uniform(300, 500, size=2)
        human = float(rng.uniform(400, 600))
        for t in p.trials:
            arroch = t.condition == "arroch"
            robots = robots_map - (rng.uniform(20, 60, size=2) if arroch else 0.0)
            completed = (p.id, t.condition) != UNFINISHED
            times = {"r0": float(robots[0]), "r1": float(robots[1]), "human": human}
            metrics = {
                "completed": completed,
                "time": max(times.values()) if completed else 1800.0,
                "team_completion_time": max(times.values()) if completed else None,
                "agent_completion_times": times,
                "human_door_openings": 1,
            }
            answers = {
                "arroch-q": {
                    "Q1": q1,
                    "Q2": base_q2 + (2 if arroch else 0),
                    "Q3": int(rng.integers(1, 6)),
                    "Q4": int(rng.integers(1, 6)),
                    "Q5": int(rng.integers(1, 6)),
                }
            }
            status = "incomplete" if (p.id, t.condition) == INCOMPLETE else "complete"
            write_trial(folder, plan, p.id, t.id, _log(human, metrics["time"]), metrics, answers, status)
            truth[t.id] = {"metrics": metrics, "answers": answers, "status": status}
    return folder.root, truth


@pytest.fixture(scope="module")
def reported(study) -> tuple[Path, dict, str]:
    """The report made once for the tests that only read it: (study root, truth, what it printed)."""
    root, truth = study
    parser = argparse.ArgumentParser()
    report.add_arguments(parser)
    assert report.main(parser.parse_args([str(root)])) == 0
    return root, truth, (root / "report" / "REPORT.md").read_text()


def test_report_finds_the_known_effects(reported) -> None:
    root, _, _ = reported
    tests = json.loads((root / "report" / "tests.json").read_text())
    likert = {r["measure"]: r for r in tests["families"]["likert"]}
    pairs = N - 1  # P03 has no complete map trial
    q2 = likert["Q2"]
    assert q2["n"] == pairs and q2["a"] == "arroch" and q2["b"] == "map"
    # Every difference is +2: the exact two-sided p is the two all-same-sign outcomes of 2^n.
    assert q2["wilcoxon"]["p"] == pytest.approx(2 / 2**pairs)
    assert q2["p_holm"] <= 5 * q2["wilcoxon"]["p"] + 1e-12
    assert q2["decision"] == "higher in arroch than in map at α=0.05 after Holm"
    assert q2["median_diff"] == 2 and q2["hodges_lehmann"] == 2
    assert likert["Q1"]["wilcoxon"]["p"] == 1.0 and likert["Q1"]["decision"] == "no difference detected"
    times = {r["measure"]: r for r in tests["families"]["times"]}
    assert times["robots_time"]["decision"] == "lower in arroch than in map at α=0.05 after Holm"
    assert times["team_time"]["n"] == pairs - 1  # P04's ARROCH mission did not finish
    assert tests["left_out"] == [
        {"trial": next(t for t in _trial_ids(root) if t.startswith("P03") and t.endswith("map")),
         "participant": "P03", "status": "incomplete", "reason": "page closed and not resumed"}
    ]  # fmt: skip
    md = (root / "report" / "REPORT.md").read_text()
    assert "P03" in md.split("## Trials left out")[1].split("##")[0]
    assert "did not finish" in md.split("## Missing values")[1].split("##")[0]


def test_command_prints_its_decisions(study, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, _ = study
    code, out, err = run_command(report, [str(root), "--out", str(tmp_path / "elsewhere")], capsys)
    assert code == 0, err
    assert "Q2" in out and "higher in arroch than in map" in out and str(tmp_path / "elsewhere") in out
    assert (tmp_path / "elsewhere" / "REPORT.md").is_file() and (tmp_path / "elsewhere" / "data.csv").is_file()


def _trial_ids(root: Path) -> list[str]:
    return [t.id for p in StudyFolder(root).plan().participants for t in p.trials]


def test_csv_is_tidy_and_holds_every_value(reported) -> None:
    root, truth, _ = reported
    with open(root / "report" / "data.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["participant", "trial", "condition", "order", "status", "measure", "value"]
    values = {(r["trial"], r["measure"]): float(r["value"]) for r in rows}
    status = {r["trial"]: r["status"] for r in rows}
    for tid, t in truth.items():
        times = t["metrics"]["agent_completion_times"]
        robots = times["r0"] + times["r1"]
        assert values[(tid, "robots_time")] == pytest.approx(robots, abs=1e-6)
        assert values[(tid, "agents_time")] == pytest.approx(robots + times["human"], abs=1e-6)
        assert values[(tid, "Q2")] == t["answers"]["arroch-q"]["Q2"]
        assert values[(tid, "time_away")] == pytest.approx((VIEW_AWAY[1] - VIEW_AWAY[0]) + TRIP[1])
        assert values[(tid, "declarations")] == 1
        assert status[tid] == t["status"]
        assert ((tid, "team_time") in values) == t["metrics"]["completed"]


def test_figures_are_readable_images(reported) -> None:
    root, _, md = reported
    for name in report.FIGURES.values():
        image = matplotlib.image.imread(root / "report" / name)
        assert image.shape[0] > 100 and image.shape[1] > 100 and image.std() > 0  # not a blank canvas
        assert f"]({name})" in md


def test_bad_answers_are_named(study, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "copy"
    shutil.copytree(study[0], root)
    plan = StudyFolder(root).plan()
    trial = plan.participants[0].trials[0]
    path = StudyFolder(root).questionnaire_file("P01", trial.id)
    path.write_text(json.dumps({"arroch-q": {"Q1": 9}}))
    code, _, err = run_command(report, [str(root)], capsys)
    assert code == 2 and str(path) in err and "Q1" in err and "1-5" in err


def test_missing_study_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_command(report, [str(tmp_path)], capsys)
    assert code == 2 and "no study.json" in err


def test_three_conditions_and_nasa_tlx(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every pair of conditions is tested, Holm over measures x pairs; TLX scales and the raw TLX too."""
    rng = np.random.default_rng(9)
    plan = build_plan(
        name="three",
        seed=2,
        conditions=["arroch", "no-feedback", "map"],
        participant_ids=[f"P{i:02d}" for i in range(1, 7)],
        questionnaires=["arroch-q", "nasa-tlx"],
        puzzle=PuzzleSpec(),
        world=WorldSpec(),
    )
    folder = StudyFolder(tmp_path / "s")
    write_json(folder.plan_file, plan)
    scales = ("mental", "physical", "temporal", "performance", "effort", "frustration")
    tlx_values = {}
    for p in plan.participants:
        for t in p.trials:
            times = {"r0": 100.0, "human": float(rng.uniform(300, 400))}
            metrics = {"completed": True, "time": 400.0, "team_completion_time": 400.0, "agent_completion_times": times}
            tlx = {s: int(rng.integers(0, 101)) for s in scales}
            tlx_values[t.id] = sum(tlx.values()) / 6
            likert = {q: int(rng.integers(1, 6)) for q in ("Q1", "Q2", "Q3", "Q4", "Q5")}
            answers = {"arroch-q": likert, "nasa-tlx": tlx}
            write_trial(folder, plan, p.id, t.id, _log(times["human"], 400.0), metrics, answers)
    code, _, err = run_command(report, [str(folder.root)], capsys)
    assert code == 0, err
    tests = json.loads((folder.root / "report" / "tests.json").read_text())
    likert = tests["families"]["likert"]
    assert len(likert) == 5 * 3
    assert {(r["a"], r["b"]) for r in likert} == {("arroch", "no-feedback"), ("arroch", "map"), ("no-feedback", "map")}
    # Holm over all 15: each adjusted p is at least the raw one and at most 15 times it.
    for r in likert:
        assert r["wilcoxon"]["p"] <= r["p_holm"] <= min(1.0, 15 * r["wilcoxon"]["p"]) + 1e-12
    tlx = {r["measure"] for r in tests["families"]["nasa-tlx"]}
    assert tlx == {f"tlx_{s}" for s in scales} | {"tlx_raw"}
    with open(folder.root / "report" / "data.csv", newline="") as f:
        raw = {r["trial"]: float(r["value"]) for r in csv.DictReader(f) if r["measure"] == "tlx_raw"}
    assert raw == pytest.approx(tlx_values)
