"""Follow a growing text log (``arroch up``'s merged ``supervisor.log``) and split its lines.

Lines look like ``[planner] 2026-01-01 12:00:00,000 INFO    arroch.planner: plan 3 ...`` (a child's
log record) or ``[sim] anything`` (other output). A line cut short by the writer waits for its end.
Secrets in a line (the tablet page's token, keys: :mod:`runtime.redact`) are redacted here, before
the line can reach a recording.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from runtime.redact import Redactor

_LINE = re.compile(
    r"^\[(?P<name>[^\]]{1,64})\] (?:\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ (?P<level>[A-Z]+)\s+)?(?P<text>.*)$"
)
MAX_READ = 1 << 20  # bytes taken per poll, so a huge backlog never stalls the recorder


@dataclass(frozen=True)
class LogLine:
    name: str
    level: str
    text: str
    number: int = 0  # the line's number in its file (1 = the first), 0 if unknown


def parse(line: str, number: int = 0) -> LogLine:
    match = _LINE.match(line)
    if not match:
        return LogLine("", "INFO", line, number)
    return LogLine(match.group("name"), match.group("level") or "INFO", match.group("text"), number)


class LogFollower:
    """``poll()`` returns the complete lines added since the last call (none if the file is not there yet)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._offset = 0
        self._partial = b""
        self._lines = 0
        self._redact = Redactor()

    def poll(self) -> list[LogLine]:
        try:
            with open(self.path, "rb") as f:
                f.seek(self._offset)
                chunk = f.read(MAX_READ)
        except FileNotFoundError:
            return []
        self._offset += len(chunk)
        data = self._partial + chunk
        *complete, self._partial = data.split(b"\n")
        out = []
        for raw in complete:
            self._lines += 1
            if raw.strip():
                out.append(parse(self._redact(raw.decode("utf-8", "replace")), self._lines))
        return out
