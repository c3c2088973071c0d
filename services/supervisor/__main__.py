"""``python -m services.supervisor [options]`` is ``arroch up [options]``."""

from __future__ import annotations

import argparse
import sys

from runtime.runner import setup_logging

from .cli import __doc__ as UP_DOC
from .cli import add_up_arguments, run_up


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m services.supervisor", description=UP_DOC, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_up_arguments(parser)
    args = parser.parse_args(argv)
    setup_logging(args.log_level)
    return run_up(args)


if __name__ == "__main__":
    sys.exit(main())
