"""What the tablet page is given for a trial (``page.json``), and the participant's consent.

``page.json`` is what ``arroch tablet --study-trial`` reads::

    {"participant": "P03", "trial": "P03-T1-arroch", "condition": "arroch",
     "door_control": "virtual" | "sensor", "puzzle": {"seed": 7, "rows": 4, "cols": 4},
     "questionnaires": ["arroch-q"], "consent": {"required": true, "text": "<consent.txt>"}}

The condition and everything else come from the study plan, never from the participant. A real
world's doors are real: she opens them by hand and their sensors report it (``sensor``); a virtual
world's door is opened on the page (``virtual``). The consent form is shown only while she has not
given consent (``consent.json`` absent or refused); what she answered is kept with the SHA-256 of
the form she saw.
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

from .layout import QUESTIONNAIRES, Consent, PlannedTrial, StudyError, StudyFolder, StudyPlan, write_json

# What the tablet page accepts (its trial file's limits): refused here first, before a world starts.
PUZZLE_SIDES = range(2, 9)
PUZZLE_SEED_LIMIT = 2**53
MAX_CONSENT_CHARS = 20_000


def consent_form(folder: StudyFolder) -> tuple[str, str]:
    """The consent form's text and its SHA-256; :class:`StudyError` when it cannot be shown."""
    path = folder.consent_form
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise StudyError(f"{path} does not exist: a participant's first trial needs the consent form") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise StudyError(f"{path} is not UTF-8 text") from None
    if not text.strip():
        raise StudyError(f"{path} is empty: write the consent form the participant reads")
    if len(text) > MAX_CONSENT_CHARS:
        raise StudyError(f"{path} has {len(text)} characters; the page shows at most {MAX_CONSENT_CHARS}")
    return text, hashlib.sha256(raw).hexdigest()


def consent_needed(folder: StudyFolder, pid: str) -> bool:
    """True while she has not given consent (never asked, or refused before)."""
    consent = folder.consent(pid)
    return consent is None or not consent.consented


def record_consent(
    folder: StudyFolder, pid: str, given: bool, form_sha256: str, *, wall: float | None = None
) -> Consent:
    consent = Consent(
        participant=pid, consented=given, wall=wall if wall is not None else time.time(), form_sha256=form_sha256
    )
    write_json(folder.consent_file(pid), consent)
    return consent


def door_control(plan: StudyPlan) -> str:
    return "sensor" if plan.world.kind == "real" else "virtual"


def page_content(plan: StudyPlan, pid: str, trial: PlannedTrial, *, consent_text: str | None) -> dict[str, Any]:
    """The trial's ``page.json``; ``consent_text`` None when her consent is already given."""
    rows, cols = plan.puzzle.rows, plan.puzzle.cols
    if rows not in PUZZLE_SIDES or cols not in PUZZLE_SIDES:
        raise StudyError(
            f"study.json: puzzle {rows}x{cols}: the page takes {PUZZLE_SIDES[0]} to {PUZZLE_SIDES[-1]} rows and columns"
        )
    if not 0 <= trial.puzzle_seed < PUZZLE_SEED_LIMIT:
        raise StudyError(f"study.json: {trial.id}: puzzle_seed {trial.puzzle_seed} is not within [0, 2^53)")
    asked = list(plan.questionnaires)
    if not asked or len(set(asked)) != len(asked) or not set(asked) <= set(QUESTIONNAIRES):
        raise StudyError(f"study.json: questionnaires {asked}: one or more of {', '.join(QUESTIONNAIRES)}, each once")
    return {
        "participant": pid,
        "trial": trial.id,
        "condition": trial.condition,
        "door_control": door_control(plan),
        "puzzle": {"seed": trial.puzzle_seed, "rows": rows, "cols": cols},
        "questionnaires": list(plan.questionnaires),
        "consent": {"required": consent_text is not None, "text": consent_text or ""},
    }


def write_page(folder: StudyFolder, pid: str, tid: str, content: dict[str, Any]) -> Path:
    path = folder.trial_dir(pid, tid) / "page.json"
    write_json(path, content)
    return path
