"""``--zenoh-mode`` is Zenoh's session mode in every command; ``--mode`` is the site clock's mode where a
command has one (``sim``, ``up``, ``demo``), and elsewhere still works for Zenoh's mode, with a warning."""

from __future__ import annotations

import argparse

import pytest

from runtime.transport import add_zenoh_arguments, options_from
from services.cli import build_parser


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="arroch x")
    add_zenoh_arguments(parser)
    return parser.parse_args(list(argv))


def test_zenoh_mode_sets_the_session_mode(capsys):
    assert options_from(parse("--zenoh-mode", "peer"), env={}).mode == "peer"
    assert options_from(parse(), env={"ARROCH_ZENOH_MODE": "router"}).mode == "router"
    assert capsys.readouterr().err == ""


def test_the_old_mode_option_still_works_with_a_deprecation_warning(capsys):
    assert options_from(parse("--mode", "peer"), env={}).mode == "peer"
    assert "--mode peer is deprecated here: use --zenoh-mode peer" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["planner"], ["restrictor"], ["ar"], ["tablet"], ["router"], ["ping", "serve"]])
def test_every_service_takes_zenoh_mode(command: list[str]):
    args = build_parser().parse_args([*command, "--zenoh-mode", "peer"])
    assert options_from(args, env={}).mode == "peer"


def test_in_the_sim_mode_is_the_clock_and_zenoh_mode_the_session():
    args = build_parser().parse_args(["sim", "--mode", "lockstep", "--zenoh-mode", "peer"])
    assert args.mode == "lockstep" and options_from(args, env={}).mode == "peer"
