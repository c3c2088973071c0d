"""Exec wrapper for ``arroch up``'s children: ``python pdeath.py SUPERVISOR_PID -- COMMAND...``.

On Linux it asks the kernel to send SIGTERM to this process when its parent dies
(``PR_SET_PDEATHSIG``), then replaces itself with COMMAND (the setting survives ``exec``). So even
a supervisor killed with SIGKILL leaves no service behind. If the supervisor already died before
the request was made, the command is not started at all. Elsewhere it only execs.

It runs as a plain script (no package imports) so that it costs one short interpreter start.
"""

from __future__ import annotations

import os
import signal
import sys

PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        print(f"pdeath: prctl(PR_SET_PDEATHSIG) failed: {os.strerror(ctypes.get_errno())}", file=sys.stderr)


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] != "--":
        print("usage: pdeath.py SUPERVISOR_PID -- COMMAND [ARG...]", file=sys.stderr)
        return 2
    supervisor = int(argv[0])
    command = argv[2:]
    _die_with_parent()
    # The supervisor may have died between fork and prctl: then we were re-parented already.
    if os.getppid() != supervisor:
        return 1
    try:
        os.execvp(command[0], command)
    except OSError as exc:
        print(f"pdeath: cannot run {command[0]}: {exc}", file=sys.stderr)
        return 127
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
