"""The supervisor's one output: every child's lines prefixed with its name, merged, plus progress.

Lines go to the terminal (or whatever stdout is) and to the run's log file, which gets them with
their secrets redacted (:mod:`runtime.redact`: the tablet page's token, keys). On a terminal the
progress is a bar kept on the last line: a log line first erases it, then the bar is redrawn
below. Elsewhere (a pipe, a CI log) progress is an ordinary ``[up] progress ...`` line.
"""

from __future__ import annotations

import logging
import shutil
import threading
from typing import TextIO

from runtime.redact import Redactor

_ERASE = "\r\x1b[K"


class Output:
    def __init__(self, stream: TextIO, *, bar: bool) -> None:
        self.stream = stream
        self.bar = bar
        self.log_file: TextIO | None = None
        self._lock = threading.Lock()
        self._status = ""  # the bar currently drawn ("" when none)
        self._redactors: dict[str, Redactor] = {}  # per child: a key block spans several of its lines

    def attach_log(self, log_file: TextIO) -> None:
        with self._lock:
            self.log_file = log_file

    def line(self, name: str, text: str) -> None:
        """One line of ``name``'s output."""
        out = f"[{name}] {text}"
        with self._lock:
            if self._status:
                self.stream.write(_ERASE)
            self.stream.write(out + "\n")
            if self._status:
                self.stream.write(self._status)
            self.stream.flush()
            if self.log_file is not None:
                redact = self._redactors.setdefault(name, Redactor())
                self.log_file.write(f"[{name}] {redact(text)}\n")
                self.log_file.flush()

    def progress(self, text: str) -> None:
        """Show progress: redraw the bar on a terminal, else print (and log) a line."""
        if not self.bar:
            self.line("up", f"progress {text}")
            return
        width = shutil.get_terminal_size((100, 20)).columns
        with self._lock:
            self._status = text[: max(width - 1, 10)]
            self.stream.write(_ERASE + self._status)
            self.stream.flush()

    def end_progress(self) -> None:
        """Leave the last bar on screen (it is the final state) and move below it."""
        with self._lock:
            if self._status:
                self.stream.write("\n")
                self.stream.flush()
                self._status = ""

    def close(self) -> None:
        self.end_progress()
        with self._lock:
            if self.log_file is not None:
                self.log_file.close()
                self.log_file = None


class OutputHandler(logging.Handler):
    """Routes the supervisor's own log records into :class:`Output` as ``[up] ...`` lines."""

    def __init__(self, output: Output, name: str = "up") -> None:
        super().__init__()
        self.output = output
        self.prefix = name

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.output.line(self.prefix, self.format(record))
        except Exception:
            self.handleError(record)
