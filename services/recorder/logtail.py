"""Follow a growing text log (``arroch up``'s merged ``supervisor.log``) and split its lines.

Lines look like ``[planner] 2026-01-01 12:00:00,000 INFO    arroch.planner: plan 3 ...`` (a child's
log record) or ``[sim] anything`` (other output). A line cut short by the writer waits for its end.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

_LINE = re.compile(
    r"^\[(?P<name>[^\]]{1,64})\] (?:\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ (?P<level>[A-Z]+)\s+)?(?P<text>.*)$"
)
MAX_READ = 1 << 20  # bytes taken per poll, so a huge backlog never stalls the recorder


@dataclass(frozen=True)
class LogLine:
    name: str
    level: str
    text: str


def parse(line: str) -> LogLine:
    match = _LINE.match(line)
    if not match:
        return LogLine("", "INFO", line)
    return LogLine(match.group("name"), match.group("level") or "INFO", match.group("text"))


class LogFollower:
    """``poll()`` returns the complete lines added since the last call (none if the file is not there yet)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._offset = 0
        self._partial = b""

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
        return [parse(raw.decode("utf-8", "replace")) for raw in complete if raw.strip()]
