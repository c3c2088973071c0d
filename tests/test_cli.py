"""The ``arroch`` command itself: what a new user tries first."""

from __future__ import annotations

import subprocess
from importlib.metadata import version

from tests.procs import ROOT, arroch


def test_version_is_the_installed_distributions() -> None:
    out = subprocess.run(arroch("--version"), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == f"arroch {version('arroch')}"
