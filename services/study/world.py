"""A trial's world: the ``arroch up`` command that runs it, the Zenoh network the runner joins to
hear it, and the process itself (started, watched, stopped).

The world is ``arroch up`` as a child process, never imported: planner, restrictor, the simulator
with a participant in place of the simulated human, the AR client and the tablet page in study mode
(``--study-trial page.json``), recorded to ``run/<timestamp>/run.mcap``. It runs ``--until-done
--linger``: after the mission the page stays up for her questionnaire, and the runner ends the world
when the trial is over. By default ``up`` starts its router on a free localhost port the runner
chooses (``--router-listen``) and the runner joins it; a plan whose ``up_args`` bring their own
network (``--no-router --connect ...``, ``--zenoh-config-dir DIR``) is joined as they say.

The process runs through :mod:`runtime.launch.children`: its own process group (a terminal's
Ctrl-C reaches only the runner, which stops it in order), and the kernel SIGTERMs it should the
runner die without cleaning up. Stopping is SIGTERM to its group (``up`` then stops its services),
then SIGKILL after a timeout.
"""

from __future__ import annotations

import collections
import logging
import re
import shlex
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from runtime.launch.children import Child, describe_exit, stop_all
from runtime.transport import DEFAULT_ROUTER, ZenohOptions, free_tcp_port

from .layout import StudyPlan

log = logging.getLogger("arroch.study.run")

UP: tuple[str, ...] = (sys.executable, "-m", "services.cli", "up")
VIRTUAL_SERVICES = "planner,restrictor,sim,ar,tablet"
# How the tablet announces its page in up's merged output: "[tablet]   https://HOST:PORT/?token=T..."
_TABLET_URL = re.compile(r"^\[tablet\]\s+(https?://\S*[?&]token=[A-Za-z0-9_\-]+\S*)\s*$")
TAIL = 60  # lines of up's output kept to show when it fails
#: What the world's command must take to run a study trial at all.
NEEDED = ("--human", "--study-trial", "--until-done", "--linger", "--run-dir", "--namespace", "--time-limit")
_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")


@dataclass
class WorldSpec:
    """One attempt's world: how to start it and how the runner joins its network."""

    argv: list[str]
    namespace: str
    zenoh: ZenohOptions


def option_value(args: list[str], name: str) -> str | None:
    """The last value of ``--name VALUE`` / ``--name=VALUE`` in ``args`` (argparse's last one wins)."""
    value = None
    for i, arg in enumerate(args):
        if arg == name and i + 1 < len(args):
            value = args[i + 1]
        elif arg.startswith(name + "="):
            value = arg.split("=", 1)[1]
    return value


def up_options(command: list[str], timeout: float = 30.0) -> set[str] | None:
    """The options the world's command takes, read from its ``--help``; None when it cannot say
    (then every option is given and up itself refuses what it does not know)."""
    try:
        done = subprocess.run([*command, "--help"], capture_output=True, text=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        log.warning("could not ask %s for its options: %s", shlex.join(command), exc)
        return None
    if done.returncode != 0:
        log.warning("%s --help exited with code %d", shlex.join(command), done.returncode)
        return None
    return set(_OPTION.findall(done.stdout))


def _connect_for(listen: str) -> str:
    """Where a local client dials a router listening on ``listen`` (any-address → loopback)."""
    proto, _, address = listen.partition("/")
    host, _, port = address.rpartition(":")
    if host in ("0.0.0.0", "[::]", "::", ""):
        host = "127.0.0.1"
    return f"{proto}/{host}:{port}"


def world_spec(
    plan: StudyPlan,
    *,
    page_file: Path,
    run_dir: Path,
    namespace: str,
    method: str,
    seed: int,
    up_command: list[str] | None = None,
    site: str | None = None,
    log_level: str | None = None,
    runner_zenoh: ZenohOptions | None = None,
    takes: set[str] | None = None,
) -> WorldSpec:
    """The ``arroch up`` command line of one attempt, and the Zenoh options the runner joins it with.

    Order matters: the world's defaults, then the plan's ``up_args`` (they may change the services,
    add ROS 2 options...), then what makes this attempt itself (namespace, method, seed, files), which
    the plan cannot override. ``runner_zenoh``: Zenoh options the experimenter gave the runner on its
    command line (None: the runner joins the world's own router). ``takes``: the options the world's
    command takes (:func:`up_options`), when known: ValueError if it lacks the participant mode."""
    if takes is not None:
        missing = [option for option in NEEDED if option not in takes]
        if missing:
            raise ValueError(
                f"{shlex.join(up_command or UP)} does not take {', '.join(missing)}: this installation cannot run "
                "a study trial (it needs arroch up's participant mode)"
            )
    world = plan.world
    argv = [*(up_command or UP), "--services", VIRTUAL_SERVICES, "--human", "participant"]
    if world.kind == "virtual":
        argv += ["--camera", "tablet"]  # the sim renders her tablet's view of the virtual building
    else:
        argv += ["--doors", "sensor"]  # real doors: their sensors (or the console) report them
    chosen_site = world.site or site
    if chosen_site:
        argv += ["--site", chosen_site]
    extra = list(world.up_args)
    argv += extra
    argv += ["--mode", world.mode]
    if world.mode == "rate":
        argv += ["--rate", f"{world.rate:g}"]
    argv += ["--time-limit", f"{world.time_limit:g}"]
    argv += [
        "--study-trial",
        str(page_file),
        "--method",
        method,
        "--seed",
        str(seed),
        "--namespace",
        namespace,
        "--run-dir",
        str(run_dir),
        "--until-done",
        "--linger",  # the page stays up after the mission, for her questionnaire
    ]
    if log_level:
        argv += ["--log-level", log_level]
    zenoh = _join(extra, argv, runner_zenoh)
    return WorldSpec(argv=argv, namespace=namespace, zenoh=zenoh)


def _join(extra: list[str], argv: list[str], runner_zenoh: ZenohOptions | None) -> ZenohOptions:
    """How the runner reaches the world's network (adds ``--router-listen`` to ``argv`` when the
    runner picks where up's router listens)."""
    config_dir = option_value(extra, "--zenoh-config-dir")
    if runner_zenoh is not None:
        # The experimenter said where the network is: a world that brings none of its own joins it too.
        if runner_zenoh.connect and not config_dir and "--no-router" not in extra:
            argv += ["--no-router", "--connect", ",".join(runner_zenoh.connect)]
        return runner_zenoh
    if config_dir:
        # A secured deployment: the runner joins as the supervisor role, as up itself does.
        return ZenohOptions(config_file=str(Path(config_dir) / "supervisor.json5"))
    if "--no-router" in extra:
        connect = option_value(extra, "--connect") or DEFAULT_ROUTER
        return ZenohOptions(mode="client", connect=[c.strip() for c in connect.split(",") if c.strip()])
    listen = option_value(extra, "--router-listen")
    if listen is None:
        listen = f"tcp/127.0.0.1:{free_tcp_port()}"
        argv += ["--router-listen", listen]
    return ZenohOptions(mode="client", connect=[_connect_for(listen)])


class World:
    """The running ``arroch up`` of one attempt."""

    def __init__(self, argv: list[str], *, name: str = "up") -> None:
        self.argv = argv
        self._child = Child(name, argv, on_line=self._on_line)
        self._lock = threading.Lock()
        self.tail: collections.deque[str] = collections.deque(maxlen=TAIL)
        self.tablet_urls: list[str] = []
        self._last_url = 0.0
        self.started = 0.0

    def start(self) -> None:
        self.started = time.monotonic()
        self._child.start()
        log.info("world started (pid %s): %s", self._child.pid, shlex.join(self.argv))

    @property
    def pid(self) -> int | None:
        return self._child.pid

    def running(self) -> bool:
        return self._child.running()

    def returncode(self) -> int | None:
        return self._child.returncode()

    def describe_exit(self) -> str:
        code = self.returncode()
        return "is running" if code is None else describe_exit(code)

    def _on_line(self, _name: str, line: str) -> None:
        """Each line of up's merged output (its reader thread): kept, logged quietly, URLs picked out."""
        with self._lock:
            self.tail.append(line)
            match = _TABLET_URL.match(line)
            if match and match.group(1) not in self.tablet_urls:
                self.tablet_urls.append(match.group(1))
                self._last_url = time.monotonic()
        if " ERROR " in line or " CRITICAL " in line:
            log.warning("world: %s", line)
        else:
            log.debug("world: %s", line)

    def urls_settled(self, quiet: float = 0.5) -> list[str]:
        """The tablet's URLs once none has come for ``quiet`` seconds (the block is complete)."""
        with self._lock:
            if self.tablet_urls and time.monotonic() - self._last_url >= quiet:
                return list(self.tablet_urls)
        return []

    def last_lines(self, n: int = 20) -> list[str]:
        with self._lock:
            return list(self.tail)[-n:]

    def stop(self, timeout: float, hurry: Callable[[], bool] | None = None) -> bool:
        """SIGTERM up's process group, SIGKILL after ``timeout`` (or at once when ``hurry()`` turns
        true: a second Ctrl-C); True when it had to be killed."""
        if self._child.popen is None:
            return False
        killed = stop_all([self._child], timeout, hurry)
        if killed:
            log.warning("the world did not stop within %.0f s of SIGTERM: killed", timeout)
        return bool(killed)
