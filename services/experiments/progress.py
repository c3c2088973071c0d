"""The sweep's progress: a bar with the time left on a terminal, a line now and then elsewhere.

The time left is the wall time per finished trial so far (in this session: a resumed sweep's old
trials took no time now) times the trials left. Trials are scheduled repetition by repetition, so
the ones finished so far are a fair sample of all conditions, big teams and small ones alike.
"""

from __future__ import annotations

import logging
import shutil
import sys
import threading
import time
from typing import TextIO


def clock(seconds: float) -> str:
    """``1:02:03`` / ``02:03``."""
    seconds = max(0, int(round(seconds)))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


class Progress:
    def __init__(
        self,
        total: int,
        done_before: int,
        *,
        label: str,
        stream: TextIO | None = None,
        bar: bool | None = None,
        interval: float = 30.0,
    ) -> None:
        self.total = total
        self.done_before = done_before
        self.label = label
        self.stream = stream or sys.stderr
        self.bar = self.stream.isatty() if bar is None else bar
        self.interval = interval  # s between lines when there is no bar
        self.started = time.monotonic()
        self.done = 0  # finished in this session
        self.failed = 0
        self.last = ""
        self._shown = 0.0
        self._printed = ""
        self._lock = threading.Lock()

    def eta(self, now: float | None = None) -> float | None:
        """Seconds left, or None before the first trial of this session finished."""
        if self.done == 0:
            return None
        elapsed = (now or time.monotonic()) - self.started
        left = self.total - self.done_before - self.done
        return elapsed / self.done * left

    def text(self, now: float | None = None, width: int = 20) -> str:
        now = now or time.monotonic()
        finished = self.done_before + self.done
        filled = round(width * finished / self.total) if self.total else width
        eta = self.eta(now)
        parts = [
            f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {finished}/{self.total}",
            f"elapsed {clock(now - self.started)}",
            f"left {'~' + clock(eta) if eta is not None else '?'}",
        ]
        if self.failed:
            parts.append(f"{self.failed} failed")
        if self.last:
            parts.append(self.last)
        return " | ".join(parts)

    def finished(self, description: str, ok: bool) -> None:
        """One more trial done (``description`` says which and how)."""
        with self._lock:
            self.done += 1
            self.failed += 0 if ok else 1
            self.last = description
            self._show(force=not self.bar and (not ok or self._due()))

    def tick(self) -> None:
        """Refresh the bar (elapsed time moves on between trials)."""
        with self._lock:
            self._show(force=False)

    def _due(self) -> bool:
        return time.monotonic() - self._shown >= self.interval

    def _show(self, *, force: bool) -> None:
        if self.bar:
            width = shutil.get_terminal_size((120, 20)).columns
            self.stream.write("\r\x1b[K" + self.text()[: width - 1])
            self.stream.flush()
        elif force:
            self._shown = time.monotonic()
            self._printed = self.text()
            self.stream.write(self._printed + "\n")
            self.stream.flush()

    def line(self, text: str) -> None:
        """A log line above the bar (the bar is erased first, then drawn again below it)."""
        with self._lock:
            if self.bar:
                self.stream.write("\r\x1b[K")
            self.stream.write(text + "\n")
            self._show(force=False)
            self.stream.flush()

    def close(self) -> None:
        with self._lock:
            text = self.text()
            if self.bar:
                self.stream.write("\r\x1b[K" + text + "\n")
            elif text != self._printed:  # not the line just printed once more
                self.stream.write(text + "\n")
            self.stream.flush()


class ProgressLogHandler(logging.Handler):
    """Log records printed through :meth:`Progress.line`, so they never tear the bar."""

    def __init__(self, progress: Progress) -> None:
        super().__init__()
        self.progress = progress

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.progress.line(self.format(record))
        except Exception:
            self.handleError(record)
