"""The study page (``arroch tablet --study-trial FILE``): its puzzle, its trial logic, and the page
itself in a real headless Chromium against a real server process and a real Zenoh router.

Unit tests: the puzzle (seeded and deterministic, a different shuffle per seed, the same size and
difficulty, moves, completion, refusals), its picture, the trial file, the questionnaires, and the
trial's judgement of requests (:class:`StudyController`).

Integration tests: a scripted participant (:mod:`tests.tablet.study_driver`) does a whole ARROCH
trial on the page while a test client plays the simulator on Zenoh (HumanState, Clock, door
states, mission_done) and listens on ``participant/*``; the map condition with real doors, a pause
and the experimenter's early questionnaire; malformed and senseless requests from a raw WebSocket;
bad trial files.
"""

from __future__ import annotations

import asyncio
import json
import queue
import threading
import time
from pathlib import Path
from typing import Any

import aiohttp
import numpy as np
import pytest

from protocol.codec import decode
from protocol.messages import (
    Clock,
    DoorState,
    Event,
    HumanState,
    ParticipantAction,
    QuestionnaireAnswers,
)
from services.ar_client.web.puzzle import MoveRefused, Puzzle, shuffle
from services.ar_client.web.puzzle_picture import PIECE_PX, picture, picture_png
from services.ar_client.web.questionnaire import ARROCH_Q, NASA_TLX, AnswersRefused, check_answers
from services.ar_client.web.study import StudyController
from services.ar_client.web.study_store import ProgressStore, progress_path
from services.ar_client.web.study_trial import TrialFileError, load_trial, parse_trial
from services.ar_client.web.study_wire import (
    AnswersSubmission,
    ConsentAnswer,
    DoorRequest,
    PuzzleMoveRequest,
    ViewChange,
)
from tests.conftest import TestClient
from tests.procs import ROOT, arroch, restrictor_argv
from tests.tablet.helpers import insecure, run, start_tablet, tablet_camera
from tests.tablet.study_driver import StudyPageDriver

DOOR = "d_storage"  # the office site's door the human operates
CONSENT_TEXT = (
    "# Consent\n\nYou will solve a puzzle while robots deliver objects.\n\n"
    "- You may stop at any time.\n- Data are pseudonymous."
)
Q_ANSWERS = {"Q1": 5, "Q2": 4, "Q3": 2, "Q4": 3, "Q5": 5}
TLX_ANSWERS = {"mental": 35, "physical": 5, "temporal": 60, "performance": 20, "effort": 45, "frustration": 0}


def trial_data(**changes: Any) -> dict[str, Any]:
    data: dict[str, Any] = {
        "participant": "P03",
        "trial": "P03-T1-arroch",
        "condition": "arroch",
        "door_control": "virtual",
        "puzzle": {"seed": 123, "rows": 4, "cols": 4},
        "questionnaires": ["arroch-q", "nasa-tlx"],
        "consent": {"required": True, "text": CONSENT_TEXT},
    }
    data.update(changes)
    return data


def write_trial(folder: Path, **changes: Any) -> Path:
    data = trial_data(**changes)
    path = folder / f"{data['trial']}.json"
    path.write_text(json.dumps(data))
    return path


def solve_moves(slots: list[int]) -> list[tuple[int, int]]:
    """Swaps (piece, other) that solve an arrangement, each sending one piece home."""
    slots = list(slots)
    moves = []
    for s in range(len(slots)):
        while slots[s] != s:
            piece, other = s, slots[s]  # bring piece s home from wherever it lies
            a = slots.index(piece)
            slots[a], slots[s] = other, piece
            moves.append((piece, other))
    return moves


# =========================================================================== the puzzle


def test_shuffle_is_seeded_deterministic_and_one_cycle_through_every_piece():
    first = shuffle(123, 16)
    assert first == shuffle(123, 16) == Puzzle(123, 4, 4).slots
    # Pinned: the same seed must give the same puzzle on every machine and Python version.
    assert first == [2, 9, 15, 7, 5, 8, 12, 10, 6, 4, 13, 3, 14, 0, 11, 1]
    assert sorted(first) == list(range(16))
    # One cycle through all pieces: nothing starts in place, and the fewest swaps is always n - 1.
    seen, piece = set(), 0
    while piece not in seen:
        seen.add(piece)
        piece = first[piece]
    assert len(seen) == 16 and Puzzle(123, 4, 4).placed == 0


def test_different_seeds_shuffle_differently_at_the_same_size_and_difficulty():
    arrangements = {tuple(Puzzle(seed, 4, 4).slots) for seed in range(60)}
    assert len(arrangements) == 60
    for seed in range(60):
        p = Puzzle(seed, 4, 4)
        assert (p.rows, p.cols, p.total, p.placed) == (4, 4, 16, 0)
        assert len(solve_moves(p.slots)) == 15  # the same difficulty for every seed
    assert Puzzle(5, 3, 5).total == 15 and Puzzle(5, 3, 5).slots != Puzzle(6, 3, 5).slots


def test_moves_progress_and_completion():
    p = Puzzle(123, 4, 4)
    moves = solve_moves(p.slots)
    for k, (piece, other) in enumerate(moves, 1):
        move = p.swap(piece, other)
        assert move.correct and move.piece == piece and move.moves == k and move.total == 16
        assert move.placed == p.placed and move.done == (k == len(moves))
    assert p.done and p.placed == 16 and p.to_json()["done"] is True


def test_refused_moves_change_nothing():
    p = Puzzle(123, 4, 4)
    before = list(p.slots)
    for piece, other, words in (
        (16, 0, "no piece 16"),
        (-1, 0, "no piece -1"),
        (3, 99, "no piece 99"),
        (3, 3, "itself"),
    ):
        with pytest.raises(MoveRefused, match=words):
            p.swap(piece, other)
    assert p.slots == before and p.moves == 0
    piece, other = solve_moves(p.slots)[0]
    p.swap(piece, other)
    with pytest.raises(MoveRefused, match=f"piece {piece} .* locked"):
        p.swap(piece, (piece + 1) % 16)
    for piece, other in solve_moves(p.slots):
        p.swap(piece, other)
    with pytest.raises(MoveRefused, match="already complete"):
        p.swap(0, 1)


def test_resume_takes_only_a_saved_state_of_the_same_puzzle():
    p = Puzzle(123, 4, 4)
    p.swap(*solve_moves(p.slots)[0])
    saved = json.loads(json.dumps(p.to_json()))
    resumed = Puzzle.resume(123, 4, 4, saved)
    assert resumed.slots == p.slots and resumed.moves == 1
    assert Puzzle.resume(124, 4, 4, saved).slots == Puzzle(124, 4, 4).slots  # another seed: fresh
    assert Puzzle.resume(123, 4, 4, {**saved, "slots": [0] * 16}).moves == 0  # damaged: fresh
    assert Puzzle.resume(123, 4, 4, None).slots == Puzzle(123, 4, 4).slots


def test_picture_is_drawn_from_the_seed():
    a = picture(123, 4, 4)
    assert a.shape == (4 * PIECE_PX, 4 * PIECE_PX, 3)
    assert np.array_equal(a, picture(123, 4, 4)) and picture_png(123, 4, 4) == picture_png(123, 4, 4)
    assert np.abs(a.astype(int) - picture(124, 4, 4)).mean() > 20  # another trial, another picture
    assert picture(9, 3, 5).shape == (3 * PIECE_PX, 5 * PIECE_PX, 3)
    # Every piece differs from every other: one can tell where each goes.
    blocks = a.reshape(4, PIECE_PX, 4, PIECE_PX, 3).transpose(0, 2, 1, 3, 4).reshape(16, -1).astype(float)
    d = np.linalg.norm(blocks[:, None] - blocks[None], axis=2)
    assert d[~np.eye(16, dtype=bool)].min() > 1000


# =========================================================================== the trial file and questionnaires


def test_trial_file_is_read_and_bad_ones_name_file_and_field(tmp_path):
    trial = load_trial(write_trial(tmp_path))
    assert trial.participant == "P03" and trial.robots_view == "ar" and trial.feedback
    assert parse_trial(trial_data(condition="map")).robots_view == "map"
    assert parse_trial(trial_data(condition="no-feedback")).feedback is False
    minimal = {k: v for k, v in trial_data().items() if k not in ("door_control", "questionnaires", "consent")}
    assert parse_trial(minimal).questionnaires == ["arroch-q"] and not parse_trial(minimal).consent.required
    bad = {
        "condition": (trial_data(condition="vr"), "condition"),
        "rows": (trial_data(puzzle={"seed": 1, "rows": 40, "cols": 4}), "puzzle.rows"),
        "seed": (trial_data(puzzle={"seed": -1, "rows": 4, "cols": 4}), "puzzle.seed"),
        "participant": (trial_data(participant="Jane Doe"), "participant"),
        "instrument": (trial_data(questionnaires=["sus"]), "questionnaires"),
        "twice": (trial_data(questionnaires=["arroch-q", "arroch-q"]), "questionnaires"),
        "consent": (trial_data(consent={"required": True, "text": " "}), "consent.text"),
        "unknown": ({**trial_data(), "conditon": "map"}, "conditon"),
        "missing": ({k: v for k, v in trial_data().items() if k != "puzzle"}, "puzzle"),
    }
    for name, (data, field) in bad.items():
        path = tmp_path / f"bad-{name}.json"
        path.write_text(json.dumps(data))
        with pytest.raises(TrialFileError) as err:
            load_trial(path)
        assert str(err.value).startswith(f"{path}: {field}"), (name, str(err.value))
    (tmp_path / "garbage.json").write_text("{not json")
    with pytest.raises(TrialFileError, match="garbage.json: not valid JSON"):
        load_trial(tmp_path / "garbage.json")
    with pytest.raises(TrialFileError, match="absent.json: cannot read"):
        load_trial(tmp_path / "absent.json")


def test_questionnaires_have_the_papers_wording_and_check_every_answer():
    assert [i.id for i in ARROCH_Q.items] == ["Q1", "Q2", "Q3", "Q4", "Q5"]
    assert ARROCH_Q.items[2].text == "I could focus on my task with minimal distraction from robot"
    assert dict(ARROCH_Q.labels) == {
        1: "Strongly disagree",
        2: "Somewhat disagree",
        3: "Neutral",
        4: "Somewhat agree",
        5: "Strongly agree",
    }
    assert NASA_TLX.values() == list(range(0, 101, 5))
    assert check_answers("arroch-q", Q_ANSWERS) == Q_ANSWERS
    assert check_answers("nasa-tlx", TLX_ANSWERS) == TLX_ANSWERS
    for answers, words in (
        ({**Q_ANSWERS, "Q3": 6}, "Q3: 6 is not on the scale 1 to 5"),
        ({**Q_ANSWERS, "Q3": 0}, "Q3: 0 is not on the scale"),
        ({k: v for k, v in Q_ANSWERS.items() if k != "Q4"}, "Q4 is not answered"),
        ({**Q_ANSWERS, "Q6": 3}, "no item 'Q6'"),
        ({**Q_ANSWERS, "Q1": True}, "not a whole number"),
    ):
        with pytest.raises(AnswersRefused, match=words):
            check_answers("arroch-q", answers)
    with pytest.raises(AnswersRefused, match="mental: 33 is not on the scale 0 to 100 in steps of 5"):
        check_answers("nasa-tlx", {**TLX_ANSWERS, "mental": 33})


def test_page_messages_of_the_study_are_shapes_checked_by_the_wire():
    from services.ar_client.web import wire

    assert wire.parse_text('{"type": "puzzle_move", "piece": 3, "other": 4, "wall": 1.5}') == PuzzleMoveRequest(
        piece=3, other=4, wall=1.5
    )
    assert wire.parse_text('{"type": "view", "view": "ar", "note": "hidden", "wall": 2}').note == "hidden"
    assert wire.parse_text('{"type": "feedback", "id": 1, "kind": "k", "params": {}, "wall": 3.5}').wall == 3.5
    for text, field in (
        ('{"type": "puzzle_move", "piece": "three", "other": 4, "wall": 1}', "piece"),
        ('{"type": "puzzle_move", "piece": 3, "other": 4}', "wall"),
        ('{"type": "view", "view": "vr", "wall": 1}', "view"),
        ('{"type": "consent", "answer": "maybe", "wall": 1}', "answer"),
        ('{"type": "door", "act": "fly", "wall": 1}', "act"),
        ('{"type": "answers", "answers": {"arroch-q": {"Q1": 3.5}}, "wall": 1}', "answers"),
        ('{"type": "answers", "answers": {}, "wall": 1}', "answers"),
        ('{"type": "door", "act": "open_door", "held": -1, "wall": 1}', "held"),
    ):
        with pytest.raises(wire.Violation) as err:
            wire.parse_text(text)
        assert err.value.code == wire.CLOSE_POLICY and field in err.value.reason, (text, err.value.reason)


# =========================================================================== the trial's judgement


class Recorder:
    def __init__(self) -> None:
        self.actions: list[ParticipantAction] = []
        self.answers: list[QuestionnaireAnswers] = []


def controller(tmp_path: Path | None = None, **changes: Any) -> tuple[StudyController, Recorder]:
    rec = Recorder()
    store = ProgressStore(tmp_path / "progress.json" if tmp_path else None)
    c = StudyController(
        parse_trial(trial_data(**changes)),
        publish_action=rec.actions.append,
        publish_answers=rec.answers.append,
        store=store,
    )
    return c, rec


def human(place: str = "desk", door: str = "", **kw: Any) -> HumanState:
    return HumanState(mode="participant", place=place, door=door, doors=[DOOR], open_time=3.0, **kw)


def test_requests_wait_for_consent_and_refusal_ends_the_trial_for_her():
    c, rec = controller()
    out = c.handle(PuzzleMoveRequest(piece=0, other=1, wall=10.0))
    assert out.refused == "the consent screen must be answered first" and not rec.actions
    assert c.handle(ConsentAnswer(answer="refused", wall=11.0)).changed
    assert [(a.act, a.note, a.participant, a.trial, a.wall) for a in rec.actions] == [
        ("consent", "refused", "P03", "P03-T1-arroch", 11.0)
    ]
    assert c.handle(ConsentAnswer(answer="given", wall=12.0)).refused == "consent was already answered (refused)"
    for msg in (PuzzleMoveRequest(piece=0, other=1, wall=13.0), ViewChange(view="puzzle", wall=13.0)):
        assert "experimenter takes over" in c.handle(msg).refused
    assert len(rec.actions) == 1 and c.counters["refused_puzzle_move"] == 2 and c.counters["refused_consent"] == 1


def test_moves_are_locked_away_from_the_desk_and_recorded_with_progress(tmp_path):
    c, rec = controller(tmp_path)
    c.handle(ConsentAnswer(answer="given", wall=1.0))
    c.human_changed(human("to_door", DOOR))
    piece, other = solve_moves(c.puzzle.slots)[0]
    assert "away from your desk" in c.handle(PuzzleMoveRequest(piece=piece, other=other, wall=2.0)).refused
    c.human_changed(human())
    assert c.handle(PuzzleMoveRequest(piece=99, other=other, wall=2.0)).refused.startswith("there is no piece 99")
    for k, (piece, other) in enumerate(solve_moves(c.puzzle.slots)):
        assert c.handle(PuzzleMoveRequest(piece=piece, other=other, wall=3.0 + k)).changed
    moves = [a for a in rec.actions if a.act == "puzzle_move"]
    assert len(moves) == 15 and all(m.correct for m in moves) and [m.placed for m in moves][-1] == 16
    assert rec.actions[-1].act == "task_done" and rec.actions[-1].placed == rec.actions[-1].total == 16
    # A restarted server resumes the trial from the saved progress.
    again, _ = controller(tmp_path)
    assert again.consent == "given" and again.puzzle.done and again.task_done


def test_door_requests_follow_where_she_is_and_the_hold_lasts_the_opening_time():
    c, rec = controller(consent={"required": False})
    assert "no word from the simulator" in c.handle(DoorRequest(act="go_to_door", door=DOOR, wall=1.0)).refused
    c.human_changed(human())
    c.clock_changed(Clock(time=5.0, mode="rate", rate=2.0))
    assert "not a door you operate" in c.handle(DoorRequest(act="go_to_door", door="d_lab", wall=1.0)).refused
    assert c.handle(DoorRequest(act="open_door", door=DOOR, held=9.0, wall=1.0)).refused.startswith("you can open")
    assert c.handle(DoorRequest(act="go_to_door", door=DOOR, wall=2.0)).refused is None
    assert "waiting for the simulator" in c.handle(DoorRequest(act="go_to_door", door=DOOR, wall=2.1)).refused
    c.human_changed(human("at_door", DOOR))
    # open_time 3 site s at rate 2: 1.5 wall s.
    assert "held 0.5 s of the 1.5 s" in c.handle(DoorRequest(act="open_door", door=DOOR, held=0.5, wall=3.0)).refused
    assert c.handle(DoorRequest(act="open_door", door=DOOR, held=1.5, wall=4.0)).refused is None
    c.human_changed(human("back", DOOR))
    assert "turn back only on the way to a door" in c.handle(DoorRequest(act="back_to_desk", wall=5.0)).refused
    c.human_changed(human())
    assert c.handle(DoorRequest(act="go_to_door", door=DOOR, wall=6.0)).refused is None
    c.human_changed(human("to_door", DOOR, paused=True))
    assert c.handle(DoorRequest(act="back_to_desk", wall=7.0)).refused == "paused by the experimenter"
    c.human_changed(human("to_door", DOOR))
    assert c.handle(DoorRequest(act="back_to_desk", wall=8.0)).refused is None
    assert [(a.act, a.door, a.wall) for a in rec.actions] == [
        ("go_to_door", DOOR, 2.0),
        ("open_door", DOOR, 4.0),
        ("go_to_door", DOOR, 6.0),
        ("back_to_desk", DOOR, 8.0),
    ]
    sensor, _ = controller(consent={"required": False}, door_control="sensor")
    sensor.human_changed(human())
    assert "open them by hand" in sensor.handle(DoorRequest(act="go_to_door", door=DOOR, wall=1.0)).refused


def test_views_feedback_and_answers_are_judged_by_the_condition():
    c, rec = controller(condition="map", consent={"required": False})
    assert "has no ar view" in c.handle(ViewChange(view="ar", wall=1.0)).refused
    assert c.handle(ViewChange(view="map", note="hidden", wall=2.0)).refused is None
    assert "no feedback in this trial's condition (map)" in c.feedback("door_unavailable", {"door": DOOR}, 3.0)
    answers = {"arroch-q": Q_ANSWERS, "nasa-tlx": TLX_ANSWERS}
    assert "opens when the trial has ended" in c.handle(AnswersSubmission(answers=answers, wall=4.0)).refused
    assert c.handle(AnswersSubmission(answers=answers, wall=4.0), early_questionnaire=True).changed
    assert "questionnaire is in" in c.handle(AnswersSubmission(answers=answers, wall=5.0)).refused
    assert [(a.instrument, a.answers, a.wall) for a in rec.answers] == [
        ("arroch-q", Q_ANSWERS, 4.0),
        ("nasa-tlx", TLX_ANSWERS, 4.0),
    ]
    a, rec_a = controller(consent={"required": False})
    a.mission_ended()
    bad = {"arroch-q": {**Q_ANSWERS, "Q2": 9}, "nasa-tlx": TLX_ANSWERS}
    assert "Q2: 9 is not on the scale" in a.handle(AnswersSubmission(answers=bad, wall=1.0)).refused
    assert "nasa-tlx is not answered" in a.handle(AnswersSubmission(answers={"arroch-q": Q_ANSWERS}, wall=1.0)).refused
    assert not rec_a.answers
    assert a.feedback("door_unavailable", {"door": DOOR, "minutes": 15}, 7.5) is None
    assert (rec_a.actions[-1].act, rec_a.actions[-1].door, rec_a.actions[-1].minutes, rec_a.actions[-1].note) == (
        "feedback",
        DOOR,
        15,
        "door_unavailable",
    )


# =========================================================================== in the browser


class FakeSim:
    """The simulator's side of a participant trial, on Zenoh: the clock at a rate, where she is
    (HumanState, a few times a second as the sim publishes it), her walk to the door and back on
    her go_to_door / open_door / back_to_desk, the door opening; mission_done on request."""

    def __init__(self, client: TestClient, *, rate: float = 2.0, open_time: float = 2.0, walk: float = 0.8) -> None:
        self.client = client
        self.rate = rate
        self.walk = walk
        self.state = HumanState(mode="participant", place="desk", doors=[DOOR], open_time=open_time, x=9.0, y=1.5)
        self.clock_paused = False
        self.heard: list[ParticipantAction] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._started = time.monotonic()
        self._arrive: tuple[float, str] | None = None  # (when, place) of the walk under way
        client._declared.append(client.session.declare_subscriber(client.keys.participant_action(), self._on_action))
        self._thread = threading.Thread(target=self._loop, name="fake-sim", daemon=True)

    def start(self) -> FakeSim:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2)

    def set(self, **changes: Any) -> None:
        with self._lock:
            for k, v in changes.items():
                setattr(self.state, k, v)
        self._publish()

    def mission_done(self) -> None:
        self.client.publish(self.client.keys.event(), Event(kind="mission_done"))

    def _on_action(self, sample) -> None:  # noqa: ANN001
        msg = decode(sample.payload.to_bytes(), ParticipantAction)
        self.heard.append(msg)
        now = time.monotonic()
        with self._lock:
            s = self.state
            if msg.act == "go_to_door" and s.place == "desk":
                s.place, s.door, s.x = "to_door", msg.door, 8.5
                self._arrive = (now + self.walk, "at_door")
            elif msg.act == "open_door" and s.place == "at_door":
                self.client.publish(self.client.keys.door_state(s.door), DoorState(door=s.door, open=True, by="human"))
                s.place = "back"
                self._arrive = (now + self.walk, "desk")
            elif msg.act == "back_to_desk" and s.place in ("to_door", "at_door"):
                s.place = "back"
                self._arrive = (now + self.walk, "desk")
        self._publish()

    def _publish(self) -> None:
        with self._lock:
            state = HumanState(
                **{
                    f: getattr(self.state, f)
                    for f in self.state.__struct_fields__
                    if f not in ("src", "seq", "stamp", "v")
                }
            )
        self.client.publish(self.client.keys.human_state(), state)

    def _loop(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                if self._arrive is not None and time.monotonic() >= self._arrive[0]:
                    place = self._arrive[1]
                    self.state.place = place
                    if place == "desk":
                        self.state.door, self.state.x = "", 9.0
                    self._arrive = None
            site_time = (time.monotonic() - self._started) * self.rate
            self.client.publish(
                self.client.keys.clock(), Clock(time=site_time, mode="rate", rate=self.rate, paused=self.clock_paused)
            )
            self._publish()
            self._stop.wait(0.2)


def collect_actions(client: TestClient) -> queue.Queue:
    return client.collect(client.keys.participant_action(), ParticipantAction)


def drain(q: queue.Queue) -> list:
    out = []
    while True:
        try:
            out.append(q.get_nowait()[0])
        except queue.Empty:
            return out


def wait_for(q: queue.Queue, predicate, seen: list, timeout: float = 10.0):  # noqa: ANN001
    """The first message satisfying ``predicate``; everything read on the way goes to ``seen``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            msg = q.get(timeout=max(0.01, deadline - time.monotonic()))[0]
        except queue.Empty:
            break
        seen.append(msg)
        if predicate(msg):
            return msg
    raise AssertionError(
        f"no matching message within {timeout} s; heard {[(m.act, m.view, m.note) for m in seen][-8:]}"
    )


def sim_camera_feed(client: TestClient, stop: threading.Event) -> None:
    """A plain grey picture on the sim's camera key at 4 Hz (nothing to localise: the stream itself is what counts)."""
    from services.sim.camera import frame_message

    camera = tablet_camera(width=320, height=240)
    msg = frame_message("simcam", np.full((240, 320, 3), 120, np.uint8), camera, gravity_noise_deg=None)
    while not stop.is_set():
        client.publish(client.keys.camera_frame("simcam"), msg)
        stop.wait(0.25)


@pytest.mark.integration
def test_arroch_trial_from_consent_to_questionnaire(router, namespace, client, spawn, browser, tmp_path):
    restrictor = spawn(restrictor_argv(namespace, router, tmp_path / "restrictor"), name="restrictor")
    trial_file = write_trial(tmp_path)
    server = start_tablet(
        spawn,
        router,
        namespace,
        tmp_path / "tablet",
        "--no-qr",
        "--camera-source",
        "sim:simcam",
        "--study-trial",
        str(trial_file),
    )
    assert "mode=" not in server.url  # the trial decides the page, not the URL
    actions = collect_actions(client)
    answers = client.collect(client.keys.questionnaire(), QuestionnaireAnswers)
    time.sleep(0.5)
    sim = FakeSim(client, rate=2.0, open_time=2.0).start()
    stop_feed = threading.Event()
    feed = threading.Thread(target=sim_camera_feed, args=(client, stop_feed), daemon=True)
    feed.start()
    heard: list[ParticipantAction] = []
    try:
        page = browser(window=(1280, 800))  # its console catches any Content Security Policy violation
        driver = StudyPageDriver(page)
        driver.open(server.url)
        # Consent first, and nothing else on screen.
        driver.wait("s.screen === 'consent'")
        consent = driver.text("#consent")
        assert consent.startswith("Consent") and "You may stop at any time." in consent and "null" not in consent
        assert not driver.visible("#main") and not driver.visible("#toggle-mode") and not driver.visible("#toggle-map")
        assert driver.consent()
        wait_for(actions, lambda m: m.act == "consent", heard)
        wait_for(actions, lambda m: m.act == "view" and m.view == "puzzle", heard)
        assert driver.visible("#puzzle-board") and driver.visible("#tabs") and driver.visible("#doorbar")
        assert not driver.visible("#toggle-mode") and not driver.visible("#stage") and not driver.visible("#panel")

        # A few moves, then the page is reloaded: the same arrangement comes back.
        assert driver.solve_puzzle(max_moves=3) == 3
        before = driver.state()["puzzle"]
        shown_before = driver.read_puzzle()
        page.navigate(server.url)
        resumed = driver.wait("s.puzzle && s.puzzle.picture && s.puzzle.shown.every((p) => p >= 0) && s.puzzle")
        assert resumed["slots"] == before["slots"] and resumed["moves"] == 3 and resumed["placed"] == before["placed"]
        assert driver.read_puzzle() == shown_before and driver.state()["screen"] == ""  # consent is not asked again

        # The robots: the sim's stream with the overlay and the feedback panel; the stream only while shown.
        frames_on_puzzle = page.evaluate("window.arroch.state().stream_frames")
        driver.switch("robots")
        wait_for(actions, lambda m: m.act == "view" and m.view == "ar", heard)
        page.wait_for("window.arroch.state().stream_frames > 2", timeout=15)
        assert frames_on_puzzle == 0
        assert driver.visible("#stage") and driver.visible("#panel") and not driver.visible("#mapbox")
        restrictor.wait_for("up on namespace", timeout=30)
        ack = driver.send_feedback("door_unavailable", door=DOOR, minutes=15)
        assert ack["status"] == "accepted", ack
        fb = wait_for(actions, lambda m: m.act == "feedback", heard)
        assert (fb.door, fb.minutes, fb.note) == (DOOR, 15, "door_unavailable")
        driver.switch("puzzle")
        wait_for(actions, lambda m: m.act == "view" and m.view == "puzzle", heard)

        # To the door: the puzzle locks while she is away.
        driver.go_to_door(DOOR)
        go = wait_for(actions, lambda m: m.act == "go_to_door", heard)
        assert go.door == DOOR
        driver.wait("s.puzzle.locked.includes('away from your desk')")
        assert driver.visible("#puzzle-lock") and "Walking to the door" in driver.text("#door-status")
        driver.wait_at_door()
        assert driver.state()["doors"]["need_s"] == pytest.approx(1.0)  # 2 site s at rate 2
        # Released early: nothing is sent, the page says why.
        driver.hold_open(0.35, release_early=True)
        driver.wait("s.doors.message.startsWith('Released after')")
        time.sleep(0.5)
        assert not [m for m in drain(actions) if m.act == "open_door"]
        held = driver.hold_open()
        opened = wait_for(actions, lambda m: m.act == "open_door", heard)
        assert opened.door == DOOR and held >= 1.0 and opened.note.startswith("held ")
        assert float(opened.note.split()[1]) >= 0.95
        driver.wait("s.human.place === 'desk' && !s.puzzle.locked")

        # The rest of the puzzle, as a person would; her task is done.
        driver.solve_puzzle()
        done = wait_for(actions, lambda m: m.act == "task_done", heard)
        assert done.placed == done.total == 16
        assert "Puzzle complete" in driver.text("#puzzle-progress")

        # The mission ends: the questionnaire, answered and submitted.
        sim.mission_done()
        driver.wait_for_questionnaire()
        assert "Q3. I could focus on my task with minimal distraction from robot" in driver.text("#questionnaire")
        assert "Strongly disagree" in driver.text("#questionnaire") and "Frustration" in driver.text("#questionnaire")
        driver.answer_questionnaire({"arroch-q": {**Q_ANSWERS, "Q5": 4}}, submit=False)
        assert page.evaluate("document.getElementById('q-submit').disabled") is True  # TLX not answered yet
        driver.answer_questionnaire({"arroch-q": Q_ANSWERS, "nasa-tlx": TLX_ANSWERS})
        got = {}
        for _ in range(2):
            msg, _key = answers.get(timeout=10)
            got[msg.instrument] = msg
        assert got["arroch-q"].answers == Q_ANSWERS and got["nasa-tlx"].answers == TLX_ANSWERS
        assert got["arroch-q"].participant == "P03" and got["arroch-q"].trial == "P03-T1-arroch"
        assert abs(got["arroch-q"].wall - time.time()) < 30
        assert "Thank you" in driver.text("#thanks") and not driver.visible("#bar") and not driver.visible("#main")
        assert not [t for t in page.console if "Content Security Policy" in t], page.console
        assert not page.page_errors, page.page_errors
    finally:
        stop_feed.set()
        sim.stop()
    heard += drain(actions)
    acts = [m.act for m in heard]
    assert acts[0] == "consent" and heard[0].note == "given"
    order = [a for a in acts if a in ("consent", "go_to_door", "open_door", "task_done", "feedback")]
    assert order == ["consent", "feedback", "go_to_door", "open_door", "task_done"], acts
    moves = [m for m in heard if m.act == "puzzle_move"]
    assert len(moves) == 15 and all(m.correct for m in moves) and moves[-1].placed == 16  # one move per piece
    assert all(m.participant == "P03" and m.trial == "P03-T1-arroch" and m.wall > 1e9 for m in heard)
    walls = [m.wall for m in heard]
    assert walls == sorted(walls)  # stamped when she acted, in the order she acted
    views = [m.view for m in heard if m.act == "view" and not m.note]
    assert views[:1] == ["puzzle"] and "ar" in views and "map" not in views
    assert progress_path(trial_file).exists()


@pytest.mark.integration
def test_map_condition_real_doors_pause_and_early_questionnaire(router, namespace, client, spawn, browser, tmp_path):
    trial_file = write_trial(
        tmp_path,
        trial="P04-T2-map",
        participant="P04",
        condition="map",
        door_control="sensor",
        consent={"required": False},
        questionnaires=["arroch-q"],
    )
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr", "--study-trial", str(trial_file))
    actions = collect_actions(client)
    answers = client.collect(client.keys.questionnaire(), QuestionnaireAnswers)
    time.sleep(0.5)
    sim = FakeSim(client).start()
    sim.set(mode="sensor")
    client.publish(client.keys.door_state(DOOR), DoorState(door=DOOR, open=False))
    heard: list[ParticipantAction] = []
    try:
        page = browser(window=(1280, 800))
        driver = StudyPageDriver(page)
        driver.open(server.url + "&mode=ar")  # a mode in the URL changes nothing: the trial decides
        wait_for(actions, lambda m: m.act == "view" and m.view == "puzzle", heard)
        assert driver.state()["screen"] == "" and driver.visible("#puzzle-board")
        # Real doors: their state, no buttons.
        driver.wait("s.doors.status === 'Doors:' && s.doors.buttons.length === 0")
        page.wait_for(f"document.querySelector('[data-door=\"{DOOR}\"]').textContent === '{DOOR} closed'")
        client.publish(client.keys.door_state(DOOR), DoorState(door=DOOR, open=True, by="sensor"))
        page.wait_for(f"document.querySelector('[data-door=\"{DOOR}\"]').textContent === '{DOOR} open'")
        # The Robots tab is the map: no camera, no stream, no feedback panel.
        driver.switch("robots")
        wait_for(actions, lambda m: m.act == "view" and m.view == "map", heard)
        state = page.evaluate("window.arroch.state()")
        assert state["mode"] == "map" and state["camera"] == "off" and state["video"] == [0, 0]
        assert driver.visible("#map") and not driver.visible("#stage") and not driver.visible("#panel")
        assert not driver.visible("#video") and not driver.visible("#entries")
        time.sleep(0.6)  # map updates come at most 4 times a second
        assert page.evaluate("document.getElementById('map').width") > 300
        # The experimenter pauses: an overlay says so, the puzzle is locked.
        sim.set(paused=True)
        driver.wait("s.screen === 'paused'")
        assert driver.visible("#paused") and "Paused by the experimenter" in driver.text("#paused")
        sim.set(paused=False)
        driver.wait("s.screen === ''")
        # Time away from the page is measured: another tab in front hides it, closing that shows it again.
        other = driver.hide_page()
        hidden = wait_for(actions, lambda m: m.act == "view" and m.note == "hidden", heard)
        driver.show_page(other)
        visible = wait_for(actions, lambda m: m.act == "view" and m.note == "visible", heard)
        assert hidden.view == visible.view == "map" and visible.wall >= hidden.wall
        # A trial ended by abort: the experimenter opens the questionnaire early.
        driver.open(server.url + "&questionnaire=1")
        driver.wait_for_questionnaire()
        assert not driver.visible("#q-submit") or page.evaluate("document.getElementById('q-submit').disabled")
        assert "Frustration" not in driver.text("#questionnaire")  # only the trial's own instruments
        driver.answer_questionnaire({"arroch-q": Q_ANSWERS})
        msg, _ = answers.get(timeout=10)
        assert (msg.participant, msg.trial, msg.instrument, msg.answers) == ("P04", "P04-T2-map", "arroch-q", Q_ANSWERS)
    finally:
        sim.stop()
    heard += drain(actions)
    assert not [m for m in heard if m.view == "ar"]


async def _study_socket(http: aiohttp.ClientSession, base: str, token: str):  # noqa: ANN202
    ws = await http.ws_connect(f"{base}/ws?token={token}", headers={"Origin": base})
    hello = await ws.receive_json(timeout=10)
    assert hello["type"] == "hello"
    return ws, hello


async def _reply(ws, kinds: tuple[str, ...] = ("refused", "study")) -> dict:  # noqa: ANN001
    """The next message of one of ``kinds`` (others skipped), or ``{"type": "closed", "code"}``."""
    while True:
        msg = await asyncio.wait_for(ws.receive(), 10)
        if msg.type != aiohttp.WSMsgType.TEXT:
            return {"type": "closed", "code": ws.close_code, "reason": msg.extra}
        data = json.loads(msg.data)
        if data["type"] in kinds:
            return data


@pytest.mark.integration
def test_bad_requests_are_refused_with_reasons_counted_and_the_server_lives(
    router, namespace, client, spawn, browser, tmp_path
):
    trial_file = write_trial(tmp_path, trial="P05-T1-nofb", participant="P05", condition="no-feedback")
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr", "--study-trial", str(trial_file))
    actions = collect_actions(client)
    time.sleep(0.5)
    wall = time.time()

    async def check() -> None:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            ws, hello = await _study_socket(http, server.base, server.token)
            study = hello["study"]
            assert hello["mode"] == "viewer" and study["condition"] == "no-feedback" and study["feedback"] is False
            assert study["consent"]["text"] == CONSENT_TEXT and len(study["instruments"]) == 2
            slots = study["puzzle"]["slots"]

            async def ask(message: dict) -> dict:
                await ws.send_str(json.dumps({**message, "wall": wall}))
                return await _reply(ws)

            assert (await ask({"type": "puzzle_move", "piece": slots[0], "other": slots[1]}))["reason"] == (
                "the consent screen must be answered first"
            )
            assert (await ask({"type": "consent", "answer": "given"}))["type"] == "study"
            refusals = {
                "no piece 999": {"type": "puzzle_move", "piece": 999, "other": slots[0]},
                "with itself": {"type": "puzzle_move", "piece": slots[0], "other": slots[0]},
                "has no map view": {"type": "view", "view": "map"},
                "no word from the simulator": {"type": "door", "act": "go_to_door", "door": DOOR},
                "opens when the trial has ended": {"type": "answers", "answers": {"arroch-q": Q_ANSWERS}},
            }
            for words, message in refusals.items():
                reply = await ask(message)
                assert reply["type"] == "refused" and words in reply["reason"], (words, reply)
            feedback = {"type": "feedback", "id": 1, "kind": "door_unavailable", "params": {"door": DOOR, "minutes": 5}}
            await ws.send_str(json.dumps(feedback))
            ack = await _reply(ws, ("ack",))
            assert ack["status"] == "refused" and "no feedback in this trial's condition" in ack["reason"]
            # Still served: a good move (piece 0 home, swapped with the piece in its slot) on the same socket.
            reply = await ask({"type": "puzzle_move", "piece": 0, "other": slots[0]})
            assert reply["type"] == "study" and reply["puzzle"]["moves"] == 1 and reply["puzzle"]["slots"][0] == 0
            # Malformed: wrong shape closes this socket only (1008, the field named).
            await ws.send_str(json.dumps({"type": "puzzle_move", "piece": "three", "other": 1, "wall": wall}))
            closed = await _reply(ws)
            assert closed["type"] == "closed" and closed["code"] == 1008 and "piece" in closed["reason"]
            ws2, hello2 = await _study_socket(http, server.base, server.token)
            assert hello2["study"]["puzzle"]["moves"] == 1  # the server lives, and kept the trial
            await ws2.send_str(json.dumps({"type": "answers", "answers": {"arroch-q": {"Q1": 3.5}}, "wall": wall}))
            assert (await _reply(ws2))["code"] == 1008

    run(check())
    assert server.proc.alive()
    [stats] = [e.data for e in client.query(client.keys.stats("tablet", "*"), Event, timeout=5)]
    assert stats["study_refused"] == 7
    assert stats["study_refused_puzzle_move"] == 3 and stats["study_refused_feedback"] == 1
    heard = drain(actions)
    assert [m.act for m in heard] == ["consent", "puzzle_move"] and heard[1].piece == 0 and heard[1].correct
    assert "refused: there is no piece 999" in server.proc.output
    # Without --study-trial, a study message is a violation of the page protocol.
    plain = start_tablet(spawn, router, namespace, tmp_path / "plain", "--no-qr")

    async def plain_check() -> None:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            ws, hello = await _study_socket(http, plain.base, plain.token)
            assert hello["study"] is None
            await ws.send_str(json.dumps({"type": "consent", "answer": "given", "wall": wall}))
            assert (await _reply(ws))["code"] == 1008
            async with http.get(f"{plain.base}/puzzle.png?token={plain.token}") as r:
                assert r.status == 404
            async with http.get(f"{server.base}/puzzle.png?token={server.token}") as r:
                assert r.status == 200 and r.headers["Content-Type"] == "image/png"
                assert (await r.read()) == picture_png(123, 4, 4)

    run(plain_check())

    # In the browser: the no-feedback page is the AR view without the panel; the plain page is the usual one.
    page = browser(window=(1280, 800))
    driver = StudyPageDriver(page)
    driver.open(server.url)
    driver.wait("s.screen === '' && s.puzzle.moves === 1")  # consent given above, the move kept
    driver.switch("robots")
    assert driver.visible("#stage") and not driver.visible("#panel") and not driver.visible("#mapbox")
    assert not driver.visible("#toggle-mode") and not driver.visible("#toggle-map")
    page.navigate(plain.url + "&mode=viewer")
    page.wait_for("window.arroch && window.arroch.state().connected")
    assert page.evaluate("window.arroch.study()") is None
    assert driver.visible("#toggle-mode") and driver.visible("#toggle-map") and driver.visible("#stage")
    assert driver.visible("#mapbox") and driver.visible("#panel")
    for selector in ("#tabs", "#doorbar", "#puzzle", "#consent", "#questionnaire", "#paused", "#thanks"):
        assert not driver.visible(selector), selector


@pytest.mark.integration
def test_consent_refused_leaves_only_the_experimenters_word(router, namespace, client, spawn, browser, tmp_path):
    trial_file = write_trial(tmp_path, trial="P06-T1-arroch", participant="P06", questionnaires=["arroch-q"])
    server = start_tablet(spawn, router, namespace, tmp_path / "tablet", "--no-qr", "--study-trial", str(trial_file))
    actions = collect_actions(client)
    time.sleep(0.5)
    page = browser(window=(1024, 768))
    driver = StudyPageDriver(page)
    driver.open(server.url)
    driver.consent(agree=False)
    heard: list[ParticipantAction] = []
    refused = wait_for(actions, lambda m: m.act == "consent", heard)
    assert (refused.participant, refused.trial, refused.note) == ("P06", "P06-T1-arroch", "refused")
    assert "The experimenter will take over" in driver.text("#declined")
    for selector in ("#bar", "#doorbar", "#main", "#puzzle-board", "#consent", "#questionnaire"):
        assert not driver.visible(selector), selector
    # A reload, or the experimenter's questionnaire link, shows the same and nothing else.
    driver.open(server.url + "&questionnaire=1")
    driver.wait("s.screen === 'declined'")
    assert not driver.visible("#questionnaire")
    time.sleep(0.5)
    assert [m.act for m in heard + drain(actions)] == ["consent"]  # no view, no move: nothing else happened


@pytest.mark.integration
def test_bad_trial_file_exits_2_naming_file_and_field(tmp_path):
    import subprocess

    bad = write_trial(tmp_path, condition="vr")
    result = subprocess.run(
        arroch("tablet", "--no-qr", "--port", "0", "--study-trial", str(bad), "--state-dir", str(tmp_path / "s")),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2, result.stderr
    assert f"{bad}: condition: 'vr' is not one of arroch, no-feedback, map" in result.stderr + result.stdout
