"""``arroch study plan``: counterbalanced orders, seeds, the files written and the refusals."""

from __future__ import annotations

import json
from collections import Counter
from itertools import pairwise
from pathlib import Path

import pytest

from services.study import plan as plan_cmd
from services.study.layout import CONDITIONS, PuzzleSpec, StudyFolder, WorldSpec
from services.study.plan import build_plan, williams_orders
from tests.study.helpers import run_command


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_williams_orders_are_balanced(n: int) -> None:
    rows = williams_orders(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    assert all(sorted(row) == list(range(n)) for row in rows)
    for position in range(n):  # every condition in every position equally often
        assert set(Counter(row[position] for row in rows).values()) == {len(rows) // n}
    carry = Counter((a, b) for row in rows for a, b in pairwise(row))
    assert set(carry) == {(a, b) for a in range(n) for b in range(n) if a != b}
    assert set(carry.values()) == {1 if n % 2 == 0 else 2}  # first-order carry-over balanced


def _plan(n: int, conditions: list[str], seed: int = 7):
    return build_plan(
        name="t",
        seed=seed,
        conditions=conditions,
        participant_ids=[f"P{i:02d}" for i in range(1, n + 1)],
        questionnaires=["arroch-q"],
        puzzle=PuzzleSpec(),
        world=WorldSpec(),
        created="2026-01-01T00:00:00Z",
    )


def test_two_conditions_half_start_with_each() -> None:
    for seed in range(5):
        plan = _plan(12, ["arroch", "map"], seed)
        firsts = Counter(p.trials[0].condition for p in plan.participants)
        assert firsts == {"arroch": 6, "map": 6}
        assert all({t.condition for t in p.trials} == {"arroch", "map"} for p in plan.participants)


def test_three_conditions_balanced_over_whole_blocks() -> None:
    conditions = list(CONDITIONS)
    plan = _plan(12, conditions)  # two blocks of the six orders
    orders = [tuple(t.condition for t in p.trials) for p in plan.participants]
    assert Counter(orders[:6]) == Counter(orders[6:])  # each block holds every order once
    assert len(set(orders[:6])) == 6
    for position in range(3):
        assert set(Counter(o[position] for o in orders).values()) == {4}
    carry = Counter(pair for o in orders for pair in pairwise(o))
    assert len(carry) == 6 and set(carry.values()) == {4}


def test_seeds_paired_within_and_distinct_across() -> None:
    plan = _plan(10, ["arroch", "no-feedback", "map"])
    worlds = [p.trials[0].world_seed for p in plan.participants]
    assert all(len({t.world_seed for t in p.trials}) == 1 for p in plan.participants)
    assert len(set(worlds)) == len(worlds)
    puzzles = [t.puzzle_seed for p in plan.participants for t in p.trials]
    assert len(set(puzzles)) == len(puzzles)
    assert all(0 <= s < 2**31 for s in worlds + puzzles)
    assert all(t.id == f"{p.id}-T{t.index}-{t.condition}" for p in plan.participants for t in p.trials)


def test_deterministic_for_a_seed_and_different_for_another() -> None:
    a, b, c = _plan(8, ["arroch", "map"], 7), _plan(8, ["arroch", "map"], 7), _plan(8, ["arroch", "map"], 8)
    assert a == b
    assert [p.trials for p in a.participants] != [p.trials for p in c.participants]
    # Adding participants leaves the first ones' seeds as they were.
    longer = _plan(12, ["arroch", "map"], 7)
    assert [p.trials[0].world_seed for p in longer.participants[:8]] == [p.trials[0].world_seed for p in a.participants]


def test_cli_writes_plan_and_consent(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "pilot"
    code, stdout, err = run_command(plan_cmd, ["--participants", "4", "--seed", "3", "--out", str(out)], capsys)
    assert code == 0, err
    plan = StudyFolder(out).plan()
    assert plan.ids() == ["P01", "P02", "P03", "P04"] and plan.seed == 3 and plan.conditions == ["arroch", "map"]
    assert plan.design.startswith("balanced-latin-square (Williams")
    consent = (out / "consent.txt").read_text()
    assert "<<" in consent and "edit" in stdout.lower()
    for p in plan.participants:  # the printed table shows each participant's order
        assert any(line.split()[0] == p.id and line.split()[2:] == [t.condition for t in p.trials]
                   for line in stdout.splitlines() if line.strip())  # fmt: skip
    # A second plan into the same folder is refused, naming the file; the first is untouched.
    before = (out / "study.json").read_bytes()
    code, _, err = run_command(plan_cmd, ["--participants", "6", "--out", str(out)], capsys)
    assert code == 2 and str(out / "study.json") in err
    assert (out / "study.json").read_bytes() == before


def test_cli_keeps_an_existing_consent_form_and_takes_ids(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s"
    out.mkdir()
    (out / "consent.txt").write_text("our approved form")
    argv = ["--ids", "P07,P09", "--conditions", "arroch,no-feedback,map", "--seed", "1", "--out", str(out)]
    argv += ["--questionnaires", "arroch-q,nasa-tlx", "--puzzle", "3x5", "--mode", "rate", "--rate", "4"]
    code, _, err = run_command(plan_cmd, argv, capsys)
    assert code == 0, err
    assert (out / "consent.txt").read_text() == "our approved form"
    data = json.loads((out / "study.json").read_text())
    assert [p["id"] for p in data["participants"]] == ["P07", "P09"]
    assert data["questionnaires"] == ["arroch-q", "nasa-tlx"]
    assert data["puzzle"] == {"rows": 3, "cols": 5} and data["world"]["rate"] == 4.0
    assert "square and mirror, 6 orders" in data["design"]


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--participants", "4", "--conditions", "arroch,nocomm"], "nocomm"),
        (["--participants", "4", "--conditions", "arroch"], "at least two"),
        (["--participants", "4", "--conditions", "arroch,arroch"], "twice"),
        (["--ids", "P01,Alice"], "Alice"),
        (["--ids", "P01,P02", "--participants", "3"], "--participants 3"),
        (["--participants", "4", "--puzzle", "big"], "ROWSxCOLS"),
        (["--participants", "4", "--questionnaires", "sus"], "--questionnaires"),
        (["--participants", "4", "--site", "/nonexistent/site.toml"], "does not exist"),
        ([], "--participants"),
    ],
)
def test_cli_refusals(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str) -> None:
    code, _, err = run_command(plan_cmd, [*argv, "--out", str(tmp_path / "s")], capsys)
    assert code == 2 and words in err
    assert not (tmp_path / "s" / "study.json").exists()
