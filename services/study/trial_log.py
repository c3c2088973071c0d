"""A trial's ``log.jsonl`` and ``questionnaire.json``, written as the trial's messages are heard.

``log.jsonl`` (format in :mod:`.layout`): one line per message, ``{"t": its stamp (site seconds),
"wall": Unix seconds when heard, "key": the key after the namespace, "type": ..., **its fields}``,
flushed line by line so a crash loses nothing heard before it. A message's own ``wall`` field (the
page's clock when she acted, in ParticipantAction and QuestionnaireAnswers) is written as
``sender_wall``, so ``wall`` always means when the runner heard it. Streams that repeat their state
(HumanState once a wall second, DoorState, ConstraintSet, and the runner's own StudyControl, said
again until the world shows it) are written when they change: for HumanState a change of her place,
door, doors, task or the pause (not of her avatar's pose); for a door its open flag or who holds it
open; for the constraints their version; for StudyControl its command or reason.

``questionnaire.json`` holds her answers per instrument (``{"arroch-q": {"Q1": 4, ...}}``), rewritten
whole (atomically) at every answer. Answers that cannot be hers are dropped with the reason: an
instrument the plan does not ask, an item the instrument does not have, a value off its scale.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import IO, Any

import msgspec

from protocol.messages import ConstraintSet, DoorState, HumanState, Message, QuestionnaireAnswers, StudyControl
from protocol.schema import record_to_wire

from .layout import write_json

log = logging.getLogger("arroch.study.run")

#: Each instrument's items and scale: the paper's Q1-Q5 on 1-5; NASA-TLX raw, six scales 0-100.
INSTRUMENTS: dict[str, tuple[tuple[str, ...] | None, int, int]] = {
    "arroch-q": (("Q1", "Q2", "Q3", "Q4", "Q5"), 1, 5),
    # The page names the six TLX scales; any six names are taken, on the 0-100 scale.
    "nasa-tlx": (None, 0, 100),
}
TLX_SCALES = 6


def _signature(msg: Message) -> tuple[Any, ...] | None:
    """What must change for a repeated state message to be written again (None: write every one)."""
    if isinstance(msg, HumanState):
        return (msg.mode, msg.place, msg.door, tuple(msg.doors), msg.task_done, msg.paused)
    if isinstance(msg, DoorState):
        return (msg.open, msg.by)
    if isinstance(msg, ConstraintSet):
        return (msg.version,)
    if isinstance(msg, StudyControl):  # said again until the world shows it: once is the record
        return (msg.command, msg.reason, msg.trial)
    return None


class TrialLog:
    """Appends the trial's messages to ``log.jsonl``; a line that cannot be written is counted and
    logged, never raised (the run's recording still has the message)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] | None = open(path, "ab")
        self._last: dict[str, tuple[Any, ...]] = {}
        self.written = 0
        self.unchanged = 0
        self.failed = 0

    def record(self, msg: Message, key: str, *, wall: float | None = None) -> bool:
        """Write ``msg`` heard on ``key`` (the part after the namespace) unless it repeats the last
        state on that key. Returns True when a line was written."""
        signature = _signature(msg)
        if signature is not None:
            if self._last.get(key) == signature:
                self.unchanged += 1
                return False
            self._last[key] = signature
        line: dict[str, Any] = {"t": msg.stamp, "wall": round(time.time() if wall is None else wall, 6), "key": key}
        try:
            fields = record_to_wire(msg)
            if "wall" in fields:  # the sender's own clock (the page's): kept, beside when it was heard
                fields["sender_wall"] = fields.pop("wall")
            line.update(fields)
            data = msgspec.json.encode(line) + b"\n"
        except (TypeError, ValueError, msgspec.EncodeError) as exc:
            self.failed += 1
            log.warning("log.jsonl: cannot write a %s from %s on %s: %s", msg.TYPE, msg.src, key, exc)
            return False
        return self._write(data)

    def _write(self, data: bytes) -> bool:
        if self._file is None:
            self.failed += 1
            return False
        try:
            self._file.write(data)
            self._file.flush()
        except OSError as exc:
            self.failed += 1
            log.error("log.jsonl: write failed (%s); the run's recording still has every message", exc)
            return False
        self.written += 1
        return True

    def close(self) -> None:
        if self._file is None:
            return
        try:
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as exc:
            log.error("log.jsonl: could not sync %s: %s", self.path, exc)
        self._file.close()
        self._file = None


class Questionnaires:
    """Her answers to the instruments the plan asks, kept in ``questionnaire.json``."""

    def __init__(self, path: Path, instruments: list[str]) -> None:
        self.path = path
        self.instruments = list(instruments)
        self.answers: dict[str, dict[str, int]] = {}

    @property
    def complete(self) -> bool:
        return all(name in self.answers for name in self.instruments)

    @property
    def missing(self) -> list[str]:
        return [name for name in self.instruments if name not in self.answers]

    def take(self, msg: QuestionnaireAnswers) -> str:
        """Keep her answers (a later answer to an instrument replaces the earlier one) and rewrite the
        file. Returns ``""``, or why they were dropped."""
        problem = check_answers(msg.instrument, msg.answers, self.instruments)
        if problem:
            return problem
        self.answers[msg.instrument] = dict(msg.answers)
        write_json(self.path, self.answers)
        return ""


def check_answers(instrument: str, answers: dict[str, int], asked: list[str]) -> str:
    """``""`` when ``answers`` are a full, on-scale set for ``instrument`` (one the plan asks), else why not."""
    if instrument not in asked:
        return f"instrument: {instrument!r} is not one this study asks ({', '.join(asked)})"
    items, low, high = INSTRUMENTS[instrument]
    if items is not None:
        unknown = sorted(set(answers) - set(items))
        missing = [item for item in items if item not in answers]
        if unknown or missing:
            return (
                f"answers: {instrument} has items {', '.join(items)}"
                + (f"; unknown {', '.join(unknown)}" if unknown else "")
                + (f"; missing {', '.join(missing)}" if missing else "")
            )
    elif len(answers) != TLX_SCALES:
        return f"answers: {instrument} has {TLX_SCALES} scales, got {len(answers)}"
    off = sorted(item for item, value in answers.items() if not low <= value <= high)
    if off:
        return f"answers: {', '.join(off)} off the {instrument} scale {low}-{high}"
    return ""
