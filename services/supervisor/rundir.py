"""``runs/<timestamp>/``: what a supervised run leaves behind.

- ``supervisor.log``: the merged, prefixed output of the supervisor and every child;
- ``events.jsonl``: every Event seen, one JSON object per line, as received (written as they come,
  so an interrupted run keeps what happened);
- ``metrics.json``: the ``mission_done`` Event's metrics (only when the mission finished);
- ``run.json``: how the run was started and how it ended (services, restarts, exit reason).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, TextIO


def _json_default(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return value.hex()
    if isinstance(value, (set, tuple)):
        return list(value)
    return repr(value)


class RunDir:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.log: TextIO = open(path / "supervisor.log", "a", encoding="utf-8")
        self._events: TextIO = open(path / "events.jsonl", "a", encoding="utf-8")

    @classmethod
    def create(cls, base: Path) -> RunDir:
        """A new folder ``base/YYYYmmdd-HHMMSS`` (``-2``, ``-3``... if two runs start in one second)."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        base.mkdir(parents=True, exist_ok=True)
        for n in range(1, 1000):
            path = base / (stamp if n == 1 else f"{stamp}-{n}")
            try:
                path.mkdir()
            except FileExistsError:
                continue
            return cls(path)
        raise RuntimeError(f"could not create a run folder under {base}")

    def event(self, record: dict[str, Any]) -> None:
        self._events.write(json.dumps(record, default=_json_default) + "\n")
        self._events.flush()

    def write_json(self, name: str, data: dict[str, Any]) -> Path:
        path = self.path / name
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=2, default=_json_default) + "\n")
        tmp.replace(path)  # never a half-written file, even if we are killed meanwhile
        return path

    def close(self) -> None:
        self._events.close()
        # The log is closed by Output, which owns writing to it.
