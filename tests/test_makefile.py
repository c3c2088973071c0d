"""The Makefile's set-up (dry runs, ``make -n``: nothing is installed): ``make demo`` installs only the
package, ``make test`` the test extras too, in one venv whose stamps say what each level has."""

from __future__ import annotations

import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

from tests.procs import ROOT

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")


def dry_run(target: str, venv: Path) -> list[str]:
    result = subprocess.run(
        ["make", "-n", target, f"VENV={venv}"], cwd=ROOT, capture_output=True, text=True, timeout=60, check=True
    )
    return result.stdout.splitlines()


def installs(lines: list[str]) -> list[str]:
    return [line.rsplit(" ", 1)[-1] for line in lines if "pip install" in line and " -e " in line]


def test_make_demo_installs_only_what_the_demo_needs(tmp_path: Path):
    lines = dry_run("demo", tmp_path / "venv")
    assert installs(lines) == ["'.'"], lines
    assert any(line.endswith("/bin/arroch demo") for line in lines)


def test_make_test_installs_the_test_extras_into_the_same_venv_and_stamps_both_levels(tmp_path: Path):
    venv = tmp_path / "venv"
    lines = dry_run("test", venv)
    assert installs(lines) == ["'.[test]'"], lines
    assert f"touch {venv}/.installed-test {venv}/.installed-demo" in lines
    # Once the test level is in, the demo needs nothing more.
    venv.mkdir()
    for stamp in (".installed-test", ".installed-demo"):
        (venv / stamp).touch()
    assert installs(dry_run("demo", venv)) == []


def test_make_bench_uses_the_test_level_which_holds_the_peers_extra(tmp_path: Path):
    venv = tmp_path / "venv"
    lines = dry_run("bench", venv)
    assert installs(lines) == ["'.[test]'"], lines
    assert f"touch {venv}/.installed-test {venv}/.installed-demo" in lines
    assert any("benchmarks/*.py" in line for line in lines)
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert any(dep.startswith("arroch[") and "peers" in dep for dep in extras["test"]), extras["test"]
