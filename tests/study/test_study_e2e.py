"""A whole study, end to end: four scripted participants in headless Chromium, the virtual world.

``arroch study plan`` writes a 4-participant plan (ARROCH against the RViz-like map view, orders
counterbalanced); each trial is ``arroch study run`` for real — the world (planner, restrictor,
sim with a participant in place of the simulated human, AR client, tablet page, recorder) as
separate processes over Zenoh — and a person's part played on the tablet page in Chromium the way a
person would: consent, the puzzle (solved by looking at the pieces), the robots' view, a feedback
card (ARROCH), walking to her door when the view shows a robot waiting there and holding the door's
control until it opens, the questionnaire. Then ``arroch study report`` builds the report from what
the trials left in the study folder, and the recordings hold her acts.

The world runs 10x faster than real time on a generated two-robot building, so a trial takes seconds.
"""

from __future__ import annotations

import csv
import json
import re
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from services.study.layout import StudyFolder, read_jsonl
from tests.procs import Proc, arroch
from tests.tablet.study_driver import StudyPageDriver

pytestmark = [pytest.mark.integration, pytest.mark.slow(seconds=135)]  # wall s on two quiet cores

DOOR = "d_storage"  # her door, into the storage room where every object goes
RATE = 10.0
URL = re.compile(r"^\s+(https://\S+[?&]token=\S+)\s*$")
#: What each scripted participant answers, by condition: ARROCH's robots are easier to keep track of (Q2).
ANSWERS = {
    "arroch": {"Q1": 5, "Q2": 5, "Q3": 4, "Q4": 4, "Q5": 5},
    "map": {"Q1": 5, "Q2": 2, "Q3": 3, "Q4": 4, "Q5": 3},
}
TRIAL_TIMEOUT = 300.0  # wall s for one trial, world start to questionnaire (generous: shared, loaded machines)


def _site(path: Path) -> Path:
    """A generated building (two robots, one object each, tags on her room's walls so the AR view
    localises), as `arroch site generate` writes it."""
    made = Proc([*arroch("site", "generate", "--robots", "2", "--objects", "1", "--seed", "1", "--out", str(path))])
    assert made.wait(60) == 0, "\n".join(made.lines)
    return path


def _plan(study: Path) -> StudyFolder:
    site = _site(study.parent / "site.toml")
    done = Proc(
        [
            *arroch("study", "plan"),
            "--participants", "4",
            "--conditions", "arroch,map",
            "--seed", "5",
            "--puzzle", "2x2",
            "--site", str(site),
            "--mode", "rate",
            "--rate", f"{RATE:g}",
            "--time-limit", "900",
            "--out", str(study),
        ],
        name="plan",
    )  # fmt: skip
    assert done.wait(60) == 0, "\n".join(done.lines)
    return StudyFolder(study)


def _tablet_url(runner: Proc) -> str:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        for line in list(runner.lines):
            found = URL.match(line)
            if found:
                return found.group(1)
        if runner.popen.poll() is not None:
            break
        time.sleep(0.1)
    raise AssertionError("the runner printed no tablet URL:\n" + "\n".join(runner.lines))


def _robot_waiting(driver: StudyPageDriver) -> bool:
    states = driver.browser.evaluate("window.arroch.state().robot_states") or {}
    return "waiting_at_door" in states.values()


def _play_trial(driver: StudyPageDriver, url: str, condition: str, first: bool) -> dict[str, int]:
    """A participant's trial on the page; returns what she did (for the test's own checks)."""
    did = {"door_openings": 0, "feedback": 0, "moves": 0}
    driver.open(url)
    if first:
        assert driver.consent() is True
    driver.wait("s.screen === ''", timeout=30)  # the world goes on once she consented (paused till then)
    # She looks at the robots first: the AR view shows the tablet camera, the map view the robots.
    driver.switch("robots")
    if condition == "arroch":
        # The tablet camera with the robots drawn where they are, through the walls (localised on the tags).
        driver.browser.wait_for("(o => o && o.ok && o.primitives > 0)(window.arroch.state().overlay)", timeout=30)
        driver.wait("s.screen === ''", timeout=30)  # a person waits for a "paused" notice to go away
        driver.send_feedback("door_unavailable", door=DOOR, minutes=1)
        did["feedback"] += 1
    else:
        driver.browser.wait_for("window.arroch.state().robots.length > 0", timeout=30)
    deadline = time.monotonic() + TRIAL_TIMEOUT
    # Then, until the mission ends: a glance at the robots' view; a robot waiting at her door there
    # sends her to it; else back to the puzzle for a move (the puzzle is done: she keeps watching).
    while (state := driver.state()).get("screen") != "questionnaire":
        assert time.monotonic() < deadline, f"the trial did not end: {state}"
        if state.get("screen") or (state.get("human") or {}).get("place", "desk") != "desk":
            time.sleep(0.2)  # paused, or still walking back from her door
            continue
        if _robot_waiting(driver):
            driver.go_to_door(DOOR)
            driver.wait_at_door()
            driver.hold_open()
            did["door_openings"] += 1
        elif not (state.get("puzzle") or {}).get("done"):
            if driver.switch("puzzle"):  # (the trial may end at any moment: no more tabs then)
                did["moves"] += driver.solve_puzzle(max_moves=1)
                driver.switch("robots")
        time.sleep(0.3)  # long enough for the view's next update of the robots (every 0.25 s)
    driver.answer_questionnaire({"arroch-q": ANSWERS[condition]})
    return did


def test_a_four_participant_study_runs_end_to_end_and_is_reported(tmp_path: Path, browser) -> None:  # noqa: ANN001
    folder = _plan(tmp_path / "study")
    plan = folder.plan()
    page = StudyPageDriver(browser(window=(1280, 800)), timeout=60)
    for participant in plan.participants:
        for k, trial in enumerate(participant.trials):
            runner = Proc([*arroch("study", "run", str(folder.root), "--participant", participant.id)], name="run")
            try:
                did = _play_trial(page, _tablet_url(runner), trial.condition, first=k == 0)
                assert runner.wait(60) == 0, "\n".join(runner.lines)
            except Exception:
                shot = tmp_path / f"{trial.id}-failed.png"  # what the page showed, for whoever reads the failure
                shot.write_bytes(page.browser.screenshot())
                print(f"page at the failure: {shot}\n{json.dumps(page.state())}\n" + "\n".join(runner.lines))
                raise
            finally:
                runner.stop()
            state = folder.trial_state(participant.id, trial)
            assert state.status == "complete", (state, "\n".join(runner.lines))
            assert did["door_openings"] >= 1
            acts = [
                r["act"]
                for r in read_jsonl(folder.log_file(participant.id, trial.id))
                if r["type"] == "ParticipantAction"
            ]
            for act in ("view", "puzzle_move", "go_to_door", "open_door", "task_done"):
                assert act in acts, (trial.id, act, acts)
            assert ("feedback" in acts) == (trial.condition == "arroch")
            answers = json.loads(folder.questionnaire_file(participant.id, trial.id).read_text())
            assert answers["arroch-q"] == ANSWERS[trial.condition]
            metrics = json.loads(folder.metrics_file(participant.id, trial.id).read_text())
            assert metrics["completed"] and metrics["closed_door_crossings"] == 0
            assert metrics["human"]["participant"] is True and metrics["human_door_openings"] >= 1
            _assert_recorded(folder.latest_run(participant.id, trial.id) / "run.mcap")
        assert folder.consent(participant.id).consented

    report = Proc([*arroch("study", "report", str(folder.root))], name="report")
    assert report.wait(120) == 0, "\n".join(report.lines)
    out = folder.report_dir
    for name in ("REPORT.md", "data.csv", "tests.json"):
        assert (out / name).stat().st_size > 0, name
    assert len(list(out.glob("*.png"))) >= 3
    with open(out / "data.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    trials = {(r["participant"], r["trial"]) for r in rows}
    assert len(trials) == 8
    assert {r["condition"] for r in rows} == {"arroch", "map"}


def _assert_recorded(path: Path) -> None:
    """Her acts are in the run's recording with the rest (robots, plans)."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        counts: dict[str, int] = {}
        for _schema, channel, _message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    acts = sum(n for topic, n in counts.items() if "participant/action" in topic)
    assert acts > 0, sorted(counts)
    assert any("pose" in topic for topic in counts), sorted(counts)
