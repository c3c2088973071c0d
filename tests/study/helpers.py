"""What the study tests share: running one ``arroch study`` sub-command in-process."""

from __future__ import annotations

import argparse
from types import ModuleType

import pytest


def run_command(module: ModuleType, argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``arroch study <module> ARGV`` through the module's own parser and main: (exit code, stdout, stderr)."""
    parser = argparse.ArgumentParser(prog=f"arroch study {module.__name__.rsplit('.', 1)[-1]}")
    module.add_arguments(parser)
    code = module.main(parser.parse_args(argv))
    out = capsys.readouterr()
    return code, out.out, out.err
