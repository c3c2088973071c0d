"""What every service's command line shares: logging, the common options, and running a service."""

from __future__ import annotations

import argparse
import faulthandler
import logging
import os
import signal
import sys
from collections.abc import Callable

from .transport import add_zenoh_arguments, options_from

LOG_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def setup_logging(level: str | None = None) -> None:
    """Log to stderr at ``level`` (or ``ARROCH_LOG_LEVEL``, default INFO)."""
    chosen = (level or os.environ.get("ARROCH_LOG_LEVEL") or "INFO").upper()
    logging.basicConfig(level=chosen, format=LOG_FORMAT, stream=sys.stderr, force=True)
    # zenoh's Rust logs go through its own env var; keep them quiet unless asked.
    os.environ.setdefault("RUST_LOG", "error")
    if hasattr(signal, "SIGUSR1"):
        # `kill -USR1 PID` prints every thread's stack: what a service that stopped answering is doing
        try:
            faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)
        except (AttributeError, OSError, ValueError):  # no stderr with a file descriptor: no stack dumps
            pass


def add_common_arguments(parser: argparse.ArgumentParser, *, site: bool = True, zenoh: bool = True) -> None:
    """--site, --namespace, --clock, --log-level and the Zenoh options."""
    if site:
        parser.add_argument(
            "--site",
            "--config",
            dest="site",
            metavar="FILE",
            help="site file (TOML); default: the packaged 'office' site",
        )
        parser.add_argument(
            "--namespace", metavar="NAME", help="key namespace arroch/<NAME>/...; default: the site's name"
        )
        parser.add_argument(
            "--clock",
            choices=("sim", "wall"),
            default="sim",
            help="site clock source (default sim: the simulator's clock messages)",
        )
    parser.add_argument(
        "--log-level",
        default=None,
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="log level (env ARROCH_LOG_LEVEL, default INFO)",
    )
    if zenoh:
        add_zenoh_arguments(parser)


def run_service(build: Callable[[], object]) -> int:
    """Build a service, open it, run until SIGINT/SIGTERM, close. Returns the exit code.

    ``build`` may raise ``ValueError``/``FileNotFoundError`` for bad configuration: that is
    reported in one line and exit code 2, before any Zenoh session exists.
    """
    try:
        service = build()
    except (ValueError, FileNotFoundError) as exc:
        logging.getLogger("arroch").error("%s", exc)
        return 2
    service.install_signal_handlers()  # type: ignore[attr-defined]
    try:
        service.open()  # type: ignore[attr-defined]
    except Exception as exc:
        logging.getLogger("arroch").error("could not start: %s", exc)
        service.close()  # type: ignore[attr-defined]
        return 1
    service.run()  # type: ignore[attr-defined]
    code = int(getattr(service, "exit_code", 0))  # a service that gave up sets it (e.g. the sim's lockstep abort)
    return leave_if_close_overran(service, code)


def leave_if_close_overran(service: object, code: int) -> int:
    """``code``, or, when the service's Zenoh close() overran its budget, the process ends here with it.

    The close still runs on a daemon thread; a normal interpreter exit would wait for the session
    forever (zenoh-python issue 434) or abort tearing down its threads. Output is flushed first."""
    if getattr(service, "close_timed_out", False):
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def zenoh_options(args: argparse.Namespace):
    return options_from(args)


def namespace_from(args: argparse.Namespace) -> str:
    """The key namespace: ``--namespace`` if given, else the name of the site (``--site`` or the
    packaged default). Raises ``ValueError`` for a bad site file (see :func:`run_service`)."""
    if getattr(args, "namespace", None):
        return args.namespace
    from protocol.site import load_site  # only when needed: loading a site is not free

    return load_site(getattr(args, "site", None)).name
