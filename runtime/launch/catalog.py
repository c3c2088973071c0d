"""What ``arroch up`` can start, and the one place where each child's command line is built.

A new service slots in with one :data:`SERVICES` entry: its ``arroch`` sub-command and which of
``up``'s options it takes (each option's flags are spelled once, in :data:`OPTION_FLAGS`).
Every service also gets the common options of :func:`runtime.runner.add_common_arguments`
(``--namespace``, ``--site``, ``--clock``, ``--log-level``) and its Zenoh settings: ``--connect`` to
the supervisor's router, or ``--zenoh-config DIR/<role>.json5`` from ``arroch deploy render`` (the
access-control role it runs as: its own name, unless its entry names another, as the tablet page
runs as ``ar``).

Extra children (``--child NAME=COMMAND``) are arbitrary commands; ``{python}``, ``{connect}``,
``{namespace}`` and ``{site}`` in them are replaced, and they find the router through the
``ARROCH_ZENOH_CONNECT`` environment variable like every ``arroch`` command does.
"""

from __future__ import annotations

import re
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ARROCH: tuple[str, ...] = (sys.executable, "-m", "services.cli")
_NAME = re.compile(r"^[a-z][a-z0-9_\-]{0,31}$")


@dataclass
class MissionOptions:
    """``up``'s options that shape the mission (passed to the services that take them)."""

    method: str | None = None
    mode: str | None = None  # sim clock mode: realtime, rate or lockstep
    rate: float | None = None
    seed: int | None = None
    time_limit: float | None = None  # site seconds after which the sim ends the mission unfinished
    camera: str | None = None  # the sim's virtual camera ('tablet' or X,Y,Z,YAW,PITCH); None: no camera
    camera_every: float | None = None  # lockstep: site s between the camera's frames besides the held ones
    view_port: int | None = None  # serve the recorder's channels live to Foxglove on this port; None: don't
    human: str | None = None  # the sim's human: 'simulated' or 'participant' (a person on her tablet page)
    doors: str | None = None  # the sim's human-operated doors: 'sim' or 'sensor' (real doors' sensors)
    study_trial: str | None = None  # the tablet page's study trial file (arroch study run writes it)


# How each option is spelled on a service's command line (the services' own flags).
OPTION_FLAGS: dict[str, Callable[[Launch], list[str]]] = {
    "method": lambda launch: ["--method", launch.mission.method] if launch.mission.method else [],
    "mode": lambda launch: ["--mode", launch.mission.mode] if launch.mission.mode else [],
    "rate": lambda launch: ["--rate", f"{launch.mission.rate:g}"] if launch.mission.rate is not None else [],
    "seed": lambda launch: ["--seed", str(launch.mission.seed)] if launch.mission.seed is not None else [],
    "time_limit": lambda launch: (
        ["--time-limit", f"{launch.mission.time_limit:g}"] if launch.mission.time_limit is not None else []
    ),
    # Persisted state of this run only: a new run must not inherit the last run's constraints,
    # while a restarted service within the run must find its own.
    "state": lambda launch: ["--state-dir", str(launch.run_dir / "state")] if launch.run_dir else [],
    # The sim renders the camera; the AR client (default source: that camera) and the tablet page
    # (viewer mode on it) show it. Without a camera the page uses each browser's own camera.
    "camera": lambda launch: (
        ["--camera", launch.mission.camera]
        + (["--camera-every", f"{launch.mission.camera_every:g}"] if launch.mission.camera_every is not None else [])
        if launch.mission.camera
        else []
    ),
    "camera_source": lambda launch: ["--camera-source", f"sim:{SIM_CAMERA_ID}"] if launch.mission.camera else [],
    # A few overlay frames spread over the run, kept with its other records.
    "snapshots": lambda launch: ["--snapshots", str(launch.run_dir / OVERLAY_FOLDER)] if launch.run_dir else [],
    # The run's recording, with the merged log's lines, and (arroch up --view) the live Foxglove view.
    "recording": lambda launch: (
        (["--out", str(launch.run_dir / RECORDING)] if launch.run_dir else [])
        + _logs(launch)
        + (["--view", "--view-port", str(launch.mission.view_port)] if launch.mission.view_port is not None else [])
    ),
    "view": lambda launch: ["--port", str(launch.mission.view_port)] + _logs(launch),
    # A study trial: a person plays the human (the sim), real doors' sensors (the sim), and the page
    # shows the trial's condition and task (the tablet).
    "human": lambda launch: ["--human", launch.mission.human] if launch.mission.human else [],
    "doors": lambda launch: ["--doors", launch.mission.doors] if launch.mission.doors else [],
    "study_trial": lambda launch: ["--study-trial", launch.mission.study_trial] if launch.mission.study_trial else [],
}
RECORDING = "run.mcap"


def _logs(launch: Launch) -> list[str]:
    return ["--logs", str(launch.run_dir / "supervisor.log")] if launch.run_dir else []


RECORDER_NAME = "recorder"  # its service name (liveliness), which the sim waits for
# Wall s the recorder has to stop before it is killed: it first drains what is still on its way (its
# settle lasts at most 20 s), so a run's last messages are recorded even on a loaded machine.
RECORDER_STOP_TIMEOUT = 30.0
SIM_CAMERA_ID = "tablet"  # the sim's default --camera-id, which is also the AR client's default --camera
OVERLAY_FOLDER = "overlays"


@dataclass(frozen=True)
class ServiceSpec:
    """A service ``arroch up`` knows: ``arroch <command...>`` plus the options of :data:`OPTION_FLAGS` it takes."""

    name: str
    command: tuple[str, ...]
    takes: tuple[str, ...] = ()
    help: str = ""
    # Services (of the same run) whose liveliness token must be seen before this one starts.
    after: tuple[str, ...] = ()
    # The access-control identity it runs as (its rendered config is <role>.json5); default: its name.
    role: str = ""

    @property
    def identity(self) -> str:
        return self.role or self.name


SERVICES: dict[str, ServiceSpec] = {
    spec.name: spec
    for spec in (
        # ``up --method`` is the experiment's method (arroch, no-feedback, no-comm): it shapes the
        # simulated human only. The planner's own --method (iidp or joint) is a different option.
        ServiceSpec("planner", ("planner",), (), "task and motion planner, dispatcher"),
        ServiceSpec("restrictor", ("restrictor",), ("state",), "feedback -> constraints"),
        # The sim starts the mission clock: the planner and restrictor must be listening by then, and
        # the AR client (when this run has one) watching, so its overlays cover the whole mission.
        ServiceSpec(
            "sim",
            ("sim",),
            ("method", "mode", "rate", "seed", "time_limit", "camera", "human", "doors"),
            "simulated robots, doors, human, tablet camera",
            after=("planner", "restrictor", "ar", RECORDER_NAME),
        ),
        ServiceSpec("ar", ("ar",), ("snapshots",), "AR client: overlays of the camera frames"),
        # Any free port: the printed URL carries it with the run's token. Its identity is the AR role's.
        ServiceSpec(
            "tablet",
            ("tablet", "--port", "0", "--no-qr"),
            ("camera_source", "study_trial"),
            "tablet page (HTTPS; URL and token printed)",
            role="ar",
        ),
        ServiceSpec("ping", ("ping", "serve"), (), "echo server for link checks (arroch ping send)"),
    )
}
DEFAULT_SERVICES: tuple[str, ...] = ("planner", "restrictor", "sim", "ar")
# Not chosen with --services: ``arroch up`` adds it to every run with a sim unless --no-record. It
# reads what the supervisor's role may read (every key but robot commands, in the secure profile).
RECORDER = ServiceSpec(
    RECORDER_NAME,
    ("record",),
    ("recording",),
    "records the run to run.mcap (and serves it live with --view)",
    role="supervisor",
)
VIEWER = ServiceSpec(
    RECORDER_NAME, ("view",), ("view",), "serves the run live to Foxglove (--view with --no-record)", role="supervisor"
)
ROUTER = "router"
SUPERVISOR_ROLE = "supervisor"


@dataclass
class Launch:
    """Everything a child's command line depends on."""

    namespace: str
    connect: list[str] = field(default_factory=list)
    zenoh_config_dir: Path | None = None
    site: str | None = None
    clock: str | None = None
    log_level: str | None = None
    mission: MissionOptions = field(default_factory=MissionOptions)
    run_dir: Path | None = None  # this run's folder, once it exists

    def config_file(self, role: str) -> Path | None:
        return None if self.zenoh_config_dir is None else self.zenoh_config_dir / f"{role}.json5"

    def zenoh_args(self, role: str) -> list[str]:
        """A rendered per-role config when there is a config directory, else the router to dial."""
        path = self.config_file(role)
        if path is not None:
            return ["--zenoh-config", str(path)]
        return ["--connect", ",".join(self.connect)] if self.connect else []

    def zenoh_env(self) -> dict[str, str]:
        """For extra children: the same router, through the variables runtime.transport reads."""
        env = {"ARROCH_NAMESPACE": self.namespace}
        if self.zenoh_config_dir is None and self.connect:
            env["ARROCH_ZENOH_CONNECT"] = ",".join(self.connect)
        return env

    def common_args(self) -> list[str]:
        args = ["--namespace", self.namespace]
        if self.site:
            args += ["--site", self.site]
        if self.clock:
            args += ["--clock", self.clock]
        if self.log_level:
            args += ["--log-level", self.log_level]
        return args


def parse_services(text: str | None) -> list[ServiceSpec]:
    """``planner,sim`` → specs, in order; an unknown or repeated name is an error that lists the known ones."""
    if text is None:
        return [SERVICES[name] for name in DEFAULT_SERVICES]
    names = [part.strip() for part in text.split(",") if part.strip()]
    unknown = [name for name in names if name not in SERVICES]
    if unknown:
        raise ValueError(
            f"unknown service{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))} "
            f"(known: {', '.join(SERVICES)})"
        )
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"service {', '.join(repeated)} listed twice")
    return [SERVICES[name] for name in names]


def service_argv(spec: ServiceSpec, launch: Launch) -> list[str]:
    """``arroch <service> --namespace ... --connect ... <mission flags>``."""
    argv = [*ARROCH, *spec.command, *launch.common_args(), *launch.zenoh_args(spec.identity)]
    for option in spec.takes:
        argv += OPTION_FLAGS[option](launch)
    return argv


def router_argv(launch: Launch, listen: str | None) -> list[str]:
    """``arroch router`` on ``listen``, or as its rendered config says."""
    argv = [*ARROCH, ROUTER]
    config = launch.config_file(ROUTER)
    if config is not None:
        argv += ["--zenoh-config", str(config)]
    if listen:
        argv += ["--listen", listen]
    if launch.log_level:
        argv += ["--log-level", launch.log_level]
    return argv


def parse_child(entry: str, launch: Launch) -> tuple[str, list[str]]:
    """``NAME=COMMAND`` → (name, argv) with the placeholders filled in."""
    name, sep, command = entry.partition("=")
    name = name.strip()
    if not sep or not command.strip():
        raise ValueError(f"--child {entry!r}: expected NAME=COMMAND")
    if not _NAME.match(name):
        raise ValueError(f"--child {entry!r}: the name must be lower-case letters, digits, '_' or '-' (at most 32)")
    if name in SERVICES or name in (ROUTER, "up"):
        raise ValueError(f"--child {entry!r}: {name!r} is taken; pick another name")
    values = {
        "{python}": sys.executable,
        "{connect}": ",".join(launch.connect),
        "{namespace}": launch.namespace,
        "{site}": launch.site or "",
    }
    try:
        words = shlex.split(command)
    except ValueError as exc:
        raise ValueError(f"--child {entry!r}: {exc}") from None
    for placeholder, value in values.items():
        words = [word.replace(placeholder, value) for word in words]
    return name, words
