"""Secrets kept out of files: what a log line may carry that must never reach a log file or a recording.

Redacted, value only (the name stays, so a reader still sees what was there):

- ``name=value`` where the name ends in ``token``, ``password``, ``passwd``, ``secret`` or ``api_key``
  (``?token=...`` in the tablet page's URL, ``access_token=...``, ``db_password=...``);
- the same names as quoted JSON keys (``"token": "..."``);
- HTTP credentials after ``Bearer`` or ``Basic``;
- every line of a PEM private key block, from its ``BEGIN ... PRIVATE KEY`` line to its ``END`` line.

A :class:`Redactor` follows one stream of lines (the PEM block spans several); the terminal still
shows what a child printed, only what is written to files goes through here.
"""

from __future__ import annotations

import re

REDACTED = "<redacted>"
_NAME = r"[A-Za-z0-9_\-]*(?:token|password|passwd|secret|api[_\-]?key)"
_ASSIGNED = re.compile(rf"(?i)(?<![A-Za-z0-9_\-])({_NAME}=)([^\s&#\"',;]+)")
_QUOTED = re.compile(rf"(?i)([\"']{_NAME}[\"']\s*:\s*[\"'])([^\"']+)")
_AUTH = re.compile(r"(?i)\b((?:bearer|basic)\s+)[A-Za-z0-9._~+/\-]{8,}=*")
_PEM_BEGIN = re.compile(r"-----BEGIN [A-Z0-9 ]*PRIVATE KEY-----")
_PEM_END = re.compile(r"-----END [A-Z0-9 ]*PRIVATE KEY-----")


def redact(text: str) -> str:
    """``text`` with the secrets of one line replaced by :data:`REDACTED`."""
    text = _ASSIGNED.sub(rf"\1{REDACTED}", text)
    text = _QUOTED.sub(rf"\1{REDACTED}", text)
    return _AUTH.sub(rf"\1{REDACTED}", text)


class Redactor:
    """:func:`redact` for a stream of lines, private key blocks included."""

    def __init__(self) -> None:
        self._in_key = False

    def __call__(self, line: str) -> str:
        if self._in_key or _PEM_BEGIN.search(line):
            self._in_key = not _PEM_END.search(line)
            return REDACTED
        return redact(line)
