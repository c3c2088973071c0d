"""``arroch up --help`` says which clock a mission runs on by default and how long the default one takes."""

from __future__ import annotations

import contextlib
import io

import pytest

from services.cli import build_parser


def test_up_help_says_real_time_is_the_default_and_how_long_the_mission_takes():
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        build_parser().parse_args(["up", "--help"])
    text = " ".join(out.getvalue().split())
    assert "realtime (the default: the default mission then takes about 11 minutes" in text
    assert "lockstep (time advances only when every request is answered: the same mission in seconds" in text
