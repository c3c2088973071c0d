"""Experiment trials with a recorder: its command line from the supervisor's catalog, and which
trials' recordings are kept (failed ones by default, all with --record all)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from services.experiments.design import SweepSpec, TrialKey
from services.experiments.trial import Trial, TrialConfig, service_commands

KEY = TrialKey("arroch", 3, 3, 0.5, 600.0, 0.0, 2)


def spec() -> SweepSpec:
    return SweepSpec(kind="robots", methods=("arroch",), robots=(3,), objects=3, ps=(0.5,), trials=1, seed=1)


def test_a_recording_trial_runs_a_recorder_writing_into_the_trial_folder(tmp_path):
    commands = service_commands(
        spec(),
        KEY,
        namespace="exp1n1",
        site=tmp_path / "site.toml",
        folder=tmp_path,
        connect="tcp/127.0.0.1:1",
        log_level="WARNING",
        human_config=None,
        record=True,
    )
    argv = commands["recorder"]
    assert argv[argv.index("record") - 1 : argv.index("record") + 1] == ["services.cli", "record"]
    assert argv[argv.index("--out") + 1] == str(tmp_path / "run.mcap")
    assert argv[argv.index("--namespace") + 1] == "exp1n1" and argv[argv.index("--site") + 1] == str(
        tmp_path / "site.toml"
    )
    plain = service_commands(
        spec(),
        KEY,
        namespace="exp1n1",
        site=tmp_path / "site.toml",
        folder=tmp_path,
        connect="tcp/127.0.0.1:1",
        log_level="WARNING",
        human_config=None,
    )
    assert set(plain) == {"planner", "restrictor", "sim"}


@pytest.mark.parametrize(
    "record, status, kept",
    [
        ("failed", "error", True),
        ("failed", "timeout", True),
        ("failed", "ok", False),
        ("failed", "unfinished", False),
        ("all", "ok", True),
        ("all", "cancelled", False),
        ("none", "error", False),
    ],
)
def test_which_recordings_are_kept(tmp_path: Path, record: str, status: str, kept: bool):
    folder = tmp_path / "trial"
    folder.mkdir()
    (folder / "run.mcap").write_bytes(b"recording")
    config = TrialConfig(record=record, recordings_dir=tmp_path / "recordings")
    trial = Trial(spec(), KEY, router=None, config=config, cancel=threading.Event(), namespace="exp1n1")  # type: ignore[arg-type]
    trial._keep_recording(folder, status)
    target = tmp_path / "recordings" / f"{KEY.ident()}.mcap"
    assert target.is_file() == kept
    assert (folder / "run.mcap").is_file() != kept
