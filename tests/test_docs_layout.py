"""The docs' layout: docs/architecture.md stays an overview (at most 400 lines) that links a page per
service under docs/services/, and every relative link in README.md, docs/*.md and docs/services/*.md
leads to a file that exists and, with a ``#anchor``, to a heading that file has (anchors as GitHub
makes them)."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

from tests.procs import ROOT

DOCS = ROOT / "docs"
OVERVIEW = DOCS / "architecture.md"
MAX_OVERVIEW_LINES = 400
SERVICE_PAGES = (
    "protocol",
    "planner",
    "restrictor",
    "sim",
    "robot",
    "ar_client",
    "recorder",
    "supervisor",
    "experiments",
    "study",
)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
FENCE = re.compile(r"^\s*(```|~~~)")


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted((DOCS / "services").glob("*.md"))]


def prose_lines(path: Path) -> list[str]:
    """The file's lines outside fenced code blocks (a ``#`` there is a comment, a ``](`` is code)."""
    lines, fenced = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            lines.append(line)
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces turned into hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file; repeated headings get -1, -2, ... as on GitHub."""
    seen: dict[str, int] = {}
    found = set()
    for line in prose_lines(path):
        match = HEADING.match(line)
        if not match:
            continue
        base = slug(match.group(2))
        count = seen.get(base, 0)
        seen[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def relative_links(path: Path) -> list[str]:
    """The link targets of a file that are neither URLs nor mail addresses."""
    targets = []
    for line in prose_lines(path):
        for target in LINK.findall(re.sub(r"`[^`]*`", "", line)):
            if not re.match(r"^[a-z][a-z0-9+.-]*:", target):
                targets.append(target)
    return targets


def test_the_overview_is_short():
    lines = OVERVIEW.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_OVERVIEW_LINES, f"{OVERVIEW.name}: {lines} lines, at most {MAX_OVERVIEW_LINES}"


@pytest.mark.parametrize("name", SERVICE_PAGES)
def test_each_service_page_exists_and_is_linked_from_the_overview(name: str):
    page = DOCS / "services" / f"{name}.md"
    assert page.is_file(), f"{page.relative_to(ROOT)} is missing"
    targets = {target.split("#", 1)[0] for target in relative_links(OVERVIEW)}
    assert f"services/{name}.md" in targets, f"{OVERVIEW.name} does not link services/{name}.md"


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(path: Path):
    broken = []
    for target in relative_links(path):
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / unquote(file_part)).resolve() if file_part else path
        if not linked.exists():
            broken.append(f"{target}: no file {linked.relative_to(ROOT) if linked.is_relative_to(ROOT) else linked}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading #{anchor} in {linked.relative_to(ROOT)}")
    assert not broken, f"{path.relative_to(ROOT)}: " + "; ".join(broken)


def test_slugs_are_githubs():
    assert slug("Execution contract (planner ↔ sim or real robot)") == "execution-contract-planner--sim-or-real-robot"
    assert slug("Protocol figures (`benchmarks/protocol.py`)") == "protocol-figures-benchmarksprotocolpy"
    assert slug("Tablet (`services/ar_client/web/`)") == "tablet-servicesar_clientweb"
