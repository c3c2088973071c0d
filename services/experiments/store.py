"""CSV files that survive a crash: one row appended per finished trial, then put in order at the end.

Every row is written with one ``write`` of a whole line, flushed and ``fsync``-ed before the next
trial is recorded, so a crash (even a power cut after the sync) loses nothing that finished. A
line cut short by a crash in the middle of a write has no newline at the end: :meth:`CsvStore.load`
drops it (the trial runs again on ``--resume``). Trials finish in whatever order the workers make,
so :meth:`CsvStore.rewrite` puts the rows in the sweep's order once the sweep is complete; it
writes a new file and renames it over the old one, so the file is never half-written.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
from collections.abc import Callable, Iterable
from pathlib import Path

log = logging.getLogger("arroch.experiment")


class StoreError(ValueError):
    """A CSV file that is not what this store writes."""


def _line(fields: tuple[str, ...], row: dict[str, str]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([row.get(name, "") for name in fields])
    return buf.getvalue()


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class CsvStore:
    def __init__(self, path: Path, fields: tuple[str, ...]) -> None:
        self.path = path
        self.fields = fields

    def exists(self) -> bool:
        return self.path.exists()

    def load(self) -> list[dict[str, str]]:
        """The rows written so far (a torn last line is dropped, with a warning)."""
        if not self.path.exists():
            return []
        text = self.path.read_text(encoding="utf-8")
        if text and not text.endswith("\n"):
            cut = text.rfind("\n") + 1
            log.warning(
                "%s: dropping an incomplete last line (%d characters) left by an interrupted write",
                self.path,
                len(text) - cut,
            )
            text = text[:cut]
        reader = csv.reader(io.StringIO(text))
        header = next(reader, None)
        if header is None:
            return []
        if tuple(header) != self.fields:
            raise StoreError(
                f"{self.path}: its columns are not this version's ({', '.join(header)}); use another --out folder"
            )
        rows = []
        for number, cells in enumerate(reader, start=2):
            if len(cells) != len(self.fields):
                raise StoreError(f"{self.path}: line {number} has {len(cells)} cells, expected {len(self.fields)}")
            rows.append(dict(zip(self.fields, cells, strict=True)))
        return rows

    def rewrite(self, rows: Iterable[dict[str, str]]) -> None:
        """Replace the file by ``rows`` (header first), atomically and durably."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w", encoding="utf-8", newline="") as out:
            out.write(_line(self.fields, {f: f for f in self.fields}))
            for row in rows:
                out.write(_line(self.fields, row))
            out.flush()
            os.fsync(out.fileno())
        tmp.replace(self.path)
        _fsync_dir(self.path.parent)

    def append(self, row: dict[str, str]) -> None:
        """Add one row durably (the header first if the file is new)."""
        if not self.path.exists():
            self.rewrite([])
        line = _line(self.fields, row)
        with open(self.path, "a", encoding="utf-8", newline="") as out:
            out.write(line)
            out.flush()
            os.fsync(out.fileno())

    def sort(self, order: Callable[[dict[str, str]], object]) -> None:
        """Put the rows in ``order`` (rewriting the file only when it is not in that order already)."""
        rows = self.load()
        ordered = sorted(rows, key=order)
        if ordered != rows or not self.path.read_text(encoding="utf-8").endswith("\n"):
            self.rewrite(ordered)


class JsonlStore:
    """One JSON object per line, with the same durability as :class:`CsvStore` (used for every
    finished trial's full metrics: bulky, and with wall-clock figures, so kept apart from the CSV)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def load(self) -> list[dict]:
        if not self.path.exists():
            return []
        records = []
        for number, line in enumerate(self.path.read_text(encoding="utf-8").splitlines(keepends=True), start=1):
            if not line.endswith("\n"):
                log.warning("%s: dropping an incomplete last line left by an interrupted write", self.path)
                break
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError as exc:
                raise StoreError(f"{self.path}: line {number} is not JSON ({exc})") from None
        return records

    def append(self, record: dict) -> None:
        with open(self.path, "a", encoding="utf-8") as out:
            out.write(json.dumps(record, sort_keys=True) + "\n")
            out.flush()
            os.fsync(out.fileno())

    def rewrite(self, records: Iterable[dict]) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w", encoding="utf-8") as out:
            for record in records:
                out.write(json.dumps(record, sort_keys=True) + "\n")
            out.flush()
            os.fsync(out.fileno())
        tmp.replace(self.path)
        _fsync_dir(self.path.parent)
