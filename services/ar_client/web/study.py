"""The study page's trial on the server: what she may do now, and the record of what she did.

A :class:`StudyController` holds one trial (:class:`.study_trial.StudyTrial`) for every page of the
server: consent, the puzzle (:mod:`.puzzle`), where the simulator has her (``HumanState``), the
site clock's rate and pause, whether the mission ended, whether the questionnaire is in. Pages send
requests (:mod:`.study_wire`); each is judged here and either

- accepted: recorded as a ``ParticipantAction`` (or ``QuestionnaireAnswers``) stamped with the
  trial's participant and trial ids and the page's wall time, published through the tablet's Zenoh
  service (``publish_action`` / ``publish_answers``), logged, and the state saved
  (:mod:`.study_store`); or
- refused with a reason in words for the page, counted in :attr:`counters`, and logged.

It runs on the server's event loop only (bridge callbacks are handed to it there), so it needs no
locks. Nothing a page sends can raise out of :meth:`handle`: a refusal is a return value.
"""

from __future__ import annotations

import collections
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from protocol.messages import Clock, HumanState, ParticipantAction, QuestionnaireAnswers

from .puzzle import MoveRefused, Puzzle
from .questionnaire import AnswersRefused, check_answers, instruments_json
from .study_store import ProgressStore
from .study_trial import StudyTrial
from .study_wire import AnswersSubmission, ConsentAnswer, DoorRequest, PuzzleMoveRequest, StudyMessage, ViewChange

log = logging.getLogger("arroch.tablet.study")

#: A press-and-hold may end this much short of the hold the page was asked for (timer granularity,
#: the clock's rate changing under it): wall seconds, and a fraction of the hold.
HOLD_SLACK_S = 0.1
HOLD_SLACK = 0.05
#: A door request waits this long (wall seconds) for the simulator's answer (a new HumanState)
#: before the same request may be made again.
DOOR_ANSWER_WAIT = 5.0
MAX_MINUTES = 1440


@dataclass(frozen=True)
class Outcome:
    """What a request did: ``changed`` the state every page shows; ``refused`` why it was turned down."""

    changed: bool = False
    refused: str | None = None


def wall_rate(clock: dict[str, Any]) -> float:
    """Site seconds per wall second: the clock's rate in ``rate`` mode, else 1 (realtime and wall
    run at 1; lockstep has no fixed rate, so a hold lasts its site seconds in wall seconds)."""
    rate = clock.get("rate", 1.0)
    if clock.get("mode") == "rate" and isinstance(rate, (int, float)) and rate > 0:
        return float(rate)
    return 1.0


class StudyController:
    def __init__(
        self,
        trial: StudyTrial,
        *,
        publish_action: Callable[[ParticipantAction], None],
        publish_answers: Callable[[QuestionnaireAnswers], None],
        store: ProgressStore | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.trial = trial
        self._publish_action = publish_action
        self._publish_answers = publish_answers
        self.store = store or ProgressStore(None)
        self._monotonic = clock
        saved = self.store.load() or {}
        spec = trial.puzzle
        self.puzzle = Puzzle.resume(spec.seed, spec.rows, spec.cols, saved.get("puzzle"))
        self.consent = saved.get("consent") if saved.get("consent") in ("given", "refused") else ""
        self.task_done = bool(saved.get("task_done")) and self.puzzle.done
        self.mission_done = bool(saved.get("mission_done"))
        self.submitted = bool(saved.get("submitted"))
        self.human: HumanState | None = None
        self.clock: dict[str, Any] = {"rate": 1.0, "paused": False, "mode": ""}
        self.counters: collections.Counter[str] = collections.Counter()
        self._awaiting: tuple[str, float] | None = None  # a door act sent, and when; its answer not yet seen

    # ------------------------------------------------------------------ what pages see

    def page_state(self) -> dict[str, Any]:
        """The ``study`` message: everything a page draws the study from."""
        t = self.trial
        human = self.human
        return {
            "type": "study",
            "participant": t.participant,
            "trial": t.trial,
            "condition": t.condition,
            "door_control": t.door_control,
            "robots_view": t.robots_view,
            "feedback": t.feedback,
            "consent": {"required": t.consent.required, "answer": self.consent},
            "puzzle": self.puzzle.to_json(),
            "puzzle_lock": self.puzzle_lock(),
            "task_done": self.task_done,
            "human": None
            if human is None
            else {
                "mode": human.mode,
                "place": human.place,
                "door": human.door,
                "doors": list(human.doors),
                "paused": human.paused,
                "task_done": human.task_done,
                "open_time": human.open_time,
            },
            "clock": dict(self.clock),
            "wall_rate": wall_rate(self.clock),
            "paused": self.paused,
            "mission_done": self.mission_done,
            "submitted": self.submitted,
            "questionnaires": list(t.questionnaires),
        }

    def hello_state(self) -> dict[str, Any]:
        """The ``study`` part of a page's hello: the state, the consent form and the questionnaires."""
        state = self.page_state()
        state["consent"]["text"] = self.trial.consent.text
        state["instruments"] = instruments_json(list(self.trial.questionnaires))
        return state

    @property
    def paused(self) -> bool:
        """The experimenter paused the trial (HumanState.paused). A paused Clock alone is not taken
        for it: the simulator's clock also stands still when the mission is over or it waits for a
        plan, and the experimenter's pause is in HumanState besides."""
        return self.human is not None and self.human.paused

    def puzzle_lock(self) -> str:
        """Why the puzzle cannot be played now ("" when it can), in words for the page."""
        if self.mission_done or self.submitted:
            return "The trial has ended."
        if self.paused:
            return "Paused by the experimenter."
        if self.human is not None and self.human.place != "desk":
            return "You are away from your desk: the puzzle waits for you there."
        return ""

    # ------------------------------------------------------------------ from the world (bridge)

    def human_changed(self, msg: HumanState) -> bool:
        """A HumanState from the simulator; True when what pages show changed."""
        old = self.human
        self.human = msg
        if old is None or (old.place, old.door) != (msg.place, msg.door):
            self._awaiting = None  # the simulator answered the last door request
        if old is None:
            return True
        shown = ("mode", "place", "door", "doors", "paused", "task_done", "open_time")
        return any(getattr(old, f) != getattr(msg, f) for f in shown)

    def clock_changed(self, msg: Clock) -> bool:
        clock = {"rate": float(msg.rate), "paused": bool(msg.paused), "mode": msg.mode}
        if clock == self.clock:
            return False
        self.clock = clock
        return True

    def mission_ended(self) -> bool:
        if self.mission_done:
            return False
        self.mission_done = True
        log.info("%s: the mission has ended: the questionnaire opens", self._who())
        self._save()
        return True

    # ------------------------------------------------------------------ requests from pages

    def handle(self, msg: StudyMessage, *, early_questionnaire: bool = False) -> Outcome:
        """Judge one request of a page (``early_questionnaire``: the page was opened with
        ``?questionnaire=1`` by the experimenter, for a trial ended by abort)."""
        if isinstance(msg, ConsentAnswer):
            outcome = self._consent(msg)
        elif isinstance(msg, ViewChange):
            outcome = self._view(msg)
        elif isinstance(msg, PuzzleMoveRequest):
            outcome = self._move(msg)
        elif isinstance(msg, DoorRequest):
            outcome = self._door(msg)
        elif isinstance(msg, AnswersSubmission):
            outcome = self._answers(msg, early_questionnaire)
        else:  # pragma: no cover - wire.parse_text only makes the types above
            outcome = Outcome(refused=f"unknown study request {type(msg).__name__}")
        if outcome.refused:
            self.counters[f"refused_{_kind(msg)}"] += 1
            log.info("%s: %s refused: %s", self._who(), _kind(msg), outcome.refused)
        return outcome

    def feedback(self, kind: str, params: dict[str, Any], wall: float) -> str | None:
        """She sent feedback from the panel: record it (None), or why it is refused in this trial."""
        refused = self._gate()
        if refused is None and not self.trial.feedback:
            refused = f"there is no feedback in this trial's condition ({self.trial.condition})"
        if refused is not None:
            self.counters["refused_feedback"] += 1
            log.info("%s: feedback refused: %s", self._who(), refused)
            return refused
        door = params.get("door", "")
        minutes = params.get("minutes", 0)
        self._act(
            "feedback",
            wall,
            door=door if isinstance(door, str) else "",
            minutes=min(max(int(minutes), 0), MAX_MINUTES) if isinstance(minutes, (int, float)) else 0,
            note=kind,
        )
        return None

    # ------------------------------------------------------------------ one request each

    def _gate(self) -> str | None:
        """Why nothing but consent can be done now, or None."""
        if self.trial.consent.required and self.consent == "refused":
            return "consent was not given: the experimenter takes over"
        if self.trial.consent.required and not self.consent:
            return "the consent screen must be answered first"
        if self.submitted:
            return "the trial is over: the questionnaire is in"
        return None

    def _consent(self, msg: ConsentAnswer) -> Outcome:
        if not self.trial.consent.required:
            return Outcome(refused="this trial asks for no consent on the page")
        if self.consent == msg.answer:
            return Outcome()  # the same answer again (a double tap): already recorded
        if self.consent:
            return Outcome(refused=f"consent was already answered ({self.consent})")
        self.consent = msg.answer
        self._act("consent", msg.wall, note=msg.answer)
        self._save()
        return Outcome(changed=True)

    def _view(self, msg: ViewChange) -> Outcome:
        refused = self._gate()
        if refused is not None:
            return Outcome(refused=refused)
        if msg.view != "puzzle" and msg.view != self.trial.robots_view:
            return Outcome(refused=f"this trial's condition ({self.trial.condition}) has no {msg.view} view")
        self._act("view", msg.wall, view=msg.view, note=msg.note)
        return Outcome()

    def _move(self, msg: PuzzleMoveRequest) -> Outcome:
        refused = self._gate() or self.puzzle_lock() or None
        if refused is not None:
            return Outcome(refused=refused)
        try:
            move = self.puzzle.swap(msg.piece, msg.other)
        except MoveRefused as exc:
            return Outcome(refused=str(exc))
        self._act(
            "puzzle_move",
            msg.wall,
            piece=move.piece,
            correct=move.correct,
            placed=move.placed,
            total=move.total,
            note=f"swapped with {move.other}" + (" (also placed)" if move.other_correct else ""),
        )
        log.info(
            "%s: move %d: pieces %d and %d swapped, %d/%d placed",
            self._who(),
            move.moves,
            move.piece,
            move.other,
            move.placed,
            move.total,
        )
        if move.done and not self.task_done:
            self.task_done = True
            self._act("task_done", msg.wall, placed=move.placed, total=move.total, note=f"{move.moves} moves")
            log.info("%s: puzzle complete in %d moves", self._who(), move.moves)
        self._save()
        return Outcome(changed=True)

    def _door(self, msg: DoorRequest) -> Outcome:
        refused = self._gate()
        if refused is not None:
            return Outcome(refused=refused)
        if self.trial.door_control != "virtual":
            return Outcome(refused="the doors are real in this trial: open them by hand")
        if self.mission_done:
            return Outcome(refused="the trial has ended")
        if self.paused:
            return Outcome(refused="paused by the experimenter")
        human = self.human
        if human is None:
            return Outcome(refused="no word from the simulator yet on where you are")
        if self._awaiting is not None and self._monotonic() - self._awaiting[1] < DOOR_ANSWER_WAIT:
            return Outcome(refused=f"{self._awaiting[0]} was asked already; waiting for the simulator")
        if msg.act == "go_to_door":
            if human.place != "desk":
                return Outcome(refused=f"you can leave for a door from your desk only (you are: {human.place})")
            if msg.door not in human.doors:
                doors = ", ".join(human.doors) or "none"
                return Outcome(refused=f"{msg.door!r} is not a door you operate (yours: {doors})")
        elif msg.act == "open_door":
            if human.place != "at_door" or msg.door != human.door:
                where = f"at {human.door}" if human.place == "at_door" else human.place
                return Outcome(refused=f"you can open {msg.door!r} only standing at it (you are: {where})")
            need = human.open_time / wall_rate(self.clock)
            if msg.held < need * (1.0 - HOLD_SLACK) - HOLD_SLACK_S:
                return Outcome(refused=f"held {msg.held:.1f} s of the {need:.1f} s it takes to open the door")
        elif human.place not in ("to_door", "at_door"):  # back_to_desk
            return Outcome(refused=f"you can turn back only on the way to a door or at it (you are: {human.place})")
        door = msg.door if msg.act != "back_to_desk" else human.door
        self._act(msg.act, msg.wall, door=door, note=f"held {msg.held:.2f} s" if msg.act == "open_door" else "")
        self._awaiting = (msg.act, self._monotonic())
        return Outcome()

    def _answers(self, msg: AnswersSubmission, early: bool) -> Outcome:
        refused = self._gate()
        if refused is not None:
            return Outcome(refused=refused)
        if not (self.mission_done or early):
            return Outcome(refused="the questionnaire opens when the trial has ended")
        wanted = list(self.trial.questionnaires)
        extra = sorted(set(msg.answers) - set(wanted))
        if extra:
            return Outcome(refused=f"{extra[0]!r} is not a questionnaire of this trial (it asks {', '.join(wanted)})")
        missing = [i for i in wanted if i not in msg.answers]
        if missing:
            return Outcome(refused=f"{missing[0]} is not answered; every questionnaire of the trial must be")
        try:
            checked = {i: check_answers(i, msg.answers[i]) for i in wanted}
        except AnswersRefused as exc:
            return Outcome(refused=str(exc))
        for instrument in wanted:
            answers = QuestionnaireAnswers(
                participant=self.trial.participant,
                trial=self.trial.trial,
                instrument=instrument,
                answers=checked[instrument],
                wall=msg.wall,
            )
            self._publish_answers(answers)
            log.info("%s: %s answers: %s", self._who(), instrument, checked[instrument])
        self.submitted = True
        self._save()
        return Outcome(changed=True)

    # ------------------------------------------------------------------ helpers

    def _act(self, act: str, wall: float, **fields: Any) -> None:
        trial = self.trial
        msg = ParticipantAction(participant=trial.participant, trial=trial.trial, act=act, wall=wall, **fields)
        self._publish_action(msg)
        if act not in ("puzzle_move",):  # moves have their own line
            details = " ".join(f"{k}={v}" for k, v in fields.items() if v not in ("", 0, False))
            log.info("%s: %s %s", self._who(), act, details)

    def _who(self) -> str:
        return f"{self.trial.participant}/{self.trial.trial}"

    def _save(self) -> None:
        self.store.save(
            {
                "participant": self.trial.participant,
                "trial": self.trial.trial,
                "consent": self.consent,
                "puzzle": self.puzzle.to_json(),
                "task_done": self.task_done,
                "mission_done": self.mission_done,
                "submitted": self.submitted,
            }
        )


def _kind(msg: object) -> str:
    return {
        ConsentAnswer: "consent",
        ViewChange: "view",
        PuzzleMoveRequest: "puzzle_move",
        DoorRequest: "door",
        AnswersSubmission: "answers",
    }.get(type(msg), "request")
