"""``arroch study run``: which trial runs next, what it writes, and whole trials against a stand-in
world (tests/study/fake_up.py: a real process on real Zenoh saying what the world and her page
would) — complete, consent refused, the world crashing, the runner stopped by SIGTERM."""

from __future__ import annotations

import argparse
import hashlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from protocol.messages import (
    ConstraintSet,
    DoorState,
    Event,
    HumanState,
    ParticipantAction,
    QuestionnaireAnswers,
    StudyControl,
)
from runtime.runner import add_common_arguments
from runtime.transport import ZenohOptions
from services.study import run as study_run
from services.study.layout import (
    PlannedParticipant,
    PlannedTrial,
    PuzzleSpec,
    StudyError,
    StudyFolder,
    StudyPlan,
    WorldSpec,
    read_json,
    read_jsonl,
    write_json,
)
from services.study.page import consent_form, page_content
from services.study.progress import TrialProgress
from services.study.selection import (
    ParticipantLock,
    begin_attempt,
    finish,
    next_trial,
    recover_interrupted,
)
from services.study.trial import CommandRefused, TrialRun
from services.study.trial_log import Questionnaires, TrialLog, check_answers
from services.study.world import NEEDED, up_options, world_spec
from tests.procs import Proc

CONSENT = "I agree to take part in this study.\n"
FAKE_UP = f"{sys.executable} -m tests.study.fake_up"


def make_study(
    root: Path, *, kind: str = "virtual", questionnaires: tuple[str, ...] = ("arroch-q",), up_args: tuple = ()
) -> StudyFolder:
    trials = [
        PlannedTrial(id="P01-T1-arroch", index=1, condition="arroch", world_seed=11, puzzle_seed=5),
        PlannedTrial(id="P01-T2-map", index=2, condition="map", world_seed=11, puzzle_seed=6),
    ]
    plan = StudyPlan(
        name="pilot",
        seed=7,
        created="2024-05-01T10:00:00Z",
        design="balanced-latin-square",
        conditions=["arroch", "map"],
        questionnaires=list(questionnaires),
        world=WorldSpec(kind=kind, mode="rate", rate=5.0, time_limit=900.0, up_args=list(up_args)),
        participants=[
            PlannedParticipant(id="P01", trials=trials),
            PlannedParticipant(
                id="P02",
                trials=[PlannedTrial(id="P02-T1-map", index=1, condition="map", world_seed=12, puzzle_seed=7)],
            ),
        ],
    )
    write_json(root / "study.json", plan)
    (root / "consent.txt").write_text(CONSENT)
    return StudyFolder(root)


def run_args(study: Path, *extra: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_common_arguments(parser)
    study_run.add_arguments(parser)
    return parser.parse_args([str(study), *extra])


# ---------------------------------------------------------------------------- next trial


def test_the_next_trial_is_the_first_pending_then_the_next_once_it_is_complete(tmp_path: Path) -> None:
    folder = make_study(tmp_path)
    p01 = folder.plan().participant("P01")
    first = next_trial(folder, p01, retry=False)
    assert (first.action, first.trial.id, first.attempt) == ("run", "P01-T1-arroch", 1)
    state = begin_attempt(folder, first.state, now=100.0)
    assert (state.status, state.attempt, state.started) == ("running", 1, 100.0)
    finish(folder, state, "complete", now=200.0)
    second = next_trial(folder, p01, retry=False)
    assert (second.action, second.trial.id) == ("run", "P01-T2-map")
    finish(folder, begin_attempt(folder, second.state), "complete")
    done = next_trial(folder, p01, retry=False)
    assert done.action == "done" and "all 2 trial(s) are complete" in done.message


def test_a_trial_found_running_is_marked_incomplete_and_runs_again_only_with_retry(tmp_path: Path) -> None:
    folder = make_study(tmp_path)
    p01 = folder.plan().participant("P01")
    state = begin_attempt(folder, next_trial(folder, p01, retry=False).state, now=100.0)
    log_file = folder.log_file("P01", "P01-T1-arroch")
    log_file.write_text('{"t": 1.0}\n')
    os.utime(log_file, (150.0, 150.0))
    (folder.trial_dir("P01", state.trial) / "questionnaire.json").write_text("{}")
    (folder.trial_dir("P01", state.trial) / "page.tablet-progress.json").write_text('{"consent": "given"}')

    notes = recover_interrupted(folder, p01, now=300.0)
    assert len(notes) == 1 and "P01-T1-arroch" in notes[0]
    state = folder.trial_state("P01", p01.trials[0])
    assert state.status == "incomplete" and "runner stopped while the trial was running" in state.reason
    assert state.ended == 150.0  # when its log was last written: the best guess of when it stopped

    blocked = next_trial(folder, p01, retry=False)
    assert blocked.action == "blocked" and "--retry" in blocked.message and "P01-T1-arroch" in blocked.message
    again = next_trial(folder, p01, retry=True)
    assert (again.action, again.trial.id, again.attempt) == ("run", "P01-T1-arroch", 2)

    state = begin_attempt(folder, again.state, now=400.0)
    trial_dir = folder.trial_dir("P01", "P01-T1-arroch")
    assert (state.status, state.attempt, state.reason, state.ended) == ("running", 2, "", None)
    assert [(a.attempt, a.status, a.started, a.ended) for a in state.attempts] == [(1, "incomplete", 100.0, 150.0)]
    assert "runner stopped" in state.attempts[0].reason
    assert (trial_dir / "attempt-1" / "log.jsonl").read_text() == '{"t": 1.0}\n'
    assert (trial_dir / "attempt-1" / "questionnaire.json").exists()
    assert not (trial_dir / "page.tablet-progress.json").exists()  # the page must not resume the earlier attempt
    assert (trial_dir / "attempt-1" / "page.tablet-progress.json").exists()
    assert not log_file.exists()
    assert read_json(trial_dir / "trial.json")["attempt"] == 2


def test_a_second_runner_cannot_take_the_same_participant(tmp_path: Path) -> None:
    folder = make_study(tmp_path)
    with ParticipantLock(folder, "P01"):
        with pytest.raises(StudyError, match=f"pid {os.getpid()}"):
            ParticipantLock(folder, "P01").acquire()
        ParticipantLock(folder, "P02").acquire()  # another participant: free
    ParticipantLock(folder, "P01").acquire()  # released


def test_main_says_when_all_is_done_and_stops_at_an_incomplete_trial(tmp_path: Path, capsys) -> None:
    folder = make_study(tmp_path)
    p02 = folder.plan().participant("P02")
    state = begin_attempt(folder, next_trial(folder, p02, retry=False).state)
    finish(folder, state, "incomplete", "aborted by the experimenter: fire alarm")
    assert study_run.main(run_args(tmp_path, "--participant", "P02")) == 1
    assert "fire alarm" in capsys.readouterr().out
    finish(folder, state, "complete")
    assert study_run.main(run_args(tmp_path, "--participant", "P02")) == 0
    assert "all 1 trial(s) are complete" in capsys.readouterr().out
    assert study_run.main(run_args(tmp_path, "--participant", "P77")) == 2  # not in the plan
    assert study_run.main(run_args(tmp_path / "nowhere", "--participant", "P01")) == 2


def test_dry_run_prints_the_world_and_the_page_and_writes_nothing(tmp_path: Path, capsys) -> None:
    folder = make_study(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert study_run.main(run_args(tmp_path, "--participant", "P01", "--dry-run")) == 0
    out = capsys.readouterr().out
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    assert "services.cli up --services planner,restrictor,sim,ar,tablet --human participant --camera tablet" in out
    assert "--study-trial " + str((folder.trial_dir("P01", "P01-T1-arroch") / "page.json").resolve()) in out
    assert '"consent": {' in out and "take her consent on the tablet page first" in out
    assert "--namespace study-P01-t1-a1" in out and "--until-done --linger" in out


# ---------------------------------------------------------------------------- page.json and the world


def test_page_json_follows_the_condition_the_world_and_her_consent(tmp_path: Path) -> None:
    folder = make_study(tmp_path, questionnaires=("arroch-q", "nasa-tlx"))
    plan = folder.plan()
    arroch, mapped = plan.participant("P01").trials
    text, sha = consent_form(folder)
    assert sha == hashlib.sha256(CONSENT.encode()).hexdigest()
    page = page_content(plan, "P01", arroch, consent_text=text)
    assert page == {
        "participant": "P01",
        "trial": "P01-T1-arroch",
        "condition": "arroch",
        "door_control": "virtual",
        "puzzle": {"seed": 5, "rows": 4, "cols": 4},
        "questionnaires": ["arroch-q", "nasa-tlx"],
        "consent": {"required": True, "text": CONSENT},
    }
    real = make_study(tmp_path / "real", kind="real").plan()
    page = page_content(real, "P01", mapped, consent_text=None)
    assert (page["condition"], page["door_control"], page["puzzle"]["seed"]) == ("map", "sensor", 6)
    assert page["consent"] == {"required": False, "text": ""}
    plan.questionnaires = ["arroch-q", "sus"]
    with pytest.raises(StudyError, match="questionnaires"):
        page_content(plan, "P01", arroch, consent_text=None)
    plan.questionnaires = ["arroch-q"]
    plan.puzzle = PuzzleSpec(rows=12, cols=4)
    with pytest.raises(StudyError, match="puzzle 12x4"):
        page_content(plan, "P01", arroch, consent_text=None)
    (tmp_path / "consent.txt").write_text("  \n")
    with pytest.raises(StudyError, match="consent.txt is empty"):
        consent_form(folder)


def test_the_world_command_per_condition_and_world_kind(tmp_path: Path) -> None:
    virtual = make_study(tmp_path / "v").plan()
    spec = world_spec(
        virtual,
        page_file=tmp_path / "page.json",
        run_dir=tmp_path / "run",
        namespace="ns1",
        method="no-feedback",
        seed=11,
    )
    argv = spec.argv
    assert argv[:4] == [sys.executable, "-m", "services.cli", "up"]
    assert argv[argv.index("--camera") + 1] == "tablet" and "--doors" not in argv
    assert argv[argv.index("--method") + 1] == "no-feedback" and argv[argv.index("--seed") + 1] == "11"
    assert argv[argv.index("--mode") + 1] == "rate" and argv[argv.index("--rate") + 1] == "5"
    assert argv[argv.index("--time-limit") + 1] == "900"
    assert argv[argv.index("--run-dir") + 1] == str(tmp_path / "run")
    listen = argv[argv.index("--router-listen") + 1]
    assert spec.zenoh.connect == [listen] and spec.zenoh.mode == "client"

    real = make_study(tmp_path / "r", kind="real", up_args=("--no-router", "--connect", "tcp/10.0.0.5:7447")).plan()
    spec = world_spec(
        real, page_file=tmp_path / "p", run_dir=tmp_path / "run", namespace="lab", method="arroch", seed=3
    )
    assert spec.argv[spec.argv.index("--doors") + 1] == "sensor" and "--camera" not in spec.argv
    assert "--router-listen" not in spec.argv and spec.zenoh.connect == ["tcp/10.0.0.5:7447"]

    secured = make_study(tmp_path / "s", up_args=("--zenoh-config-dir", "/etc/arroch/zenoh")).plan()
    spec = world_spec(secured, page_file=tmp_path / "p", run_dir=tmp_path / "r", namespace="n", method="arroch", seed=1)
    assert spec.zenoh.config_file == "/etc/arroch/zenoh/supervisor.json5" and "--router-listen" not in spec.argv

    given = ZenohOptions(mode="client", connect=["tcp/10.1.1.1:7447"], explicit={"connect"})
    spec = world_spec(
        virtual,
        page_file=tmp_path / "p",
        run_dir=tmp_path / "r",
        namespace="n",
        method="arroch",
        seed=1,
        runner_zenoh=given,
    )
    assert spec.zenoh is given and spec.argv[-3:] == ["--no-router", "--connect", "tcp/10.1.1.1:7447"]


def test_a_world_without_the_participant_mode_is_refused(tmp_path: Path) -> None:
    plan = make_study(tmp_path).plan()
    common = {"page_file": tmp_path / "p", "run_dir": tmp_path / "r", "namespace": "n", "method": "arroch", "seed": 1}
    with pytest.raises(ValueError, match="does not take --human"):
        world_spec(plan, **common, takes=set(NEEDED) - {"--human"})
    with pytest.raises(ValueError, match="does not take --time-limit"):
        world_spec(plan, **common, takes=set(NEEDED) - {"--time-limit"})
    spec = world_spec(plan, **common, takes=set(NEEDED))
    assert "--time-limit" in spec.argv and "--human" in spec.argv
    assert up_options(FAKE_UP.split()) >= {"--human", "--time-limit", "--study-trial", "--linger"}
    assert up_options([sys.executable, "-c", "raise SystemExit(3)"]) is None  # cannot say: everything is given


def test_a_taken_console_port_leaves_the_trial_untouched(tmp_path: Path) -> None:
    folder = make_study(tmp_path)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        args = run_args(tmp_path, "--participant", "P01", "--console-port", port, "--up-command", FAKE_UP)
        assert study_run.main(args) == 2
    assert not folder.trial_dir("P01", "P01-T1-arroch").exists()


def test_arroch_study_run_is_a_command() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "study", "run", "--help"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert "--participant PID" in done.stdout and "--console-port N" in done.stdout and "--retry" in done.stdout


# ---------------------------------------------------------------------------- log.jsonl and answers


def stamped(msg: Any, t: float, src: str = "sim-1", seq: int = 1) -> Any:
    msg.stamp, msg.src, msg.seq = t, src, seq
    return msg


def test_the_log_writes_each_message_once_per_change_in_the_layout_format(tmp_path: Path) -> None:
    trial_log = TrialLog(tmp_path / "log.jsonl")
    human = HumanState(mode="participant", place="desk", doors=["d1"], x=1.0)
    assert trial_log.record(stamped(human, 1.0), "human/state", wall=1000.0)
    moved = HumanState(mode="participant", place="desk", doors=["d1"], x=2.0)  # only her pose changed
    assert not trial_log.record(stamped(moved, 1.5), "human/state")
    assert trial_log.record(stamped(HumanState(mode="participant", place="to_door", door="d1"), 2.0), "human/state")
    door = DoorState(door="d1", open=True, by="human")
    assert trial_log.record(stamped(door, 3.0), "door/d1/state")
    assert not trial_log.record(stamped(DoorState(door="d1", open=True, by="human"), 4.0), "door/d1/state")
    assert trial_log.record(stamped(DoorState(door="d2", open=True, by="human"), 4.0), "door/d2/state")  # other key
    assert trial_log.record(stamped(ConstraintSet(version=1), 4.5), "constraints")
    assert not trial_log.record(stamped(ConstraintSet(version=1), 4.6), "constraints")
    act = ParticipantAction(participant="P01", trial="T", act="open_door", door="d1", wall=1234.5)
    assert trial_log.record(stamped(act, 5.0), "participant/action", wall=1001.0)
    assert trial_log.record(
        stamped(ParticipantAction(participant="P01", act="view", view="ar"), 5.1), "participant/action"
    )
    assert trial_log.record(stamped(Event(kind="mission_done", data={"completed": True}), 6.0), "event")
    assert trial_log.record(stamped(StudyControl(command="pause", reason="x"), 6.5), "study/control")
    assert not trial_log.record(stamped(StudyControl(command="pause", reason="x"), 6.6), "study/control")  # said again
    trial_log.close()
    assert (
        trial_log.record(stamped(Event(kind="human_done", data={"task_duration": None}), 7.0), "event") is False
    )  # closed: counted, not raised
    assert trial_log.failed == 1

    lines = list(read_jsonl(tmp_path / "log.jsonl"))
    assert [(line["key"], line["type"]) for line in lines] == [
        ("human/state", "HumanState"),
        ("human/state", "HumanState"),
        ("door/d1/state", "DoorState"),
        ("door/d2/state", "DoorState"),
        ("constraints", "ConstraintSet"),
        ("participant/action", "ParticipantAction"),
        ("participant/action", "ParticipantAction"),
        ("event", "Event"),
        ("study/control", "StudyControl"),
    ]
    first, opened = lines[0], lines[5]
    assert (first["t"], first["wall"], first["place"], first["src"]) == (1.0, 1000.0, "desk", "sim-1")
    assert (opened["t"], opened["wall"], opened["act"], opened["door"], opened["sender_wall"]) == (
        5.0,
        1001.0,
        "open_door",
        "d1",
        1234.5,
    )
    assert lines[7]["data"] == {"completed": True} and lines[7]["kind"] == "mission_done"


def test_answers_are_kept_only_when_complete_and_on_their_scale(tmp_path: Path) -> None:
    q = {"Q1": 4, "Q2": 5, "Q3": 3, "Q4": 4, "Q5": 1}
    asked = ["arroch-q", "nasa-tlx"]
    assert check_answers("arroch-q", q, asked) == ""
    assert "off the arroch-q scale" in check_answers("arroch-q", {**q, "Q2": 6}, asked)
    assert "missing Q5" in check_answers("arroch-q", {k: v for k, v in q.items() if k != "Q5"}, asked)
    assert "unknown Q9" in check_answers("arroch-q", {**q, "Q9": 2}, asked)
    assert "not one this study asks" in check_answers("nasa-tlx", {}, ["arroch-q"])
    tlx = {"mental": 55, "physical": 10, "temporal": 40, "performance": 20, "effort": 50, "frustration": 100}
    assert check_answers("nasa-tlx", tlx, asked) == ""
    assert "6 scales" in check_answers("nasa-tlx", {"mental": 5}, asked)

    book = Questionnaires(tmp_path / "questionnaire.json", asked)
    assert book.take(QuestionnaireAnswers(participant="P01", instrument="arroch-q", answers={**q, "Q1": 0}))
    assert not (tmp_path / "questionnaire.json").exists() and book.missing == asked
    assert book.take(QuestionnaireAnswers(participant="P01", instrument="arroch-q", answers=q)) == ""
    assert not book.complete and book.missing == ["nasa-tlx"]
    assert book.take(QuestionnaireAnswers(participant="P01", instrument="nasa-tlx", answers=tlx)) == ""
    assert book.complete
    assert read_json(tmp_path / "questionnaire.json") == {"arroch-q": q, "nasa-tlx": tlx}


# ---------------------------------------------------------------------------- the trial's logic (no Zenoh)


class StubService:
    """What TrialRun asks of its service, recorded."""

    src = "study-1"

    def __init__(self) -> None:
        self.sent: list[tuple] = []
        self.stopped = False

    def send_control(self, command: str, reason: str = "") -> None:
        self.sent.append(("control", command, reason))

    def send_mark(self, note: str) -> None:
        self.sent.append(("mark", note))

    def send_door(self, door: str, is_open: bool) -> None:
        self.sent.append(("door", door, is_open))

    def every(self, *args: Any, **kwargs: Any) -> None:
        pass

    def stop(self) -> None:
        self.stopped = True


class StubWorld:
    def __init__(self) -> None:
        self.alive = True

    def running(self) -> bool:
        return self.alive

    def urls_settled(self) -> list[str]:
        return []

    def describe_exit(self) -> str:
        return "exited with code 3"

    def returncode(self) -> int | None:
        return None if self.alive else 3

    def last_lines(self) -> list[str]:
        return ["boom"]


def trial_run(tmp_path: Path, *, consent: bool, kind: str = "virtual") -> tuple[TrialRun, StubService, StubWorld]:
    folder = make_study(tmp_path, kind=kind)
    progress = TrialProgress(
        participant="P01", trial="P01-T1-arroch", condition="arroch", attempt=1, world=kind, questionnaires=["arroch-q"]
    )
    world = StubWorld()
    run = TrialRun(
        folder=folder,
        participant="P01",
        trial="P01-T1-arroch",
        world_kind=kind,
        world=world,  # type: ignore[arg-type]
        progress=progress,
        trial_log=TrialLog(folder.log_file("P01", "P01-T1-arroch")),
        questionnaires=Questionnaires(folder.questionnaire_file("P01", "P01-T1-arroch"), ["arroch-q"]),
        consent_required=consent,
        consent_sha256="abc",
    )
    service = StubService()
    run.attach(service)  # type: ignore[arg-type]
    return run, service, world


def act(act: str, participant: str = "P01", **fields: Any) -> ParticipantAction:
    return stamped(
        ParticipantAction(participant=participant, trial="P01-T1-arroch", act=act, **fields), 1.0, "tablet-1"
    )


def command(run: TrialRun, kind: str, **args: Any) -> Any:
    future = run.submit(kind, **args)
    run.tick()
    return future.result(timeout=1)


def test_the_world_is_held_paused_until_she_consents(tmp_path: Path) -> None:
    run, service, _ = trial_run(tmp_path, consent=True)
    run.tick()
    assert service.sent == [("control", "pause", "waiting for her consent")]  # before anything is heard
    run.tick()
    assert len(service.sent) == 1  # not again within HOLD_PERIOD
    run.on_message(stamped(HumanState(paused=True), 0.0), "human/state")
    run._last_control = 0.0
    run.tick()
    assert len(service.sent) == 1  # the world says it is paused: nothing more to say
    with pytest.raises(CommandRefused, match="consent"):
        command(run, "resume")
    run.on_message(act("consent", note="maybe"), "participant/action")  # neither given nor refused: dropped
    assert run.consent == "pending" and run.drops["note"] == 1
    run.on_message(act("consent", note="given"), "participant/action")
    assert service.sent[-1] == ("control", "resume", "")
    consent = read_json(run.folder.consent_file("P01"))
    assert consent["consented"] is True and consent["form_sha256"] == "abc"
    assert run.outcome is None


def test_consent_given_before_the_world_took_the_pauses_still_resumes_it(tmp_path: Path) -> None:
    # Under load the world may not have heard the pauses said while she read the form: its HumanState
    # still says "not paused" when she consents. A resume goes out at once all the same (controls
    # arrive in order: the pauses land first, then the resume), and it is said again while the world
    # shows itself paused.
    run, service, _ = trial_run(tmp_path, consent=True)
    run.tick()
    run.on_message(stamped(HumanState(paused=False), 0.0), "human/state")
    assert service.sent == [("control", "pause", "waiting for her consent")]
    run.on_message(act("consent", note="given"), "participant/action")
    assert service.sent[-1] == ("control", "resume", "")
    run.on_message(stamped(HumanState(paused=True), 0.0), "human/state")  # the late pause taken
    run._last_control = 0.0
    run.tick()
    assert service.sent[-1] == ("control", "resume", "") and len(service.sent) == 3
    run.on_message(stamped(HumanState(paused=False), 0.0), "human/state")
    run._last_control = 0.0
    run.tick()
    assert len(service.sent) == 3  # the world runs: nothing more to say


def test_refused_consent_ends_the_trial_and_aborts_the_world(tmp_path: Path) -> None:
    run, service, _ = trial_run(tmp_path, consent=True)
    run.on_message(act("consent", note="refused"), "participant/action")
    assert run.outcome == ("incomplete", "consent refused") and run.consent_ended == "consent refused"
    assert ("control", "abort", "consent refused") in service.sent
    assert read_json(run.folder.consent_file("P01"))["consented"] is False


def test_messages_of_another_participant_are_dropped_and_counted(tmp_path: Path) -> None:
    run, _, _ = trial_run(tmp_path, consent=False)
    run.on_message(act("task_done", participant="P09"), "participant/action")
    other = stamped(QuestionnaireAnswers(participant="P01", trial="P01-T9", instrument="arroch-q"), 1.0)
    run.on_message(other, "participant/answers")
    run.on_message(act("task_done"), "participant/action")
    run.log.close()
    lines = list(read_jsonl(run.log.path))
    assert [line["act"] for line in lines] == ["task_done"] and lines[0]["participant"] == "P01"
    assert run.drops == {"participant": 1, "trial": 1} and run.progress.snapshot()["dropped"] == 2


def test_the_trial_is_complete_once_the_mission_is_done_and_her_answers_came(tmp_path: Path) -> None:
    run, service, _ = trial_run(tmp_path, consent=False)
    answers = QuestionnaireAnswers(
        participant="P01", trial="P01-T1-arroch", instrument="arroch-q", answers={f"Q{i}": 3 for i in range(1, 6)}
    )
    with pytest.raises(CommandRefused, match="still running"):
        command(run, "end")
    run.on_message(stamped(answers, 2.0), "participant/answers")
    run.tick()
    assert run.outcome is None  # the mission goes on
    run.on_message(stamped(Event(kind="mission_done", data={"completed": True}), 3.0), "event")
    run.tick()
    assert run.outcome == ("complete", "") and service.stopped


def test_console_commands_reach_the_world_or_say_why_not(tmp_path: Path) -> None:
    run, service, world = trial_run(tmp_path, consent=False)
    assert command(run, "mark", note="  she laughs  ") == {"marked": "she laughs"}
    assert service.sent[-1] == ("mark", "she laughs")
    with pytest.raises(CommandRefused, match="note"):
        command(run, "mark", note=" ")
    assert command(run, "pause") == {"paused": True} and service.sent[-1][:2] == ("control", "pause")
    assert command(run, "resume") == {"paused": False}
    with pytest.raises(CommandRefused, match="virtual world"):
        command(run, "door", door="d1", open=True)
    with pytest.raises(CommandRefused, match="reason"):
        command(run, "abort", reason="")
    assert command(run, "abort", reason="she felt unwell") == {"aborted": "she felt unwell"}
    assert run.outcome == ("incomplete", "aborted by the experimenter: she felt unwell")
    assert service.sent[-1] == ("control", "abort", "aborted by the experimenter: she felt unwell")
    with pytest.raises(CommandRefused, match="ended"):
        command(run, "mark", note="late")


def test_a_real_worlds_door_is_reported_by_the_console(tmp_path: Path) -> None:
    run, service, _ = trial_run(tmp_path, consent=False, kind="real")
    run.on_message(stamped(HumanState(mode="participant", doors=["d1"]), 1.0), "human/state")
    assert command(run, "door", door="d1", open=True) == {"door": "d1", "open": True}
    assert service.sent[-1] == ("door", "d1", True)
    with pytest.raises(CommandRefused, match="not one of hers"):
        command(run, "door", door="d7", open=True)


def test_a_world_that_stops_before_the_mission_ends_leaves_the_trial_incomplete(tmp_path: Path) -> None:
    run, _, world = trial_run(tmp_path, consent=False)
    world.alive = False
    run.tick()
    assert run.outcome == ("incomplete", "the world stopped before the mission ended: arroch up exited with code 3")


# ---------------------------------------------------------------------------- whole trials (real processes)


def start_runner(spawn, study: Path, *extra: str, scenario: str) -> Proc:  # noqa: ANN001
    argv = [sys.executable, "-m", "services.study.run", str(study), "--participant", "P01", *extra]
    return spawn(argv + ["--up-command", FAKE_UP, "--stop-timeout", "5"], env={"FAKE_UP_SCENARIO": scenario})


def acts(lines: list[dict]) -> list[str]:
    return [line["act"] for line in lines if line["type"] == "ParticipantAction"]


def heard(folder: StudyFolder, tid: str) -> list[dict]:
    run = folder.latest_run("P01", tid)
    assert run is not None
    return list(read_jsonl(run / "heard.jsonl"))


def wait_gone(pid: int, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


@pytest.mark.integration
def test_a_whole_trial_with_consent_is_recorded_and_complete(tmp_path: Path, spawn) -> None:  # noqa: ANN001
    folder = make_study(tmp_path)
    runner = start_runner(spawn, tmp_path, scenario="complete")
    assert runner.wait(40) == 0, runner.output
    out = runner.output
    assert "console: http://127.0.0.1:" in out and "https://127.0.0.1:9/?token=fake-token_123" in out
    assert "P01-T1-arroch complete (attempt 1); mission completed at t=321.5 s; team 321.5 s; her task 250.0 s" in out

    state = read_json(folder.trial_dir("P01", "P01-T1-arroch") / "trial.json")
    assert (state["status"], state["attempt"], state["reason"]) == ("complete", 1, "")
    assert state["ended"] > state["started"]
    assert read_json(folder.trial_dir("P01", "P01-T1-arroch") / "page.json")["consent"]["required"] is True
    consent = read_json(folder.consent_file("P01"))
    assert consent["consented"] is True and consent["form_sha256"] == hashlib.sha256(CONSENT.encode()).hexdigest()
    assert read_json(folder.questionnaire_file("P01", "P01-T1-arroch")) == {
        "arroch-q": {"Q1": 4, "Q2": 5, "Q3": 3, "Q4": 4, "Q5": 2}
    }

    lines = list(read_jsonl(folder.log_file("P01", "P01-T1-arroch")))
    assert acts(lines) == ["consent", "view", "puzzle_move", "go_to_door", "open_door", "puzzle_move", "task_done"]
    assert [line["kind"] for line in lines if line["type"] == "Event"] == [
        "door_opened",
        "delivered",
        "human_done",
        "mission_done",
    ]
    places = [(line["place"], line["paused"], line["task_done"]) for line in lines if line["type"] == "HumanState"]
    assert ("desk", True, False) in places[:2]  # held for her consent (the hold may come before her first state)
    assert places[-6:] == [
        ("desk", False, False),  # resumed once she consented
        ("to_door", False, False),
        ("at_door", False, False),
        ("back", False, False),
        ("desk", False, False),
        ("desk", False, True),
    ]
    assert sum(line["type"] == "DoorState" for line in lines) == 1  # repeated state: once
    assert sum(line["type"] == "ConstraintSet" for line in lines) == 1
    answers = [line for line in lines if line["type"] == "QuestionnaireAnswers"]
    assert len(answers) == 1 and answers[0]["answers"]["Q1"] == 4  # the off-scale one was dropped
    assert all(line["participant"] == "P01" for line in lines if "participant" in line)  # P99's act dropped
    controls = [line["command"] for line in lines if line["type"] == "StudyControl"]
    assert controls[0] == "pause" and controls[-1] == "resume"
    order = [line["type"] + ":" + (line.get("act") or line.get("command") or "") for line in lines]
    assert order.index("StudyControl:resume") > order.index("ParticipantAction:consent")
    # The world was told to pause before she was asked, and to resume once she had consented.
    told = [h["control"] for h in heard(folder, "P01-T1-arroch") if h["type"] == "StudyControl"]
    assert told[0] == "pause" and told[-1] == "resume"
    run = folder.latest_run("P01", "P01-T1-arroch")
    assert (run / "metrics.json").exists() and (run / "run.json").exists()  # up was stopped, cleanly
    assert wait_gone(int((run / "pid").read_text()))
    assert "consent" in (folder.trial_dir("P01", "P01-T1-arroch") / "runner.log").read_text()


@pytest.mark.integration
def test_refused_consent_ends_her_trials(tmp_path: Path, spawn) -> None:  # noqa: ANN001
    folder = make_study(tmp_path)
    runner = start_runner(spawn, tmp_path, scenario="refuse")
    assert runner.wait(40) == 1, runner.output
    for tid in ("P01-T1-arroch", "P01-T2-map"):
        state = read_json(folder.trial_dir("P01", tid) / "trial.json")
        assert (state["status"], state["reason"]) == ("incomplete", "consent refused"), tid
    assert read_json(folder.consent_file("P01"))["consented"] is False
    told = [h["control"] for h in heard(folder, "P01-T1-arroch") if h["type"] == "StudyControl"]
    assert "abort" in told
    rerun = start_runner(spawn, tmp_path, scenario="refuse")
    assert rerun.wait(20) == 1 and "consent refused" in rerun.output and "--retry" in rerun.output


@pytest.mark.integration
def test_a_crashing_world_leaves_the_trial_incomplete_with_its_reason(tmp_path: Path, spawn) -> None:  # noqa: ANN001
    folder = make_study(tmp_path)
    consent = {"participant": "P01", "consented": True, "wall": 1.0, "form_sha256": "x"}
    write_json(folder.consent_file("P01"), consent)
    runner = start_runner(spawn, tmp_path, scenario="crash")
    assert runner.wait(40) == 1, runner.output
    state = read_json(folder.trial_dir("P01", "P01-T1-arroch") / "trial.json")
    assert state["status"] == "incomplete"
    assert state["reason"] == "the world stopped before the mission ended: arroch up exited with code 3"
    assert read_json(folder.trial_dir("P01", "P01-T1-arroch") / "page.json")["consent"] == {
        "required": False,
        "text": "",
    }
    assert "the sim crashed" in runner.output  # up's last words are shown


@pytest.mark.integration
def test_sigterm_mid_trial_stops_the_world_and_marks_the_trial_incomplete(tmp_path: Path, spawn) -> None:  # noqa: ANN001
    folder = make_study(tmp_path)
    write_json(folder.consent_file("P01"), {"participant": "P01", "consented": True, "wall": 1.0, "form_sha256": "x"})
    runner = start_runner(spawn, tmp_path, scenario="hang")
    runner.wait_for("tablet page", timeout=30)
    log_file = folder.log_file("P01", "P01-T1-arroch")
    deadline = time.monotonic() + 20
    while not (log_file.exists() and "HumanState" in log_file.read_text()):
        assert time.monotonic() < deadline, runner.output
        time.sleep(0.1)
    assert read_json(folder.trial_dir("P01", "P01-T1-arroch") / "trial.json")["status"] == "running"
    fake_pid = int((folder.latest_run("P01", "P01-T1-arroch") / "pid").read_text())
    os.kill(runner.popen.pid, signal.SIGTERM)  # the runner alone: it must stop the world itself
    assert runner.wait(30) == 128 + signal.SIGTERM, runner.output
    state = read_json(folder.trial_dir("P01", "P01-T1-arroch") / "trial.json")
    assert state["status"] == "incomplete" and state["reason"] == "interrupted: the runner received SIGTERM"
    assert wait_gone(fake_pid), "the stand-in world outlived the runner"
    assert (folder.latest_run("P01", "P01-T1-arroch") / "run.json").exists()  # stopped by SIGTERM, not killed
    assert any(line["type"] == "HumanState" for line in read_jsonl(log_file))  # what was heard is kept
    again = start_runner(spawn, tmp_path, "--dry-run", scenario="hang")
    assert again.wait(20) == 1 and "--retry" in again.output
