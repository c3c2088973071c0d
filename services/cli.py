"""The ``arroch`` command: one sub-command per service or tool.

Each entry of :data:`COMMANDS` is a module exposing ``register(subparsers)``, which adds its
sub-command(s) and sets ``func`` on the parsed arguments. Modules are imported only when the
CLI starts, so ``arroch --help`` is the one place that lists everything.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from importlib.metadata import PackageNotFoundError, version

from protocol.runner import setup_logging

COMMANDS: tuple[str, ...] = (
    "protocol.site.cli",  # arroch site check|show|generate
    "protocol.router_cli",  # arroch router
    "protocol.ping",  # arroch ping serve|send (protocol round trip)
    "services.demo",  # arroch demo
    "services.planner.cli",  # arroch planner, arroch plan
    "services.restrictor.cli",  # arroch restrictor, feedback, constraints
    "services.sim.cli",  # arroch sim, sim snapshot
    "services.robot.cli",  # arroch robot --ros2
    "services.ros2.cli",  # arroch ros2 bridge
    "services.ar_client.cli",  # arroch ar, ar localize|render, tags
    "services.ar_client.web.cli",  # arroch tablet, ar calibrate
    "services.supervisor.cli",  # arroch up
    "services.experiments.cli",  # arroch experiment
    "services.recorder.cli",  # arroch record, view, replay, runs show
)


def installed_version() -> str:
    """The installed distribution's version (``pip install -e .`` included)."""
    try:
        return version("arroch")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed: pip install -e .)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="arroch",
        description="ARROCH: AR for robots collaborating with a human. Services and tools.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {installed_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMANDS:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            # Only a module that is not part of this installation is skipped; a broken import
            # inside an existing module is a bug and must surface.
            if exc.name is not None and module_name.startswith(exc.name):
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    setup_logging(getattr(args, "log_level", None))
    result = args.func(args)
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
