"""One trial: a generated site, the real planner, restrictor and sim as processes, one mission.

Order (as ``arroch up`` does it, through the same catalog and child-process code): the planner and
the restrictor start together, each with this trial's namespace and the restrictor with a fresh
``--state-dir`` (constraints of an earlier mission must not leak into this one); once both show
their liveliness tokens the sim starts in lockstep mode with ``--until-done --metrics-out``. The
trial ends when the sim has written its metrics (or exited), when ``timeout`` wall seconds have
passed, when a service dies, or when the sweep is cancelled; then every process of the trial is
stopped (SIGTERM, SIGKILL after ``stop_timeout``) and its folder removed, whatever happened.

A trial's site is ``generate_site`` of its seed (the paper's buildings) or, in the ``detour``
domain, ``generate_detour_site`` (:func:`site_text`), with its point's site factors as generator
options. Its human model is the sim's default unless the sweep gives a ``--human-config`` text,
human parameters for every trial (``SweepSpec.human``) or a point's human factors: then a
``[human]`` file with all of them (:func:`human_text`) goes to the sim. A point sweep's trial also
keeps the sim's events and the plans it saw, and adds how feedback changed the plans to the metrics
(``plan_changes``, :mod:`.plan_changes`).

Statuses: ``ok`` (the mission was completed), ``unfinished`` (the sim ended it at its time limit:
a result of the model, not of the machinery), ``timeout`` (no end within ``timeout`` wall s),
``error`` (a service failed; the reason names it). A cancelled trial has no status: it is not
recorded, and ``--resume`` runs it again.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import logging
import re
import shutil
import signal
import tempfile
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.site import loads_site
from runtime.launch.catalog import RECORDER, RECORDING, SERVICES, Launch, MissionOptions, ServiceSpec, service_argv
from runtime.launch.children import Child, describe_exit, stop_all
from runtime.site.generate import generate_site
from runtime.site.generate_detour import generate_detour_site

from .design import DEFAULT_DOOR_SHARE, SweepSpec, TrialKey, format_p
from .factors import split
from .plan_changes import plan_changes
from .provenance import code_fingerprint
from .routers import Router, child_env

log = logging.getLogger("arroch.experiment")

POLL = 0.05  # wall s between two looks at a running trial
STACK_DUMP_WAIT = 1.0  # wall s the services of a trial that timed out get to print their stacks
# The planner's wall-clock limits, set so that they never bind in a trial: a plan cut short by the
# clock would depend on the machine's load, and the same seed must give the same results. (The
# service's defaults, 5 s a plan and 2 s a program, suit a live mission, not an experiment.)
PLANNER_LIMITS = ["--time-limit", "300", "--solve-limit", "120"]
FIRST = ("planner", "restrictor")  # services the sim waits for (the catalog's `after` of the sim)
OUTPUT_LINES = 400  # lines of each trial's output kept for its log when it fails
_LOG_PREFIX = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ ")  # LOG_FORMAT's asctime


@dataclass
class TrialConfig:
    """How trials are run (their speed and robustness, never their results)."""

    timeout: float = 300.0  # wall s for one trial, start-up included (a 6-robot trial takes ~10-50 s)
    start_timeout: float = 60.0  # wall s for the planner and restrictor to come up
    stop_timeout: float = 5.0  # wall s a service gets after SIGTERM
    log_level: str = "WARNING"  # the services' log level (their output is kept only for failures)
    events_dir: Path | None = None  # keep each trial's event log there (the sim's --events-out)
    # A recorder beside the services (arroch record); which trials' recordings are kept in
    # recordings_dir as <trial>.mcap: "failed" (timeout, error), "all", or "none" (no recorder at all).
    record: str = "none"
    recordings_dir: Path | None = None


@dataclass
class TrialOutcome:
    key: TrialKey
    status: str  # ok, unfinished, timeout, error, or cancelled (never recorded)
    reason: str = ""
    metrics: dict[str, Any] | None = None
    timing: dict[str, float] = field(default_factory=dict)
    output: list[str] = field(default_factory=list)  # the services' merged output (kept for failures)
    code: str = ""  # provenance.code_fingerprint() when the trial started


class Cancelled(Exception):
    """The sweep was asked to stop while this trial ran."""


class _Output:
    """The merged output of a trial's processes, last lines only, from their reader threads."""

    def __init__(self) -> None:
        self._lines: collections.deque[str] = collections.deque(maxlen=OUTPUT_LINES)
        self._lock = threading.Lock()

    def __call__(self, name: str, line: str) -> None:
        with self._lock:
            self._lines.append(f"[{name}] {line}")

    def lines(self) -> list[str]:
        with self._lock:
            return list(self._lines)

    def last_from(self, name: str) -> str:
        """``name``'s most telling last line (an ERROR if it logged one), without its time stamp."""
        mine = [line[len(name) + 3 :] for line in self.lines() if line.startswith(f"[{name}] ")]
        errors = [line for line in mine if " ERROR " in line or "Error" in line]
        text = (errors or mine or ["(no output)"])[-1]
        return _LOG_PREFIX.sub("", text).strip()[:300]


def _spec_for(name: str, drop: tuple[str, ...] = ()) -> ServiceSpec:
    """The catalog's entry for ``name`` without the options in ``drop``."""
    spec = SERVICES[name]
    return dataclasses.replace(spec, takes=tuple(t for t in spec.takes if t not in drop))


def service_commands(
    spec: SweepSpec,
    key: TrialKey,
    *,
    namespace: str,
    site: Path,
    folder: Path,
    connect: str,
    log_level: str,
    human_config: Path | None,
    events: Path | None = None,
    record: bool = False,
) -> dict[str, list[str]]:
    """The three command lines of a trial (four with ``record``), built by the supervisor's catalog.

    The catalog's ``method`` is the baseline the *sim* runs (the human model); the planner is the
    same ARROCH planner for every method (its own ``--method`` is iidp/joint), so it does not get it.
    """
    launch = Launch(
        namespace=namespace,
        connect=[connect],
        site=str(site),
        log_level=log_level,
        mission=MissionOptions(method=key.method, mode="lockstep", seed=spec.sim_seed(key)),
        run_dir=folder,
    )
    sim = service_argv(SERVICES["sim"], launch) + [
        "--until-done",
        "--metrics-out",
        str(folder / "metrics.json"),
        "--door-probability",
        format_p(key.p),
        "--task-mean",
        format_p(key.task),
        "--interruption-cost",
        format_p(key.cost),
    ]
    if spec.focus_reading is not None:
        sim += ["--focus-reading", spec.focus_reading]
    if human_config is not None:
        sim += ["--human-config", str(human_config)]
    if events is not None:
        sim += ["--events-out", str(events)]
    if spec.time_limit is not None:
        sim += ["--time-limit", f"{spec.time_limit:g}"]
    commands = {
        "planner": service_argv(_spec_for("planner", drop=("method",)), launch) + PLANNER_LIMITS,
        "restrictor": service_argv(SERVICES["restrictor"], launch),  # --state-dir <folder>/state
        "sim": sim,
    }
    if record:
        commands[RECORDER.name] = service_argv(RECORDER, launch)  # --out <folder>/run.mcap
    return commands


def site_text(spec: SweepSpec, key: TrialKey) -> str:
    """The trial's site (module docstring): the same building for every method and, outside a
    population, every point of a sweep."""
    options = dict(split(spec.point(key)).site)
    share = options.pop("door_share", None)
    seed = spec.site_seed(key)
    if spec.domain == "detour":
        share = DEFAULT_DOOR_SHARE if share is None else share
        return generate_detour_site(key.robots, key.objects, seed, door_share=share, **options)
    if share is not None:
        raise ValueError("door_share is a factor of the detour domain (--domain detour)")
    return generate_site(key.robots, key.objects, seed, **options)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # always with a '.' or an exponent: read back as the same float
    if isinstance(value, int):
        return str(value)
    return json.dumps(str(value))  # a JSON string is a valid TOML basic string


def human_text(spec: SweepSpec, key: TrialKey) -> str | None:
    """The trial's --human-config text, or None for the sim's defaults (module docstring)."""
    values = {**spec.human, **split(spec.point(key)).human}
    if not values:
        return spec.human_config
    base: dict[str, Any] = {}
    if spec.human_config is not None:
        try:
            data = tomllib.loads(spec.human_config)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"--human-config: {exc}") from None
        base = {k: v for k, v in data.get("human", data).items() if not isinstance(v, dict)}
    table = {**base, **values}
    return "[human]\n" + "".join(f"{name} = {_toml_value(value)}\n" for name, value in table.items())


def _human_doors(site: str) -> list[str]:
    return sorted(d.id for d in loads_site(site, "site.toml").doors.values() if d.human_operated)


def _read_events(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    events = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            continue  # a line cut short when the sim was stopped: nothing the measures need
    return events


def _read_metrics(path: Path) -> dict[str, Any] | None:
    """The sim's metrics once the file is complete (it is written in one go, but not atomically)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) and "completed" in data else None


class Trial:
    """Runs one trial on ``router``. ``cancel`` (set by the sweep) ends it early, unrecorded."""

    def __init__(
        self,
        spec: SweepSpec,
        key: TrialKey,
        router: Router,
        config: TrialConfig,
        cancel: threading.Event,
        namespace: str,
    ) -> None:
        self.spec = spec
        self.key = key
        self.router = router
        self.config = config
        self.cancel = cancel
        self.namespace = namespace
        self.output = _Output()
        self.children: dict[str, Child] = {}
        self.timing: dict[str, float] = {}

    def run(self) -> TrialOutcome:
        started = time.monotonic()
        code = code_fingerprint()
        folder = Path(tempfile.mkdtemp(prefix=f"arroch-exp-{self.key.ident()}-"))
        assert self.router.monitor is not None, "the router must be started"
        watch = self.router.monitor.watch(self.namespace)
        status = ""
        try:
            try:
                status, reason, metrics = self._mission(folder, watch, started)
            except Cancelled:
                status, reason, metrics = "cancelled", "the sweep was stopped", None
            self.timing["plans"], self.timing["solve_time"] = watch.planning()
        finally:
            stopping = time.monotonic()
            killed = stop_all(list(self.children.values()), 0.5 if self.cancel.is_set() else self.config.stop_timeout)
            self._keep_recording(folder, status)
            watch.close()
            shutil.rmtree(folder, ignore_errors=True)
            self.timing["shutdown"] = time.monotonic() - stopping
            self.timing["wall"] = time.monotonic() - started
        if killed:
            self.output("experiment", f"had to SIGKILL {', '.join(killed)}")
        if metrics is not None:
            self.timing["mission"] = float((metrics.get("run") or {}).get("wall_time") or 0.0)
        return TrialOutcome(self.key, status, reason, metrics, self.timing, self.output.lines(), code)

    # ------------------------------------------------------------------ steps

    def _keep_recording(self, folder: Path, status: str) -> None:
        """Move the trial's recording out of its folder (about to be removed) if it is to be kept."""
        recording = folder / RECORDING
        keep = self.config.record == "all" or (self.config.record == "failed" and status in ("timeout", "error"))
        if not keep or status in ("", "cancelled") or self.config.recordings_dir is None or not recording.is_file():
            return
        self.config.recordings_dir.mkdir(parents=True, exist_ok=True)
        target = self.config.recordings_dir / f"{self.key.ident()}.mcap"
        shutil.move(str(recording), target)
        self.output("experiment", f"recording kept: {target}")

    def _start(self, name: str, argv: list[str]) -> None:
        child = Child(name, argv, env=child_env(), on_line=self.output, restart=False)
        self.children[name] = child
        child.start()

    def _dead(self, names: tuple[str, ...]) -> str:
        """The reason for the first of ``names`` that has exited, else ""."""
        for name in names:
            child = self.children[name]
            if not child.running():
                child.flush_output()
                return (
                    f"{name} {describe_exit(child.returncode() or 0)} during the mission: {self.output.last_from(name)}"
                )
        return ""

    def _check(self, started: float, what: str) -> None:
        if self.cancel.is_set():
            raise Cancelled()
        if not self.router.alive():
            raise _Failed("error", "the Zenoh router stopped")
        if time.monotonic() - started > self.config.timeout:
            self._dump_stacks()
            raise _Failed("timeout", f"no end of mission within {self.config.timeout:g} s wall ({what})")

    def _dump_stacks(self) -> None:
        """Have every service still running print its threads' stacks into the trial's log (each
        registers SIGUSR1 for that: runtime.runner.setup_logging), so a hang says where it hangs."""
        running = [child for child in self.children.values() if child.running()]
        for child in running:
            child.signal(signal.SIGUSR1)
        time.sleep(STACK_DUMP_WAIT)
        for child in running:
            child.flush_output()

    def _mission(self, folder: Path, watch: Any, started: float) -> tuple[str, str, dict[str, Any] | None]:
        try:
            return self._run_mission(folder, watch, started)
        except _Failed as failure:
            return failure.status, failure.reason, None
        except (Cancelled, KeyboardInterrupt):
            raise
        except Exception as exc:  # e.g. a site the generator cannot make: this trial fails, the sweep goes on
            log.exception("%s failed", self.key.ident())
            return "error", f"{type(exc).__name__}: {exc}", None

    def _run_mission(self, folder: Path, watch: Any, started: float) -> tuple[str, str, dict[str, Any] | None]:
        site = folder / "site.toml"
        site_doc = site_text(self.spec, self.key)
        site.write_text(site_doc, encoding="utf-8")
        human = None
        human_doc = human_text(self.spec, self.key)
        if human_doc is not None:
            human = folder / "human.toml"
            human.write_text(human_doc, encoding="utf-8")
        events = self.config.events_dir / f"{self.key.ident()}.jsonl" if self.config.events_dir else None
        if events is None and self.spec.points:  # the plan measures read the events
            events = folder / "events.jsonl"
        commands = service_commands(
            self.spec,
            self.key,
            namespace=self.namespace,
            site=site,
            folder=folder,
            connect=self.router.endpoint,
            log_level=self.config.log_level,
            human_config=human,
            events=events,
            record=self.config.record != "none",
        )
        first = tuple(name for name in (*FIRST, RECORDER.name) if name in commands)
        for name in first:  # together: their start-ups overlap
            self._start(name, commands[name])
        while True:
            missing = watch.wait_alive(first, POLL)
            if not missing:
                break
            dead = self._dead(first)
            if dead:
                raise _Failed("error", dead.replace(" during the mission", " before it was up"))
            self._check(started, f"waiting for {', '.join(missing)} to come up")
            if time.monotonic() - started > self.config.start_timeout:
                raise _Failed("error", f"{', '.join(missing)} did not come up within {self.config.start_timeout:g} s")
        self.timing["services_up"] = time.monotonic() - started
        sim_started = time.monotonic()
        self._start("sim", commands["sim"])
        metrics_path = folder / "metrics.json"
        while True:
            metrics = _read_metrics(metrics_path)
            if metrics is not None:
                break
            sim = self.children["sim"]
            if not sim.running():
                metrics = _read_metrics(metrics_path)  # written just before it exited
                if metrics is not None:
                    break
                sim.flush_output()
                raise _Failed(
                    "error",
                    f"sim {describe_exit(sim.returncode() or 0)} without metrics: {self.output.last_from('sim')}",
                )
            dead = self._dead(FIRST)
            if dead:
                raise _Failed("error", dead)
            self._check(started, "mission running")
            time.sleep(POLL)
        mission = float((metrics.get("run") or {}).get("wall_time") or 0.0)
        self.timing["sim_startup"] = max(0.0, time.monotonic() - sim_started - mission)
        if self.spec.points and events is not None:
            self.children["sim"].wait(self.config.stop_timeout)  # its events file is complete once it exits
            changes = plan_changes(watch.plan_records(), _read_events(events), _human_doors(site_doc))
            metrics["plan_changes"] = changes.as_dict()
        if metrics.get("completed"):
            return "ok", "", metrics
        return (
            "unfinished",
            f"mission ended unfinished at t={float(metrics.get('time') or 0.0):.1f} s (the sim's time limit)",
            metrics,
        )


class _Failed(Exception):
    def __init__(self, status: str, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason
