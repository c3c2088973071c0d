"""The figures the docs quote from a demo run are the ones ``make docs`` measured (``docs/make_docs.py``
writes ``docs/figures.json`` and rewrites every ``<!--figure:KEY-->TEXT<!--/figure-->`` quote in README.md,
docs/*.md and docs/services/*.md): every quote names a measured figure and shows its text, and every
figure is quoted somewhere."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from tests.procs import ROOT

FIGURES = ROOT / "docs" / "figures.json"


def _make_docs():  # noqa: ANN202
    spec = importlib.util.spec_from_file_location("make_docs", ROOT / "docs" / "make_docs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


make_docs = _make_docs()


def quotes() -> list[tuple[Path, str, str]]:
    """(file, key, quoted text) of every figure the docs quote."""
    return [
        (path, match.group(1), match.group(2))
        for path in make_docs.quoted_files()
        for match in make_docs.QUOTE.finditer(path.read_text(encoding="utf-8"))
    ]


def test_every_quoted_figure_is_the_one_make_docs_measured():
    figures = json.loads(FIGURES.read_text())
    found = quotes()
    assert len(found) >= 10
    scanned = set(make_docs.quoted_files())
    assert set((ROOT / "docs" / "services").glob("*.md")) <= scanned, "a service page make docs does not rewrite"
    for path, key, text in found:
        assert key in figures, f"{path.name} quotes {key!r}: not in {FIGURES.name} (run make docs)"
        assert text == figures[key]["text"], (
            f"{path.name}: {key} is quoted as {text!r}, measured {figures[key]['text']!r}"
        )
    assert set(figures) == {key for _, key, _ in found}, "a measured figure no doc quotes"
    assert (ROOT / "docs" / "demo-timeline.png").read_bytes()[:4] == b"\x89PNG"


def test_requoting_replaces_the_text_and_refuses_an_unknown_figure():
    figures = {"demo.wall_s": make_docs.Figure(61.2, "61 s")}
    text = "took <!--figure:demo.wall_s-->12 s<!--/figure--> of wall time"
    assert make_docs.requote(text, figures, "x.md") == "took <!--figure:demo.wall_s-->61 s<!--/figure--> of wall time"
    with pytest.raises(SystemExit, match="x.md quotes figure 'demo.nope'"):
        make_docs.requote("<!--figure:demo.nope-->1<!--/figure-->", figures, "x.md")
