"""One recorded mission shared by all the recorder tests: the default lockstep demo mission (planner,
restrictor, sim with the tablet camera, AR client) under ``arroch up``, which records it to
``run.mcap``, and a second recorder beside it writing the ROS 2 profile."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from protocol.transport import free_tcp_port
from tests.procs import Proc, arroch

MISSION_TIMEOUT = 150.0  # wall s; the mission takes 12-35 s on two cores


@dataclass(frozen=True)
class Mission:
    run: Path  # runs/<time>/
    ros2: Path  # the ros2 profile's bag folder
    output: str  # the supervisor's output

    @property
    def recording(self) -> Path:
        return self.run / "run.mcap"


@pytest.fixture(scope="session")  # one mission for every recorder test (only they use it)
def mission(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Mission]:
    base = tmp_path_factory.mktemp("mission")
    ros2 = base / "ros2"
    namespace = f"rec{free_tcp_port()}"
    proc = Proc(
        arroch(
            "up",
            "--services",
            "planner,restrictor,sim,ar",
            "--camera",
            "tablet",
            "--mode",
            "lockstep",
            "--seed",
            "1",
            "--until-done",
            "--timeout",
            str(MISSION_TIMEOUT),
            "--run-dir",
            str(base / "runs"),
            "--progress",
            "line",
            "--namespace",
            namespace,
            "--child",
            f"ros2rec={{python}} -m services.cli record --profile ros2 --out {ros2} --namespace {{namespace}} "
            "--log-level WARNING",
        ),
        name="up",
    )
    try:
        deadline = time.monotonic() + MISSION_TIMEOUT + 20
        while proc.alive() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not proc.alive(), f"mission not done in time:\n{proc.output[-4000:]}"
        assert proc.popen.returncode == 0, proc.output[-4000:]
    finally:
        proc.stop()
    (run,) = [p for p in (base / "runs").iterdir() if p.is_dir()]
    yield Mission(run, ros2, proc.output)
