"""One exit code per kind of error across commands (docs/architecture.md, "Exit codes"): every command
that takes a site exits 2 (bad input, as argparse does for bad usage) on a site file it refuses, with
one line naming the file, before it starts anything."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.cli import main
from tests.procs import ROOT

BAD_SITE = 'name = "bad"\n[[rooms]]\nid = 1\n'  # not a site: an unknown table, a room without its fields
EXIT_BAD_INPUT = 2

# Each command as a newcomer would run it on a site file (FILE is replaced by the bad one).
COMMANDS: dict[str, tuple[str, ...]] = {
    "site check": ("site", "check", "FILE"),
    "site show": ("site", "show", "FILE", "--png", "out.png"),
    "demo": ("demo", "--site", "FILE", "--no-linger", "--run-dir", "runs"),
    "up": ("up", "--site", "FILE", "--until-done"),
    "plan": ("plan", "--site", "FILE"),
    "sim": ("sim", "--site", "FILE"),
    "planner": ("planner", "--site", "FILE"),
    "restrictor": ("restrictor", "--site", "FILE"),
    "ar": ("ar", "--site", "FILE"),
    "tablet": ("tablet", "--site", "FILE"),
}


def run(argv: list[str], capfd: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """(exit code, everything printed) of ``arroch <argv>``, in this process (a start-up each is slow)."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capfd.readouterr()
    return code, out + err


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_refused_site_exits_2_naming_the_file(command: str, tmp_path: Path, monkeypatch, capfd):  # noqa: ANN001
    site = tmp_path / "bad.toml"
    site.write_text(BAD_SITE)
    monkeypatch.chdir(tmp_path)
    code, printed = run([str(site) if a == "FILE" else a for a in COMMANDS[command]], capfd)
    assert code == EXIT_BAD_INPUT, (command, code, printed[-2000:])
    assert "bad.toml" in printed and "Traceback" not in printed, printed[-2000:]
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())  # nothing started


def test_the_table_is_documented():
    text = (ROOT / "docs" / "architecture.md").read_text()
    table = text[text.index("### Exit codes") :].split("\n\n")[2]
    assert [line.split("|")[1].strip() for line in table.splitlines()[2:]] == ["0", "1", "2", "3", "4", "128+N"]
