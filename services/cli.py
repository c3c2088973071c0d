"""The ``arroch`` command: one sub-command per service or tool.

Each entry of :data:`COMMANDS` is a module exposing ``register(subparsers)``, which adds its
sub-command(s) and sets ``func`` on the parsed arguments. A command imports only its own
module(s); ``arroch --help`` imports them all and is the one place that lists everything.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from runtime.runner import setup_logging

#: Each module and the top-level commands its ``register`` adds (``ar`` is extended by the tablet's
#: module with ``ar calibrate``). tests/test_cli_registry.py checks this against the modules.
COMMANDS: dict[str, tuple[str, ...]] = {
    "runtime.site.cli": ("site",),  # arroch site check|show|generate
    "runtime.router_cli": ("router",),
    "runtime.ping": ("ping",),  # arroch ping serve|send (protocol round trip)
    "services.demo": ("demo",),
    "services.planner.cli": ("planner", "plan"),
    "services.restrictor.cli": ("restrictor", "feedback", "constraints"),
    "services.sim.cli": ("sim",),  # arroch sim, sim snapshot
    "services.robot.cli": ("robot",),  # arroch robot --ros2
    "services.ros2.cli": ("ros2",),  # arroch ros2 bridge
    "services.ar_client.cli": ("ar", "tags"),  # arroch ar, ar localize|render, tags
    "services.ar_client.web.cli": ("tablet", "ar"),  # arroch tablet, ar calibrate
    "services.supervisor.cli": ("up", "deploy"),
    "services.experiments.cli": ("experiment",),
    "services.recorder.cli": ("record", "view", "replay", "runs"),
    "services.study.cli": ("study",),  # arroch study plan|run|report|calibrate
    "services.graph.cli": ("graph",),  # arroch graph [--format text|json|dot|markdown] [--out FILE.png|.svg]
}
#: Modules whose ``register`` extends another's commands, with the module they need first.
REQUIRES: dict[str, str] = {"services.ar_client.web.cli": "services.ar_client.cli"}


def modules_for(argv: list[str]) -> list[str]:
    """The modules to import for ``argv``: only those of its command when it names one.

    Importing every service's CLI costs ~0.3 s of CPU; a sweep starts several services per trial,
    each through this dispatcher, so a service's start-up imports only its own command's module.
    Help, version, options before the command and unknown commands get every module.
    """
    command = argv[0] if argv and not argv[0].startswith("-") else None
    wanted = {m for m, commands in COMMANDS.items() if command in commands}
    wanted |= {REQUIRES[m] for m in wanted if m in REQUIRES}
    return [m for m in COMMANDS if m in wanted] or list(COMMANDS)


def installed_version() -> str:
    """The installed distribution's version (``pip install -e .`` included)."""
    from importlib.metadata import PackageNotFoundError, version  # only for --version: ~60 ms a lookup

    try:
        return version("arroch")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed: pip install -e .)"


class _VersionAction(argparse.Action):
    """``--version``: looks the version up only when asked (every service starts through this parser)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="print the version and exit")

    def __call__(self, parser: argparse.ArgumentParser, *_args: object, **_kwargs: object) -> None:
        print(f"{parser.prog} {installed_version()}")
        parser.exit()


def build_parser(modules: list[str] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="arroch",
        description="ARROCH: AR for robots collaborating with a human. Services and tools.",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMANDS if modules is None else modules:
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
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(modules_for(argv))
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    setup_logging(getattr(args, "log_level", None))
    result = args.func(args)
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
