"""Bad command lines: random argv for every ``arroch`` sub-command, run in-process.

The argv is drawn by hypothesis (derandomized) from each sub-command's own parser: its options (with
their choices, or not), values from a pool of edge cases (NaN, huge, negative, empty, unicode, shaped
values like ``1,2,3``, missing files, a directory, a garbage file, real files), stray tokens. Each
run must end with exit code 0, 1 or 2 (3 for the two commands documented to exit 3 when nothing
answers) and, unless 0, say why; an exception escaping, a traceback printed, or a run outliving
:data:`LIMIT` fails the test with the argv.

How each sub-command runs:

- tools run as they are (site check, plan, sim snapshot, deploy certs, ...), in a scratch folder
  (``plan`` with a bounded solver budget, ``tags sheet`` writing a PDF: :data:`BOUNDED`);
- services run against a router that is not there (``--connect`` to a closed port, client mode),
  so their argument and configuration checks run and then opening Zenoh fails fast;
- commands that would start long-lived things of their own (a router, a demo mission, experiment
  sweeps) only parse: their ``type=`` checks are what can fail.
"""

from __future__ import annotations

import argparse
import shutil
from importlib import resources
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.site.load import default_site_path
from services.cli import build_parser, main
from tests.reliability.fuzzing import Overran, contained

LIMIT = 30.0  # wall s a single run may take
DEAD_ROUTER = "tcp/127.0.0.1:1"  # nothing listens there: opening a session fails at once
PARSE_ONLY = {("router",), ("demo",)} | {
    ("experiment", sweep) for sweep in ("robots", "laziness", "map", "detour", "sensitivity", "population")
}
# Services: the arguments that point them at the absent router, and the options left out because they
# would point Zenoh elsewhere (their Zenoh-mode flag among them).
ZENOH = {"--connect", "--listen", "--multicast", "--zenoh-config"}
CLIENT = (["--mode", "client"], ZENOH | {"--mode"})
# Commands whose --mode is something else (the clock's) or that have none: the Zenoh mode by its own name.
ZENOH_CLIENT = (["--zenoh-mode", "client"], ZENOH | {"--zenoh-mode"})
SERVICES: dict[tuple[str, ...], tuple[list[str], set[str]]] = {
    ("planner",): CLIENT,
    ("restrictor",): CLIENT,
    ("sim",): ZENOH_CLIENT,
    # without --connect these two become the router themselves and run until stopped
    ("record",): ZENOH_CLIENT,
    ("view",): ZENOH_CLIENT,
    ("ar",): CLIENT,
    ("tablet",): CLIENT,
    ("ping", "serve"): CLIENT,
    ("ping", "send"): CLIENT,
    ("feedback", "send"): CLIENT,
    ("constraints", "show"): CLIENT,
    # `up` never gets to start a child: its supervisor cannot join the (absent) router.
    ("ros2", "bridge"): CLIENT,
    ("up",): (["--no-router"], ZENOH | {"--child", "--router", "--no-router", "--router-listen", "--zenoh-config-dir"}),
}
# Appended to a tool's argv (the last value of an option wins): a command line that gets through the
# checks then does a bounded amount of work (the joint program alone takes seconds).
BOUNDED = {("plan",): ["--method", "iidp", "--time-limit", "2"], ("tags", "sheet"): ["--out", "sheet.pdf"]}
EXIT_3 = {("feedback", "send"), ("constraints", "show")}  # documented: 3 when nothing answers
# Fewer examples where a run that gets through its checks does real work (solving, rendering).
EXAMPLES = {
    ("plan",): 15,
    ("sim", "snapshot"): 20,
    ("tags", "sheet"): 3,
    ("site", "show"): 12,
    ("ar", "render"): 20,
    ("ar", "localize"): 20,
}
DEFAULT_EXAMPLES = 30

NUMBERS = [
    "0",
    "1",
    "-1",
    "3",
    "2.5",
    "-0.0",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "99999999999999999999",
    "0x10",
    "1_000",
    "4096",
]
TEXT = [
    "",
    " ",
    "x",
    "office",
    "d_storage",
    "planner,sim",
    "a b",
    "\u00e9\u00e8",
    "\U0001f4a5",
    "--",
    "-",
    "%s",
    "${door}",
    "1,2,3",
    "1,2,3,4,5,6",
    "8.5,3.2,1.3,-94,-9",
    "500,500,320,240,640,480",
    "64x48",
    "0x0",
    "d_storage:0:10",
    "ar=x",
    "tcp/127.0.0.1:1",
    '{"kind": "forbid_room", "room": "lab", "minutes": 4}',
    "{",
    "[]",
    "chessboard:9x6:0.025",
]
FILES = [
    "missing.toml",
    "garbage.bin",
    "empty.txt",
    "adir",
    "office.toml",
    "library.toml",
    "image.png",
    "sub/out.png",
    "out.png",
    "out.json",
    "out.pdf",
    "out.mp4",
]


def leaf_commands() -> list[tuple[str, ...]]:
    """Every runnable sub-command path (``("site", "check")``, ``("planner",)``, ...)."""
    out = []

    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if parser.get_default("func") is not None and path:
            out.append(path)
        for action in subs:
            for name, sub in action.choices.items():
                walk(sub, (*path, name))

    walk(build_parser(), ())
    return out


def parser_of(path: tuple[str, ...]) -> argparse.ArgumentParser:
    parser = build_parser()
    for name in path:
        (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        parser = action.choices[name]
    return parser


# What an option's name says it wants (the dest or metavar containing the word): the good values.
HINTS = (
    ("site", ["office.toml"]),
    ("config", ["office.toml"]),
    ("library", ["library.toml"]),
    ("file", ["office.toml"]),
    ("image", ["image.png"]),
    ("png", ["out.png"]),
    ("truth", ["out.json"]),
    ("out", ["out.png", "out.json", "newdir"]),
    ("dir", ["adir", "newdir"]),
    ("intrinsics", ["500,500,320,240,640,480"]),
    ("camera", ["8.5,3.2,1.3,-94,-9", "tablet"]),
    ("size", ["64x48"]),
    ("feedback", ['{"kind": "forbid_room", "room": "lab", "minutes": 4}']),
    ("hosts", ["planner,sim"]),
)


def good_values(action: argparse.Action) -> list[str]:
    """Values ``action`` would accept, as far as its declaration tells (choices, default, name, type)."""
    out = [str(c) for c in action.choices] if action.choices is not None else []
    if isinstance(action.default, (str, int, float)) and not isinstance(action.default, bool):
        out.append(str(action.default))
    name = f"{action.dest} {action.metavar or ''}".lower()
    out += [v for hint, values in HINTS if hint in name for v in values]
    if action.type in (int, float):
        out += ["1", "2"]
    return out or ["1"]


def value_for(draw: Any, action: argparse.Action) -> str:
    """Half the time a value the option should take, half the time an odd one (an odd number for a
    number)."""
    if draw(st.booleans()):
        return draw(st.sampled_from(good_values(action)))
    return draw(st.sampled_from(NUMBERS if action.type in (int, float) else NUMBERS + TEXT + FILES))


@st.composite
def argv_for(draw: Any, path: tuple[str, ...]) -> list[str]:
    """A random command line for ``path``: some of its options (and positionals), odd values, stray tokens."""
    parser = parser_of(path)
    left_out = SERVICES[path][1] if path in SERVICES else set()
    options = [
        a
        for a in parser._actions
        if a.option_strings and not isinstance(a, argparse._HelpAction) and not set(a.option_strings) & left_out
    ]
    positionals = [a for a in parser._actions if not a.option_strings and not isinstance(a, argparse._SubParsersAction)]
    argv = list(path)
    required = [a for a in options if a.required and draw(st.integers(0, 9))]  # now and then one is missing
    for action in required + (draw(st.lists(st.sampled_from(options), max_size=5)) if options else []):
        argv.append(draw(st.sampled_from(action.option_strings)))
        if action.nargs == 0:
            continue
        count = (
            draw(st.integers(1, 3))
            if action.nargs in ("+", "*")
            else action.nargs
            if isinstance(action.nargs, int)
            else 1
        )
        argv += [value_for(draw, action) for _ in range(count)]
    for action in positionals:
        if draw(st.integers(0, 9)):  # now and then one is missing
            argv.append(value_for(draw, action))
    if draw(st.integers(0, 9)) == 0:
        argv.insert(
            draw(st.integers(len(path), len(argv))), draw(st.sampled_from(["--no-such-option", "stray", "-x", "--"]))
        )
    if path in SERVICES:
        argv += [*SERVICES[path][0], "--connect", DEAD_ROUTER]
    return argv + BOUNDED.get(path, [])


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The files the value pool names, in a folder the runs work in."""
    folder = tmp_path_factory.mktemp("cli")
    (folder / "garbage.bin").write_bytes(bytes(range(256)) * 4)
    (folder / "empty.txt").write_text("")
    (folder / "adir").mkdir()
    shutil.copy(default_site_path(), folder / "office.toml")
    (folder / "library.toml").write_bytes(resources.files("services.restrictor").joinpath("library.toml").read_bytes())
    cv2.imwrite(str(folder / "image.png"), np.full((48, 64, 3), 128, np.uint8))
    return folder


def run(path: tuple[str, ...], argv: list[str], folder: Path) -> tuple[int, str]:
    """(exit code, everything printed) of ``arroch <argv>``."""
    with contained(folder, LIMIT) as (out, err):
        try:
            if path in PARSE_ONLY:
                build_parser().parse_args(argv)
                code = 0
            else:
                code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except Overran:
            pytest.fail(f"arroch {' '.join(argv)!r} ran longer than {LIMIT} s")
        except Exception as exc:  # noqa: BLE001 - exactly what must never happen
            pytest.fail(f"arroch {argv!r} raised {exc!r}\n{err.getvalue()[-2000:]}")
    return code, out.getvalue() + err.getvalue()


COMMANDS = leaf_commands()


def test_every_sub_command_is_fuzzed() -> None:
    assert len(COMMANDS) >= 30 and {("site", "check"), ("plan",), ("up",), ("feedback", "send")} <= set(COMMANDS)
    assert set(SERVICES) | PARSE_ONLY <= set(COMMANDS)


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: "-".join(p))
def test_random_argv_ends_with_a_code_and_a_message(path: tuple[str, ...], scratch: Path) -> None:
    allowed = {0, 1, 2, 3} if path in EXIT_3 else {0, 1, 2}

    @settings(
        max_examples=EXAMPLES.get(path, DEFAULT_EXAMPLES),
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    )
    @given(argv=argv_for(path))
    def check(argv: list[str]) -> None:
        code, printed = run(path, argv, scratch)
        assert code in allowed, f"arroch {argv!r} exited {code}:\n{printed[-2000:]}"
        assert "Traceback (most recent call last)" not in printed, (
            f"arroch {argv!r} printed a traceback:\n{printed[-3000:]}"
        )
        if code != 0:
            assert printed.strip(), f"arroch {argv!r} exited {code} without a word"

    check()
