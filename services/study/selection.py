"""Which trial of a participant runs next, and the bookkeeping of its attempts.

A participant's trials run in the plan's order; the next one is the first that is not complete:

- ``pending``: its first attempt;
- ``running``: the runner that ran it died mid-trial (the participant lock proves no runner holds it
  now), so it is first marked ``incomplete`` with that reason (:func:`recover_interrupted`);
- ``incomplete``: run again as a new attempt only when asked (``--retry``); otherwise nothing runs
  and the experimenter decides. A new attempt moves the earlier attempt's ``log.jsonl``,
  ``questionnaire.json`` and ``page.json`` to ``attempt-<k>/``; its ``run/<timestamp>/`` stays where it is.

When every trial is complete there is nothing to run.

The participant lock (:class:`ParticipantLock`, an advisory ``flock`` on ``participants/<PID>/.runner.lock``)
keeps two runners off one participant's trials: without it a second runner would take the first
one's live trial for a dead one and mark it incomplete.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from .layout import Attempt, PlannedParticipant, PlannedTrial, StudyError, StudyFolder, TrialState

log = logging.getLogger("arroch.study.run")

#: What an earlier attempt leaves in the trial folder and a new attempt moves aside: its log, her
#: answers, the page's trial file and whatever the page keeps beside it (``page.tablet-progress.json``:
#: her consent, puzzle and answers, which a new attempt must not resume).
ATTEMPT_FILES = ("log.jsonl", "questionnaire.json", "page.json")
ATTEMPT_PATTERNS = ("page.*",)
LOCK_NAME = ".runner.lock"


@dataclass
class Selection:
    """What to do for a participant: ``run`` ``trial`` (``state``: its state before this attempt),
    ``done`` (every trial complete) or ``blocked`` (an incomplete trial and no ``--retry``)."""

    action: Literal["run", "done", "blocked"]
    message: str
    trial: PlannedTrial | None = None
    state: TrialState | None = None

    @property
    def attempt(self) -> int:
        """The number the attempt to run gets (1 for a trial never started)."""
        return (self.state.attempt if self.state else 0) + 1


def recover_interrupted(folder: StudyFolder, participant: PlannedParticipant, *, now: float | None = None) -> list[str]:
    """Mark every ``running`` trial of the participant ``incomplete``: no runner holds it (the caller
    holds the participant lock), so the one that ran it stopped mid-trial. Returns a line per trial."""
    notes = []
    for trial in participant.trials:
        state = folder.trial_state(participant.id, trial)
        if state.status != "running":
            continue
        ended = _last_trace(folder, participant.id, trial.id) or (now if now is not None else time.time())
        state.status = "incomplete"
        state.ended = ended
        state.reason = (
            "interrupted: the runner stopped while the trial was running "
            f"(found running on {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(now or time.time()))})"
        )
        folder.save_trial_state(state)
        notes.append(f"{trial.id}: found running without a runner; marked incomplete ({state.reason})")
    return notes


def _last_trace(folder: StudyFolder, pid: str, tid: str) -> float | None:
    """When the trial last left a trace (its log's last write): the best guess of when it stopped."""
    path = folder.log_file(pid, tid)
    try:
        return path.stat().st_mtime
    except OSError:
        return None


def next_trial(folder: StudyFolder, participant: PlannedParticipant, *, retry: bool) -> Selection:
    """The participant's next trial (see the module's docstring). A ``running`` trial counts as
    incomplete here: :func:`recover_interrupted` marks it so before a real run."""
    total = len(participant.trials)
    for trial in participant.trials:
        state = folder.trial_state(participant.id, trial)
        if state.status == "complete":
            continue
        where = f"trial {trial.index} of {total}, {trial.id} (condition {trial.condition})"
        if state.status == "pending":
            return Selection("run", f"{participant.id}: {where}", trial, state)
        reason = state.reason or ("interrupted mid-trial" if state.status == "running" else "no reason recorded")
        if retry:
            return Selection(
                "run", f"{participant.id}: {where}, again after attempt {state.attempt} ({reason})", trial, state
            )
        return Selection(
            "blocked",
            f"{participant.id}: {trial.id} is incomplete (attempt {state.attempt}: {reason}). "
            "Run it again with --retry, or leave it incomplete.",
            trial,
            state,
        )
    return Selection("done", f"{participant.id}: all {total} trial(s) are complete; nothing to run")


def begin_attempt(folder: StudyFolder, state: TrialState, *, now: float | None = None) -> TrialState:
    """Start a new attempt of the trial: the earlier attempt's files go to ``attempt-<k>/`` (first,
    so a crash in between leaves them moved and the state still saying the earlier attempt), then
    ``trial.json`` says ``running``. Returns the new state (saved)."""
    trial_dir = folder.trial_dir(state.participant, state.trial)
    if state.attempt > 0:
        _move_attempt_files(trial_dir, state.attempt)
        state.attempts = [
            *state.attempts,
            Attempt(
                attempt=state.attempt,
                status=state.status,
                started=state.started,
                ended=state.ended,
                reason=state.reason,
            ),
        ]
    state.attempt += 1
    state.status = "running"
    state.started = now if now is not None else time.time()
    state.ended = None
    state.reason = ""
    folder.save_trial_state(state)
    return state


def _move_attempt_files(trial_dir: Path, attempt: int) -> None:
    target = trial_dir / f"attempt-{attempt}"
    names = set(ATTEMPT_FILES) | {
        p.name for pattern in ATTEMPT_PATTERNS for p in trial_dir.glob(pattern) if p.is_file()
    }
    for name in sorted(names):
        source = trial_dir / name
        if not source.exists():
            continue
        target.mkdir(parents=True, exist_ok=True)
        destination = target / name
        if destination.exists():  # a crash mid-move left one there already: keep both
            destination = target / f"{name}.{int(time.time())}"
        shutil.move(str(source), str(destination))
        log.info("kept attempt %d's %s in %s", attempt, name, destination)


def finish(folder: StudyFolder, state: TrialState, status: str, reason: str = "", *, now: float | None = None) -> None:
    """End the current attempt ``complete`` or ``incomplete`` (with ``reason``), saved."""
    state.status = status  # type: ignore[assignment]
    state.reason = reason
    state.ended = now if now is not None else time.time()
    folder.save_trial_state(state)


def mark_participant_incomplete(
    folder: StudyFolder, participant: PlannedParticipant, reason: str, *, except_trial: str = ""
) -> list[str]:
    """Every trial of hers still pending becomes ``incomplete`` with ``reason`` (consent refused);
    returns their ids. ``except_trial``: the one the caller finishes itself."""
    marked = []
    for trial in participant.trials:
        if trial.id == except_trial:
            continue
        state = folder.trial_state(participant.id, trial)
        if state.status in ("complete", "incomplete"):  # an earlier outcome keeps its own reason
            continue
        finish(folder, state, "incomplete", reason)
        marked.append(trial.id)
    return marked


class ParticipantLock:
    """An exclusive advisory lock on a participant's trials, held while a runner works on them."""

    def __init__(self, folder: StudyFolder, pid: str) -> None:
        self.path = folder.participant_dir(pid) / LOCK_NAME
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`StudyError` naming the runner that holds it."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise StudyError(
                f"another runner (pid {holder}) is running this participant's trials ({self.path} is locked)"
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> ParticipantLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
