"""The trial file that turns the tablet page into a study page (``arroch tablet --study-trial FILE``).

The study runner writes one JSON file per trial::

    {"participant": "P03", "trial": "P03-T1-arroch", "condition": "arroch",
     "door_control": "virtual", "puzzle": {"seed": 123, "rows": 4, "cols": 4},
     "questionnaires": ["arroch-q", "nasa-tlx"],
     "consent": {"required": true, "text": "..."}}

The condition comes from this file, never from the participant. A file that breaks the shape below
is refused before anything starts, with the file and the field named (:class:`TrialFileError`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import msgspec
from msgspec import Meta, Struct

from protocol.errors import ProtocolError
from protocol.messages import QUESTIONNAIRES
from protocol.schema import ID_REGEX
from protocol.validation import field_error

CONDITIONS = ("arroch", "no-feedback", "map")
DOOR_CONTROLS = ("virtual", "sensor")
MAX_SIDE = 8  # rows or columns of a puzzle: 64 pieces at most, each still big enough to tap
MAX_FILE_BYTES = 256 * 1024
MAX_CONSENT_TEXT = 20_000

Condition = Literal["arroch", "no-feedback", "map"]
DoorControl = Literal["virtual", "sensor"]
Instrument = Literal["arroch-q", "nasa-tlx"]
assert set(Instrument.__args__) == set(QUESTIONNAIRES)  # the wire's instruments, and no other


class PuzzleSpec(Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    seed: Annotated[int, Meta(ge=0, lt=2**53)]
    rows: Annotated[int, Meta(ge=2, le=MAX_SIDE)]
    cols: Annotated[int, Meta(ge=2, le=MAX_SIDE)]


class ConsentSpec(Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    required: bool
    text: Annotated[str, Meta(max_length=MAX_CONSENT_TEXT)] = ""


class StudyTrial(Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """One trial of one participant, as the study plan fixed it."""

    participant: Annotated[str, Meta(min_length=1, max_length=64, pattern=ID_REGEX)]  # pseudonymous
    trial: Annotated[str, Meta(min_length=1, max_length=64)]
    condition: Condition
    puzzle: PuzzleSpec
    door_control: DoorControl = "virtual"
    questionnaires: Annotated[list[Instrument], Meta(min_length=1, max_length=len(QUESTIONNAIRES))] = msgspec.field(
        default_factory=lambda: ["arroch-q"]
    )
    consent: ConsentSpec = ConsentSpec(required=False)

    @property
    def robots_view(self) -> str:
        """What the Robots tab shows, and the ``view`` it reports: ``ar`` or ``map``."""
        return "map" if self.condition == "map" else "ar"

    @property
    def feedback(self) -> bool:
        """The feedback panel is part of this condition (ARROCH only)."""
        return self.condition == "arroch"


class TrialFileError(ValueError):
    """A trial file that cannot be used; the message names the file and the field."""


def parse_trial(data: object, source: str = "trial file") -> StudyTrial:
    """Plain data (a decoded JSON object) as a :class:`StudyTrial`; :class:`TrialFileError` if not one."""
    if not isinstance(data, dict):
        raise TrialFileError(f"{source}: expected a JSON object, got {type(data).__name__}")
    try:
        trial = msgspec.convert(data, StudyTrial)
    except msgspec.ValidationError as exc:
        err = field_error(exc, StudyTrial, data)
        raise TrialFileError(f"{source}: {err.field or '(top level)'}: {err.problem}") from None
    if len(set(trial.questionnaires)) != len(trial.questionnaires):
        raise TrialFileError(f"{source}: questionnaires: {trial.questionnaires} lists one twice")
    if trial.consent.required and not trial.consent.text.strip():
        raise TrialFileError(f"{source}: consent.text: required consent needs the consent form's text")
    if trial.trial.strip() != trial.trial or not trial.trial.isprintable():
        raise TrialFileError(f"{source}: trial: {trial.trial!r} has surrounding spaces or unprintable characters")
    return trial


def load_trial(path: str | Path) -> StudyTrial:
    """The trial file at ``path``; :class:`TrialFileError` (naming the file and the field) if unusable."""
    path = Path(path)
    try:
        raw = path.read_bytes()[: MAX_FILE_BYTES + 1]
    except OSError as exc:
        raise TrialFileError(f"{path}: cannot read the trial file: {exc.strerror or exc}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise TrialFileError(f"{path}: larger than {MAX_FILE_BYTES} bytes: not a trial file")
    try:
        data = msgspec.json.decode(raw)
    except (msgspec.DecodeError, RecursionError) as exc:
        raise TrialFileError(f"{path}: not valid JSON: {exc}") from None
    try:
        return parse_trial(data, str(path))
    except ProtocolError as exc:  # field_error's own failure modes, worded the same way
        raise TrialFileError(f"{path}: {exc}") from None
