"""ASP smuggled through feedback never reaches the solver, whichever way the feedback comes in.

The restrictor's unit tests refuse the injection corpus through every parameter of every library
entry, the kind and the parameter names (``tests/restrictor/test_validate.py``); the mission fuzz
puts the same attempts on the ``feedback`` key during a mission, and the tablet fuzz sends them over
the page's WebSocket. Here, against a real restrictor process, the two remaining ways in: the query
path (what ``arroch feedback send``, the tablet bridge and the simulated human use), with the whole
corpus, and the command line itself (``arroch feedback send --kind K --PARAM=VALUE``), whose values
are typed by the library before they leave. Every attempt gets a refusal, and the constraint set the
planner would be sent stays empty.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from protocol.site import load_site
from runtime.feedback_client import fetch_constraints, send_feedback
from services.cli import main
from services.restrictor.library import load_library
from tests.procs import restrictor_argv
from tests.reliability.fuzzing import contained, hostile_feedback
from tests.restrictor.helpers import valid_params
from tests.restrictor.test_validate import INJECTIONS, NUMERIC_INJECTIONS

pytestmark = [pytest.mark.integration]

INJECTED_NAMES = ["door).\nhuman_opens(d_storage, 1", "t0", "t1", "kind", "#include", "${door}"]
# The command line's sample of the corpus: facts, rules, comments, directives, scripts, odd spaces.
CLI_INJECTIONS = [i for i in INJECTIONS[:12] if not i.startswith("-")] + ["d_storage\n:- human_opens(D, T).", "${door}"]


def test_smuggled_asp_through_queries_and_the_command_line_is_refused(
    router, namespace, client, spawn, tmp_path: Path
) -> None:
    restrictor = spawn(
        restrictor_argv(namespace, router, tmp_path / "state"),
        name="restrictor",
    )
    restrictor.wait_for("up on namespace", timeout=30)
    library, site = load_library(), load_site()

    # The query path, the whole corpus: an answer for each, never an acceptance.
    attempts = hostile_feedback(library, site, INJECTIONS, NUMERIC_INJECTIONS, INJECTED_NAMES)
    answered = 0
    for kind, params in attempts:
        try:
            ack = send_feedback(client, kind, params, timeout=5.0, retry=2.0)
        except (OverflowError, TypeError):
            continue  # not encodable at all (an integer past 64 bits): nothing a sender could put on the wire
        assert ack is not None, (kind, params)
        assert not ack.accepted, (kind, params, ack.reason)
        answered += 1
    assert answered >= len(attempts) - 5

    # The command line: every parameter of every entry, each with a sample of the corpus (the other
    # parameters valid, so the injection is the only thing wrong).
    outcomes: Counter[bool] = Counter()
    for entry in library.entries.values():
        valid = valid_params(entry, site, active_ids=("c999999",))
        for param in entry.params:
            for bad in CLI_INJECTIONS:
                argv = [
                    "feedback",
                    "send",
                    "--namespace",
                    namespace,
                    "--connect",
                    router,
                    "--clock",
                    "wall",
                    "--timeout",
                    "5",
                    "--kind",
                    entry.id,
                    *(f"--{n}={v}" for n, v in valid.items() if n != param.name),
                    f"--{param.name}={bad}",
                ]
                with contained(tmp_path, 30.0) as (out, err):
                    try:
                        code = main(argv)
                    except SystemExit as exc:
                        code = exc.code
                printed = out.getvalue() + err.getvalue()
                # 1: the restrictor refused it; 2: the command line itself could not make it a Feedback.
                refused = code == 1 and printed.startswith("refused: ")
                assert refused or (code == 2 and "error" in printed), (argv, code, printed)
                outcomes[refused] += 1
    assert sum(outcomes.values()) == sum(len(e.params) for e in library.entries.values()) * len(CLI_INJECTIONS)
    assert outcomes[True] > outcomes[False], outcomes  # most went all the way to the restrictor

    current = fetch_constraints(client)
    assert current is not None and current.constraints == [] and current.asp == "" and current.version == 0, current
    assert restrictor.alive()
