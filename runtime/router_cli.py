"""``arroch router``: a Zenoh router made of this project's own dependencies.

The ``zenohd`` binary is on neither PyPI nor Debian, so the infrastructure node is a zenoh-python
session in ``router`` mode: it routes between client-mode services and peers. It holds no
subscribers of its own and exits cleanly on SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading

from .signals import StopSignals
from .transport import DEFAULT_ROUTER, add_zenoh_arguments, open_session, options_from

log = logging.getLogger("arroch.router")


def run_router(args: argparse.Namespace) -> int:
    if not args.listen and not args.zenoh_config:
        args.listen = DEFAULT_ROUTER
    args.zenoh_mode = "router"
    try:
        opts = options_from(args)
        session = open_session(opts)
    except Exception as exc:
        log.error("could not start the router: %s", exc)
        return 1
    signals = StopSignals()
    signals.install()
    log.info("router %s listening on %s", session.zid(), ", ".join(opts.listen) or "(config file)")
    print(f"router ready on {', '.join(opts.listen) or 'the config file endpoints'}", flush=True)
    signals.wait()
    closer = threading.Thread(target=session.close, daemon=True)
    closer.start()
    closer.join(1.5)
    log.info("router stopped")
    if closer.is_alive():
        # close() overran its budget and still runs: a normal interpreter exit would wait for it
        # forever (the router would outlive a SIGTERM). Leave now, output flushed.
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "router",
        help="run a Zenoh router (zenoh-python in router mode)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_zenoh_arguments(parser)
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    parser.set_defaults(func=run_router)
