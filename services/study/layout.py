"""The study folder: where a study's plan, its participants' trials and their analysis live.

One study, one folder; everything about its participants stays inside it, under pseudonymous ids
(``P01``, ``P02``, ...), never names::

    STUDY/
      study.json                      the plan (``arroch study plan``), never changed afterwards
      consent.txt                     the consent form shown before a participant's first trial
      participants/<PID>/
        consent.json                  her answer on the consent screen, with the form's SHA-256
        <TID>/                        a trial, e.g. P03-T1-arroch
          trial.json                  its state: pending, running, complete or incomplete (+ attempts)
          page.json                   what the tablet page is given (``arroch tablet --study-trial``)
          log.jsonl                   every message of the trial the analysis reads, one JSON line each
          questionnaire.json          her answers: {"arroch-q": {"Q1": 4, ...}, "nasa-tlx": {...}}
          run/<timestamp>/            each attempt's world (``arroch up --run-dir``): run.mcap,
                                      events.jsonl, metrics.json, supervisor.log, run.json
          attempt-<k>/                an earlier attempt's log and answers, kept when a trial is run again
      report/                         ``arroch study report``
      human.toml                      ``arroch study calibrate``: the human model fitted to the trials

``log.jsonl`` lines are ``{"t": site seconds (the message's stamp), "wall": Unix seconds when it was
heard, "key": the key's part after the namespace, "type": the message type, **its fields}`` for
Event, ParticipantAction, QuestionnaireAnswers, HumanState (changes), DoorState (changes) and
ConstraintSet messages, in the order heard (also StudyControl, and DoorState from ``door/<d>/sensor``).
A message's own ``wall`` field (the page's clock) is written as ``sender_wall``. ``runner.log`` beside
them is the runner's own log of the trial.

Files are written whole to a temporary name and renamed, so a crash never leaves half a file.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import msgspec

FORMAT = 1
CONDITIONS = ("arroch", "no-feedback", "map")
#: What each condition shows the participant; the simulator's --method for it (the human is a
#: person in every condition, so the method only names what the page offers).
CONDITION_METHOD = {"arroch": "arroch", "no-feedback": "no-feedback", "map": "no-feedback"}
QUESTIONNAIRES = ("arroch-q", "nasa-tlx")
TRIAL_STATES = ("pending", "running", "complete", "incomplete")
PARTICIPANT_ID = re.compile(r"^P[0-9]{2,4}$")

TrialStatus = Literal["pending", "running", "complete", "incomplete"]


class StudyError(ValueError):
    """A study folder or file that cannot be used; the message names the file and the problem."""


class PlannedTrial(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    id: str  # <PID>-T<index>-<condition>
    index: int  # 1-based position in the participant's order
    condition: Literal["arroch", "no-feedback", "map"]
    world_seed: int  # the simulated world's seed (the same for one participant's trials: paired)
    puzzle_seed: int  # her puzzle's picture and shuffle (different in every trial)


class PlannedParticipant(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    id: str
    trials: list[PlannedTrial]


class PuzzleSpec(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    rows: int = 4
    cols: int = 4


class WorldSpec(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    """How each trial's world runs: ``virtual`` (simulated robots and doors; she opens her door on
    the page) or ``real`` (robots through ROS 2, doors from sensors)."""

    kind: Literal["virtual", "real"] = "virtual"
    site: str = ""  # a site file, or "" for the packaged office site
    mode: Literal["realtime", "rate"] = "realtime"
    rate: float = 1.0  # site seconds per wall second in rate mode (rehearsals, tests)
    time_limit: float = 1800.0  # site seconds after which a trial ends unfinished
    up_args: list[str] = []  # further `arroch up` options (e.g. --robots none, ROS 2 configs)


class StudyPlan(msgspec.Struct, kw_only=True, forbid_unknown_fields=True):
    format: int = FORMAT
    name: str
    seed: int
    created: str  # ISO 8601, UTC
    design: str  # how the orders were balanced, e.g. "balanced-latin-square"
    conditions: list[str]
    questionnaires: list[str] = msgspec.field(default_factory=lambda: ["arroch-q"])
    puzzle: PuzzleSpec = msgspec.field(default_factory=PuzzleSpec)
    world: WorldSpec = msgspec.field(default_factory=WorldSpec)
    participants: list[PlannedParticipant]

    def participant(self, pid: str) -> PlannedParticipant:
        for p in self.participants:
            if p.id == pid:
                return p
        raise StudyError(f"participant {pid!r} is not in the study plan (known: {', '.join(self.ids())})")

    def ids(self) -> list[str]:
        return [p.id for p in self.participants]


class Attempt(msgspec.Struct, kw_only=True):
    attempt: int
    status: TrialStatus
    started: float | None = None  # Unix seconds
    ended: float | None = None
    reason: str = ""


class TrialState(msgspec.Struct, kw_only=True):
    participant: str
    trial: str
    index: int
    condition: str
    world_seed: int
    puzzle_seed: int
    status: TrialStatus = "pending"
    attempt: int = 0  # the current (or last) attempt, 1-based; 0: never started
    started: float | None = None
    ended: float | None = None
    reason: str = ""  # why it is incomplete
    attempts: list[Attempt] = []  # earlier attempts, oldest first


class Consent(msgspec.Struct, kw_only=True):
    participant: str
    consented: bool
    wall: float
    form_sha256: str


# ---------------------------------------------------------------------------- files


def write_json(path: Path, value: Any) -> None:
    """Write ``value`` as indented JSON, atomically (temporary file, fsync, rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    data = msgspec.json.format(msgspec.json.encode(value), indent=2) + b"\n"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def read_json(path: Path, kind: type[Any] = Any) -> Any:  # type: ignore[assignment]
    """Read ``path`` as ``kind``; a missing or malformed file is a StudyError naming it."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise StudyError(f"{path} does not exist") from None
    try:
        return msgspec.json.decode(raw, type=kind)
    except msgspec.ValidationError as exc:
        raise StudyError(f"{path}: {exc}") from None
    except msgspec.DecodeError as exc:
        raise StudyError(f"{path} is not valid JSON: {exc}") from None


def read_jsonl(path: Path) -> Iterator[dict[str, Any]]:
    """The records of a JSON-lines file; a torn last line (a crash mid-write) is skipped."""
    if not path.exists():
        return
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line:
                continue
            try:
                yield json.loads(line)
            except json.JSONDecodeError:
                # Only the last line can be torn by a crash; anything else is damage worth saying.
                if f.readline():
                    raise StudyError(f"{path}:{number} is not a JSON line") from None
                return


# ---------------------------------------------------------------------------- the folder


class StudyFolder:
    """Paths and state files of one study folder."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    @property
    def plan_file(self) -> Path:
        return self.root / "study.json"

    @property
    def consent_form(self) -> Path:
        return self.root / "consent.txt"

    @property
    def report_dir(self) -> Path:
        return self.root / "report"

    @property
    def human_config(self) -> Path:
        return self.root / "human.toml"

    def exists(self) -> bool:
        return self.plan_file.is_file()

    def plan(self) -> StudyPlan:
        if not self.plan_file.is_file():
            raise StudyError(f"{self.root} is not a study folder: no study.json (arroch study plan --out {self.root})")
        plan = read_json(self.plan_file, StudyPlan)
        if plan.format > FORMAT:
            raise StudyError(f"{self.plan_file}: format {plan.format} is newer than this version reads ({FORMAT})")
        return plan

    def participant_dir(self, pid: str) -> Path:
        if not PARTICIPANT_ID.match(pid):
            raise StudyError(f"participant id {pid!r} is not pseudonymous (P followed by 2-4 digits, e.g. P03)")
        return self.root / "participants" / pid

    def consent_file(self, pid: str) -> Path:
        return self.participant_dir(pid) / "consent.json"

    def consent(self, pid: str) -> Consent | None:
        path = self.consent_file(pid)
        return read_json(path, Consent) if path.exists() else None

    def trial_dir(self, pid: str, tid: str) -> Path:
        return self.participant_dir(pid) / tid

    def trial_state(self, pid: str, trial: PlannedTrial) -> TrialState:
        """The trial's state file, or a pending state when it has never started."""
        path = self.trial_dir(pid, trial.id) / "trial.json"
        if path.exists():
            return read_json(path, TrialState)
        return TrialState(
            participant=pid,
            trial=trial.id,
            index=trial.index,
            condition=trial.condition,
            world_seed=trial.world_seed,
            puzzle_seed=trial.puzzle_seed,
        )

    def save_trial_state(self, state: TrialState) -> None:
        write_json(self.trial_dir(state.participant, state.trial) / "trial.json", state)

    def trials(self) -> Iterator[tuple[PlannedParticipant, PlannedTrial, TrialState]]:
        """Every planned trial with its state, participant by participant, in plan order."""
        for p in self.plan().participants:
            for t in p.trials:
                yield p, t, self.trial_state(p.id, t)

    def log_file(self, pid: str, tid: str) -> Path:
        return self.trial_dir(pid, tid) / "log.jsonl"

    def questionnaire_file(self, pid: str, tid: str) -> Path:
        return self.trial_dir(pid, tid) / "questionnaire.json"

    def run_dir(self, pid: str, tid: str) -> Path:
        return self.trial_dir(pid, tid) / "run"

    def latest_run(self, pid: str, tid: str) -> Path | None:
        """The newest run folder of the trial (its last attempt's world), if any."""
        base = self.run_dir(pid, tid)
        runs = sorted(p for p in base.iterdir() if p.is_dir()) if base.is_dir() else []
        return runs[-1] if runs else None

    def metrics_file(self, pid: str, tid: str) -> Path | None:
        """The last attempt's metrics.json (the sim's mission_done summary), if the mission ended."""
        run = self.latest_run(pid, tid)
        path = run / "metrics.json" if run is not None else None
        return path if path is not None and path.exists() else None
