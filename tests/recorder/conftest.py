"""One recorded mission shared by all the recorder tests: the demo's lockstep mission (planner,
restrictor, sim with the tablet camera, AR client, the tablet page) under ``arroch up``, which
records it to ``run.mcap`` and, with ``--record-profile ros2 --ros-distro humble``, to a Humble bag
beside it. The tablet page prints its URL with the run's access token, which must reach no file.

Under pytest-xdist the recorder's test files may land on both workers: the first to need the mission
records it in the session's shared temporary folder and the other reads the same run (a file lock
between them), so the suite runs it once. The tests only read the run's folder."""

from __future__ import annotations

import fcntl
import json
import re
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import pytest

from runtime.transport import free_tcp_port
from tests.procs import Proc, arroch

MISSION_TIMEOUT = 150.0  # wall s; the mission takes 12-35 s on two cores
_TOKEN = re.compile(r"^\[tablet\]\s+https://\S+\?token=([A-Za-z0-9_\-]+)")  # as services/demo.py reads it


@dataclass(frozen=True)
class Mission:
    run: Path  # runs/<time>/
    output: str  # the supervisor's output
    token: str  # the tablet page's access token, as printed on the terminal
    started: float  # wall time (Unix s) just before `arroch up` was started
    finished: float  # and once it had exited

    @property
    def ros2(self) -> Path:
        """The Humble bag ``--record-profile ros2`` wrote beside the recording."""
        return self.run / "run_ros2"

    @property
    def recording(self) -> Path:
        return self.run / "run.mcap"


@pytest.fixture(scope="session")  # one mission for every recorder test (only they use it)
def mission(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> Mission:
    if worker_id == "master":  # not distributed: this session's own folder
        return _record(tmp_path_factory.mktemp("mission"))
    # pytest-xdist: every worker's temporary folder is in the session's one
    shared = tmp_path_factory.getbasetemp().parent / "recorder-mission"
    with _locked(shared.parent / "recorder-mission.lock"):
        done = shared / "mission.json"
        if not done.exists():
            shared.mkdir(exist_ok=True)
            mission = _record(Path(tempfile.mkdtemp(dir=shared)))  # a failed attempt's folder stays apart
            done.write_text(json.dumps({**asdict(mission), "run": str(mission.run)}))
        found = json.loads(done.read_text())
    return Mission(**{**found, "run": Path(found["run"])})


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        yield


def _record(base: Path) -> Mission:
    namespace = f"rec{free_tcp_port()}"
    started = time.time()
    proc = Proc(
        arroch(
            "up",
            "--services",
            "planner,restrictor,sim,ar,tablet",
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
            "--record-profile",
            "ros2",
            "--ros-distro",
            "humble",
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
    (token,) = {m.group(1) for line in proc.output.splitlines() if (m := _TOKEN.match(line))}
    return Mission(run, proc.output, token, started, time.time())
