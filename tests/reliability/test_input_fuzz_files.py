"""Bad input files: site files and constraint library files, mutated by hypothesis (derandomized, so
CI runs the same examples every time).

Two kinds of mutation of the packaged files: edits of the parsed document (values replaced by other
types, NaN, huge or negative numbers, entries deleted or duplicated, unknown keys), written back as
TOML; and edits of the raw bytes (flips, insertions, deletions, truncation: broken TOML, broken
UTF-8). Whatever the file, the loader either accepts it or refuses it with its one error type whose
message names the file and the problem; no other exception ever escapes. A library that loads also
resolves against the site.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from hypothesis import HealthCheck, given, settings

from protocol.site import SiteError, load_site
from protocol.site.load import default_site_path
from services.restrictor.library import LibraryError, library_for_site, load_library
from tests.reliability.fuzzing import byte_mutations, dump_toml, mutate, mutate_bytes, mutations

FUZZ = settings(
    max_examples=400,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

SITE_TEXT = default_site_path().read_bytes()
SITE_DOC = tomllib.loads(SITE_TEXT.decode())
LIBRARY_TEXT = resources.files("services.restrictor").joinpath("library.toml").read_bytes()
LIBRARY_DOC = tomllib.loads(LIBRARY_TEXT.decode())
OFFICE = load_site()


def check_site(path: Path) -> None:
    try:
        load_site(path)
    except SiteError as exc:
        assert exc.file == path.name and exc.problem, exc
        assert str(exc).startswith(f"{path.name}: "), exc


def check_library(path: Path) -> None:
    try:
        library = load_library(path)
    except LibraryError as exc:
        assert str(exc).startswith(f"{path.name}: ") and len(str(exc)) > len(path.name) + 2, exc
        return
    library_for_site(OFFICE, library)  # what the tablet and the AR client show: must not fail either


@FUZZ
@given(ops=mutations())
def test_mutated_site_documents_load_or_are_refused_by_name(tmp_path: Path, ops) -> None:
    path = tmp_path / "office.toml"
    path.write_text(dump_toml(mutate(SITE_DOC, ops)), encoding="utf-8")
    check_site(path)


@FUZZ
@given(ops=byte_mutations())
def test_mutated_site_bytes_load_or_are_refused_by_name(tmp_path: Path, ops) -> None:
    path = tmp_path / "office.toml"
    path.write_bytes(mutate_bytes(SITE_TEXT, ops))
    check_site(path)


@FUZZ
@given(ops=mutations())
def test_mutated_library_documents_load_or_are_refused_by_name(tmp_path: Path, ops) -> None:
    path = tmp_path / "library.toml"
    path.write_text(dump_toml(mutate(LIBRARY_DOC, ops)), encoding="utf-8")
    check_library(path)


@FUZZ
@given(ops=byte_mutations())
def test_mutated_library_bytes_load_or_are_refused_by_name(tmp_path: Path, ops) -> None:
    path = tmp_path / "library.toml"
    path.write_bytes(mutate_bytes(LIBRARY_TEXT, ops))
    check_library(path)


def test_the_unmutated_files_round_trip_through_the_writer(tmp_path: Path) -> None:
    # The mutations start from documents the writer reproduces exactly: what fails is the mutation.
    site, library = tmp_path / "office.toml", tmp_path / "library.toml"
    site.write_text(dump_toml(SITE_DOC), encoding="utf-8")
    library.write_text(dump_toml(LIBRARY_DOC), encoding="utf-8")
    assert load_site(site).robots.keys() == OFFICE.robots.keys()
    assert load_library(library).entries.keys() == load_library().entries.keys()
