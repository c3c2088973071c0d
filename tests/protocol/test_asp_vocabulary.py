"""The ASP check every piece of restrictor ASP passes: plain rules over the shared vocabulary only."""

from __future__ import annotations

import pytest

from protocol.asp_vocabulary import VOCABULARY, UnsafeProgram, is_asp_constant
from runtime.asp_check import check_program

ACCEPTED = [
    (
        "human_unavailable(d, 0, 60).\n:- human_opens(d, T), T >= 0, T < 60.",
        {("human_unavailable", 3), ("human_opens", 2)},
    ),
    ("room_forbidden(r, 0, 60).\n:- robot_in(R, r, S, E), S < 60, E > 0.", {("room_forbidden", 3), ("robot_in", 4)}),
    (":- goes_through(R, p, T), T < 10.", {("goes_through", 3)}),
    (":- #count { R : robot_in(R, r, S, E) } > 1.", {("robot_in", 4)}),
    (":~ human_opens(D, T). [T@1, D]", {("human_opens", 2)}),
    ("human_available(d, 0, 60).", {("human_available", 3)}),
]

REFUSED = [
    ("p(1).", "not in the shared vocabulary"),
    ("human_opens(d, 1) :- q.", "q/0"),
    ("human_opens(d).", "human_opens/1"),  # right name, wrong arity
    ('#include "/etc/passwd".', "strings"),
    ("#include <incmode>.", "directive #include"),
    ("# include <incmode>.", "directive #include"),
    ("#script (python)\nimport os\n#end.", "directive #script"),
    ("#program step(t).", "directive #program"),
    ("#const n = 3.", "directive #const"),
    ("#show human_opens/2.", "directive #show"),
    ("#external human_opens(d, 1).", "directive #external"),
    ("#minimize { T : human_opens(D, T) }.", "directive #minimize"),
    ("#heuristic human_opens(d, 1). [1, true]", "directive #heuristic"),
    ("human_opens(d, 1). % a comment", "comments"),
    ("human_opens(d, 1). %* block *%", "comments"),
    ("human_opens(@f(1), 2).", "external function calls"),
    (":- human_opens(D, T), @g(T) > 1.", "external function calls"),
    ("&diff { a - b } <= 3.", "theory atoms"),
    ("human_opens(d\u00e9, 1).", "non-ASCII"),
    (":- human_opens(d, T)", "not valid ASP"),
    ("human_opens(d, 1", "not valid ASP"),
]


@pytest.mark.parametrize("text,signatures", ACCEPTED)
def test_plain_programs_over_the_vocabulary_pass(text: str, signatures: set) -> None:
    assert check_program(text) == signatures


@pytest.mark.parametrize("text,problem", REFUSED)
def test_anything_else_is_refused_with_the_reason(text: str, problem: str) -> None:
    with pytest.raises(UnsafeProgram) as info:
        check_program(text)
    assert problem in str(info.value)


def test_the_vocabulary_is_the_documented_one() -> None:
    # docs/architecture.md, "ASP vocabulary shared by restrictor and planner"
    assert set(VOCABULARY) == {
        ("human_opens", 2),
        ("robot_in", 4),
        ("goes_through", 3),
        ("human_unavailable", 3),
        ("room_forbidden", 3),
        ("human_available", 3),
    }


@pytest.mark.parametrize(
    "value,ok",
    [
        ("d_storage", True),
        ("room_a", True),
        ("x", True),
        ("dA1", True),
        ("D_storage", False),
        ("_x", False),
        ("not", False),
        ("d-storage", False),
        ("1d", False),
        ("", False),
        ("d storage", False),
        ("d.x", False),
        (3, False),
        (None, False),
        ("a" * 65, False),
    ],
)
def test_asp_constants(value, ok: bool) -> None:
    assert is_asp_constant(value) is ok
