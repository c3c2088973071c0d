"""Controls made ahead and freed behind (services/planner/controls.py): the program grounded in one
made ahead is the one a Control made in place grounds, and a Control given back is freed on the helper
thread, never on the planner's."""

from __future__ import annotations

import gc
import hashlib
import subprocess
import sys
import threading
import time

import clingo
import pytest

from services.planner.controls import ControlShop, make
from services.planner.facts import site_facts
from services.planner.single import SingleRobotSolver
from services.planner.solver import _options, encoding_statements, solve
from services.planner.world import initial_world
from tests.planner.conftest import planner_for, site_named
from tests.procs import ROOT

PARTS = ("domain", "doors", "objective", "makespan")


class _Stream:
    """Everything grounding hands the solver, digested in order."""

    def __init__(self) -> None:
        self.digest = hashlib.sha256()
        self.calls = 0

    def _note(self, *what: object) -> None:
        self.digest.update(repr(what).encode())
        self.calls += 1

    def rule(self, choice: bool, head, body) -> None:  # noqa: ANN001
        self._note("rule", choice, list(head), list(body))

    def weight_rule(self, choice: bool, head, lower: int, body) -> None:  # noqa: ANN001
        self._note("weight", choice, list(head), lower, list(body))

    def minimize(self, priority: int, literals) -> None:  # noqa: ANN001
        self._note("minimize", priority, list(literals))

    def output_atom(self, symbol: clingo.Symbol, atom: int) -> None:
        self._note("output", str(symbol), atom)

    def external(self, atom: int, value) -> None:  # noqa: ANN001
        self._note("external", atom, str(value))


def _one_robot_program() -> str:
    """The facts of a real one-robot program: the office site's first robot alone."""
    name = "office"
    tp = planner_for(name)
    problems = tp.problems(initial_world(site_named(name)), 0)
    single = SingleRobotSolver(site_facts(site_named(name), 0), tp.hold, None)
    prob = problems[sorted(problems)[0]]
    return single.site_facts + single._member(prob, single.context(prob, {})) + f"active({prob.robot}).\n"


def _grounded_stream(ctl: clingo.Control, facts: str) -> tuple[str, int]:
    stream = _Stream()
    ctl.register_observer(stream)
    ctl.add("base", [], facts)
    ctl.ground([("base", [])])
    return stream.digest.hexdigest(), stream.calls


def test_a_control_made_ahead_grounds_the_program_one_made_in_place_grounds():
    facts = _one_robot_program()
    key = (tuple(_options()), PARTS)
    shop = ControlShop(encoding_statements)
    shop.take(*key)  # made in place; orders the next one
    deadline = time.monotonic() + 10
    while key not in shop._ready and time.monotonic() < deadline:
        time.sleep(0.01)
    ahead = shop.take(*key)
    assert shop.made_ahead == 1 and shop.made_in_place == 1
    in_place = _grounded_stream(make(key, encoding_statements), facts)
    assert in_place[1] > 1000  # a real program
    assert _grounded_stream(ahead, facts) == in_place


def test_a_control_given_back_is_freed_on_the_helper_thread(monkeypatch: pytest.MonkeyPatch):
    freed: list[str] = []
    original = clingo.Control.__del__

    def spy(self: clingo.Control) -> None:
        freed.append(threading.current_thread().name)
        original(self)

    monkeypatch.setattr(clingo.Control, "__del__", spy)
    for _ in range(5):
        out = solve("a(1..9). { b(X) : a(X) } 2. #minimize { X : b(X) }. :- not b(3).", [], time_limit=5)
        assert out.status == "optimal" and out.cost == (3,)
    deadline = time.monotonic() + 10
    while len(freed) < 5 and time.monotonic() < deadline:
        gc.collect()
        time.sleep(0.01)
    assert len(freed) >= 5
    assert set(freed) == {"clingo-controls"}


EXITS_WHILE_MAKING = """
import time
import clingo.ast as ast
from services.planner.controls import shop

PROGRAM = "\\n".join(f"p({i}) :- q({i}), not r({i})." for i in range(20000))

def statements(part):  # parsing calls back into Python from clingo's C++, in the helper thread
    parsed = []
    ast.parse_string(PROGRAM, parsed.append)
    return parsed

made = shop(statements)
made.take([], ["rules"])   # made here; orders the next Control of this kind: the helper starts parsing
time.sleep(0.05)
print("done")
"""


def test_a_process_exiting_while_the_helper_makes_a_control_exits_cleanly(tmp_path):
    # A daemon thread inside a clingo callback at finalization is ended by a forced unwind that clingo's
    # C++ catches: the process aborted ("FATAL: exception not rethrown", -6) after its work was done.
    script = tmp_path / "exits.py"
    script.write_text(EXITS_WHILE_MAKING)
    out = subprocess.run(
        [sys.executable, str(script)],
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (out.returncode, out.stdout.strip()) == (0, "done"), out.stderr
    assert "FATAL" not in out.stderr
