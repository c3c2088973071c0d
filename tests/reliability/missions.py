"""A lockstep mission under ``arroch up`` that a fault test can watch, hurt and judge.

:class:`UpMission` starts ``arroch up`` (router, services, the default office mission, one
namespace of its own) and reads what the supervisor leaves: its output (which child runs under
which pid, restarts, liveliness) and the run folder (``events.jsonl`` as the mission goes,
``metrics.json`` and ``run.json`` at the end). :meth:`UpMission.kill` sends SIGKILL to one child
by the pid the supervisor logged for it; :meth:`UpMission.finish` waits for the end and returns
an :class:`Outcome`, which :func:`assert_mission_completed` judges: every object delivered once,
no robot in a closed doorway, one ``mission_done``.
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protocol.site import load_site
from tests.procs import Proc, arroch

SITE = load_site()
OBJECTS = len(SITE.objects)
POLL = 0.05  # wall s between two looks at the run folder
# Lockstep at most this many times real time: the default mission (~690 site s) then lasts ~9 wall s,
# time enough to hurt services in the middle of it (uncapped it takes ~2 s). The cap only delays
# steps: the mission is the same.
PACE = 80


@dataclass(frozen=True)
class Kill:
    service: str
    pid: int
    at: float  # time.monotonic() of the SIGKILL
    wall: float  # time.time() of it (events.jsonl stamps what it receives with that clock)
    site_time: float  # the last event's site time then
    delivered: tuple[str, ...]  # objects delivered by then


@dataclass
class Outcome:
    exit_code: int
    run: dict[str, Any]  # run.json
    metrics: dict[str, Any]  # metrics.json (empty if the mission did not finish)
    events: list[dict[str, Any]]
    output: str

    def starts(self, child: str) -> int:
        return int(self.run["children"][child]["starts"])


class UpMission:
    """``arroch up --until-done`` of the default lockstep mission; see the module docstring."""

    def __init__(
        self,
        spawn: Callable[..., Proc],
        tmp_path: Path,
        namespace: str,
        *,
        services: str = "planner,restrictor,sim",
        seed: int = 1,
        timeout: float = 180.0,
        extra: tuple[str, ...] = (),
    ) -> None:
        self.namespace = namespace
        self.run_base = tmp_path / "runs"
        self.timeout = timeout
        self.proc = spawn(
            arroch(
                "up",
                "--services",
                services,
                "--mode",
                "lockstep",
                "--rate",
                str(PACE),
                "--seed",
                str(seed),
                "--until-done",
                "--namespace",
                namespace,
                "--run-dir",
                str(self.run_base),
                "--progress",
                "off",
                "--timeout",
                f"{timeout:g}",
                "--no-record",  # outcomes are checked; a recorder doubles the poses sent (docs/services/sim.md)
                *extra,
            ),
            name="up",
        )
        self.started = time.monotonic()

    # ------------------------------------------------------------------ what the supervisor says

    def pids(self, child: str) -> list[int]:
        """Every pid ``child`` has run under, in start order (from the supervisor's "started" lines)."""
        return [int(m) for m in re.findall(rf"started {re.escape(child)} \(pid (\d+)\)", self.proc.output)]

    def pid(self, child: str) -> int:
        pids = self.pids(child)
        if not pids:
            raise AssertionError(f"the supervisor never started {child}:\n{self.tail()}")
        return pids[-1]

    def router_endpoints(self) -> list[str]:
        """The endpoint of every router start, from its "router ready on ..." line."""
        return re.findall(r"router ready on (\S+)", self.proc.output)

    def lines(self, text: str) -> list[str]:
        return [line for line in self.proc.output.splitlines() if text in line]

    def tail(self, n: int = 60) -> str:
        return "\n".join(self.proc.output.splitlines()[-n:])

    # ------------------------------------------------------------------ the run folder

    @property
    def run_dir(self) -> Path | None:
        runs = [p for p in self.run_base.iterdir() if p.is_dir()] if self.run_base.is_dir() else []
        return runs[0] if len(runs) == 1 else None

    def events(self) -> list[dict[str, Any]]:
        """The events seen so far (a line still being written is left for the next look)."""
        run = self.run_dir
        if run is None or not (run / "events.jsonl").is_file():
            return []
        out = []
        for line in (run / "events.jsonl").read_text().splitlines():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                break
        return out

    def delivered(self) -> list[str]:
        return [e["object"] for e in self.events() if e["kind"] == "delivered"]

    def site_time(self) -> float:
        events = self.events()
        return max((float(e["stamp"]) for e in events), default=0.0)

    # ------------------------------------------------------------------ waiting and hurting

    def wait(self, condition: Callable[[], bool], what: str, timeout: float = 60.0) -> float:
        """Poll ``condition`` until it holds; returns the wall seconds it took. Fails (with the
        supervisor's last lines) if the run ends or ``timeout`` passes first."""
        start = time.monotonic()
        while not condition():
            if not self.proc.alive():
                raise AssertionError(f"the run ended before {what}:\n{self.tail()}")
            if time.monotonic() - start > timeout:
                raise AssertionError(f"no {what} within {timeout:.0f} s:\n{self.tail()}")
            time.sleep(POLL)
        return time.monotonic() - start

    def kill(self, child: str) -> Kill:
        """SIGKILL ``child`` (the process the supervisor started, not its group: as a crash would)."""
        pid = self.pid(child)
        record = Kill(child, pid, time.monotonic(), time.time(), self.site_time(), tuple(self.delivered()))
        os.kill(pid, signal.SIGKILL)
        return record

    def wait_restart(self, kill: Kill, timeout: float = 30.0) -> int:
        """The new pid once the supervisor reports it restarted the killed child."""
        self.wait(
            lambda: len(self.lines(f"restarted {kill.service} (pid")) >= 1 and self.pid(kill.service) != kill.pid,
            f"restart of {kill.service}",
            timeout,
        )
        return self.pid(kill.service)

    def finish(self) -> Outcome:
        """Wait for the run to end (``--until-done``, or its ``--timeout``) and read what it left."""
        remaining = self.timeout + 30.0 - (time.monotonic() - self.started)
        try:
            code = self.proc.wait(max(remaining, 1.0))
        except Exception:
            raise AssertionError(f"arroch up did not end within its --timeout:\n{self.tail()}") from None
        run = self.run_dir
        assert run is not None and (run / "run.json").is_file(), (
            f"no run folder with run.json under {self.run_base}:\n{self.tail()}"
        )
        metrics_file = run / "metrics.json"
        return Outcome(
            exit_code=code,
            run=json.loads((run / "run.json").read_text()),
            metrics=json.loads(metrics_file.read_text()) if metrics_file.is_file() else {},
            events=self.events(),
            output=self.proc.output,
        )


def assert_mission_completed(outcome: Outcome) -> None:
    """The mission finished as a healthy one does: every object delivered exactly once, no robot
    ever in the doorway of a closed door, one ``mission_done``, the supervisor exiting 0."""
    tail = "\n".join(outcome.output.splitlines()[-60:])
    assert outcome.exit_code == 0, f"arroch up exited {outcome.exit_code}:\n{tail}"
    assert outcome.run["mission_done"] is True and outcome.run["stop_reason"] == "mission done", outcome.run
    m = outcome.metrics
    assert m.get("completed") is True, tail
    delivered = [o for r in m["robots"].values() for o in r["delivered"]]
    assert sorted(delivered) == sorted(SITE.objects), delivered
    assert m["closed_door_crossings"] == 0, [e for e in outcome.events if e["kind"] == "closed_door_crossing"]
    assert not [e for e in outcome.events if e["kind"] == "closed_door_crossing"]
    assert sum(e["kind"] == "mission_done" for e in outcome.events) == 1
