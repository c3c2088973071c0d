"""The CSV store: durable appends, a torn last line dropped, order restored at the end."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.experiments.store import CsvStore, JsonlStore, StoreError

FIELDS = ("trial", "status", "reason")


def test_append_load_and_sort(tmp_path: Path) -> None:
    store = CsvStore(tmp_path / "t.csv", FIELDS)
    for trial in (2, 0, 1):
        store.append(
            {"trial": str(trial), "status": "ok", "reason": 'a "quoted", reason\nover two lines' if trial == 1 else ""}
        )
    assert [r["trial"] for r in store.load()] == ["2", "0", "1"]
    assert store.load()[2]["reason"] == 'a "quoted", reason\nover two lines'
    store.sort(lambda r: int(r["trial"]))
    assert [r["trial"] for r in store.load()] == ["0", "1", "2"]
    assert (tmp_path / "t.csv").read_text().startswith("trial,status,reason\n0,ok,\n")


def test_a_line_torn_by_a_crash_is_dropped(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    store = CsvStore(tmp_path / "t.csv", FIELDS)
    store.append({"trial": "0", "status": "ok", "reason": ""})
    with open(tmp_path / "t.csv", "a") as out:
        out.write("1,o")  # killed in the middle of a write
    assert [r["trial"] for r in store.load()] == ["0"]
    assert "incomplete last line" in caplog.text


def test_other_columns_are_refused(tmp_path: Path) -> None:
    (tmp_path / "t.csv").write_text("trial,status\n0,ok\n")
    with pytest.raises(StoreError, match="columns are not this version's"):
        CsvStore(tmp_path / "t.csv", FIELDS).load()


def test_jsonl(tmp_path: Path) -> None:
    store = JsonlStore(tmp_path / "m.jsonl")
    store.append({"b": 1, "a": [1.5]})
    with open(tmp_path / "m.jsonl", "a") as out:
        out.write('{"torn":')
    assert store.load() == [{"a": [1.5], "b": 1}]
    store.rewrite([{"x": 1}])
    assert (tmp_path / "m.jsonl").read_text() == '{"x": 1}\n'
