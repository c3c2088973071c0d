"""Where the study page's progress survives a restart of the tablet server.

One small JSON file per trial, beside the trial file (``<trial file stem>.tablet-progress.json``, in
the study folder the runner writes the trial into): consent, the puzzle's arrangement and moves,
whether her task and the mission are done, whether the questionnaire is in. Written atomically
(a temporary file, then a rename) after every change, so a restarted server resumes the trial
where the page left it. A file that cannot be read or written costs the resumption only: it is
logged, and the trial goes on in memory.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

log = logging.getLogger("arroch.tablet.study")

SUFFIX = ".tablet-progress.json"
MAX_BYTES = 64 * 1024


def progress_path(trial_file: str | Path) -> Path:
    path = Path(trial_file)
    return path.with_name(path.stem + SUFFIX)


class ProgressStore:
    """``load()`` the saved progress (None when there is none or it is unreadable), ``save(state)``."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self._warned = False

    def load(self) -> dict[str, Any] | None:
        if self.path is None or not self.path.exists():
            return None
        try:
            raw = self.path.read_bytes()
            data = json.loads(raw) if len(raw) <= MAX_BYTES else None
        except (OSError, ValueError) as exc:
            log.warning("study progress %s unreadable (%s): starting the trial afresh", self.path, exc)
            return None
        if not isinstance(data, dict):
            log.warning("study progress %s is not a JSON object: starting the trial afresh", self.path)
            return None
        log.info("resuming the trial from %s", self.path)
        return data

    def save(self, state: dict[str, Any]) -> None:
        if self.path is None:
            return
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(state, separators=(",", ":")))
            os.replace(tmp, self.path)
        except OSError as exc:
            if not self._warned:  # once: the trial itself goes on
                log.warning("cannot save study progress to %s (%s): a restart would not resume it", self.path, exc)
                self._warned = True
