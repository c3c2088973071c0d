"""``arroch up``: one command that runs a router and the chosen services, and watches the mission.

The supervisor is itself a small Zenoh client (a :class:`~runtime.service.Service` named
``supervisor``): it hears ``event`` and ``robot/*/status`` to show progress and to notice the end
of the mission. Everything it does to its children happens on its worker thread (the main thread),
in a timer every :data:`TICK` seconds — that thread is also the one the launch wrapper's
parent-death signal is tied to.

Order of things: router (waits for its "router ready" line) → the supervisor's own session →
services, each as soon as the services it comes ``after`` (catalog) show their liveliness tokens
(the sim, which starts the mission clock, waits for the planner and restrictor; after
``start_timeout`` it starts anyway) → watch, restart what crashes → on Ctrl-C/SIGTERM, mission end
(with ``--until-done``), timeout, or a child that cannot run: services stop first, then the router.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from protocol.messages import Event, RobotStatus
from protocol.schema import record_to_wire
from runtime.clock import SimClock, WallClock
from runtime.launch.catalog import (
    RECORDER_NAME,
    RECORDER_STOP_TIMEOUT,
    ROUTER,
    SUPERVISOR_ROLE,
    Launch,
    ServiceSpec,
    router_argv,
    service_argv,
)
from runtime.launch.children import CONFIG_ERROR, Child, RestartPolicy, describe_exit, stop_all
from runtime.service import Service
from runtime.transport import ZenohOptions

from .output import Output
from .progress import MissionProgress
from .rundir import RunDir

log = logging.getLogger("arroch.up")

TICK = 0.1  # seconds between two looks at the children
ROUTER_READY = "router ready"


@dataclass
class UpConfig:
    services: list[ServiceSpec]
    launch: Launch
    extra_children: list[tuple[str, list[str]]] = field(default_factory=list)
    start_router: bool = True
    router_listen: str | None = None
    until_done: bool = False
    linger: bool = False  # with until_done: after the mission, keep everything up until a signal
    timeout: float | None = None
    run_base: Path = Path("runs")
    progress_interval: float = 5.0
    stop_timeout: float = 5.0
    max_restarts: int = 5
    router_timeout: float = 20.0
    start_timeout: float = 60.0
    totals: dict[str, int] | None = None


class Supervisor(Service):
    def __init__(
        self, config: UpConfig, output: Output, zenoh_options: ZenohOptions, clock: WallClock | SimClock | None = None
    ) -> None:
        super().__init__(SUPERVISOR_ROLE, config.launch.namespace, zenoh_options, clock=clock)
        self.config = config
        self.output = output
        self.progress = MissionProgress(config.totals)
        self.run_dir: RunDir | None = None
        self.router: Child | None = None
        self.children: list[Child] = []  # services and extra children (not the router)
        self.exit_code = 0
        self.stop_reason = ""
        self._signal_taken = False
        self._started = time.monotonic()
        self._mission_reported = False
        self._metrics_printed = False
        self._waiting: dict[str, tuple[str, ...]] = {}  # child name -> services it still waits for
        self._alive: dict[str, set[str]] = {}  # service name -> instances with a liveliness token
        self._alive_lock = threading.Lock()

    # ------------------------------------------------------------------ signals

    def install_signal_handlers(self) -> None:
        """First signal: stop in order. A second one: stop waiting, kill the children now.

        The handlers only count signals (:mod:`runtime.signals`): they run on the main thread
        between two bytecodes, possibly while it holds a lock, so what a signal means is worked out
        on the worker (:meth:`on_stop_signal`, :meth:`_hurried`) and logged there.
        """
        self.signals.install((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))

    def on_stop_signal(self) -> None:
        self._take_signal()

    def _take_signal(self) -> None:
        """A first signal while nothing else stops the run: stop in order, and say why."""
        if self._signal_taken or not self.signals.received:
            return
        self._signal_taken = True
        if self.stop_reason:  # already stopping (mission done, a failure): the signal only hurries
            return
        self.stop_reason = f"received {self.signals.name}"
        if self.config.until_done and not self.progress.done:
            self.exit_code = 128 + int(self.signals.first or 0)
        self.stop()

    def _hurried(self) -> bool:
        """A second signal, or one that came while stopping for another reason: kill at once."""
        return self.signals.count >= 2 or (self.signals.received and not self.stop_reason.startswith("received"))

    # ------------------------------------------------------------------ service I/O

    def setup(self) -> None:
        self.subscribe(self.keys.event(), Event, self._on_event)
        self.subscribe(
            self.keys.robot_status("*"), RobotStatus, lambda msg, key: self.progress.on_status(msg), latest=True
        )
        # history=True: tokens declared before this subscriber count too.
        self._declared.append(
            self.session.liveliness().declare_subscriber(self.keys.liveliness("*", "*"), self._on_token, history=True)
        )
        self.every(TICK, self._tick)
        self.every(self.config.progress_interval, self._show_progress)

    def _on_event(self, msg: Event, key: str) -> None:
        if self.run_dir is not None:
            self.run_dir.event({"received": time.time(), "key": key, **record_to_wire(msg)})
        self.progress.on_event(msg)
        if msg.kind == "mission_done" and not self._mission_reported:
            self._mission_reported = True
            path = self.run_dir.write_json("metrics.json", self.progress.metrics or {}) if self.run_dir else None
            log.info("mission done at t=%.1f s (from %s); metrics in %s", msg.stamp, msg.src, path)
            if self.config.until_done and self.config.linger:
                self._print_metrics()
                self.output.line("up", "mission done: the services and the tablet page stay up until Ctrl-C (--linger)")
            elif self.config.until_done:
                self.stop_reason = "mission done"
                self.stop()

    def _on_token(self, sample: Any) -> None:
        """Liveliness of every service (Zenoh's thread): who is up, for start order and the log."""
        parts = str(sample.key_expr).split("/")
        service, instance = parts[-2], parts[-1]
        with self._alive_lock:
            instances = self._alive.setdefault(service, set())
            if sample.kind == zenoh.SampleKind.PUT:
                instances.add(instance)
            else:
                instances.discard(instance)
        if service == SUPERVISOR_ROLE or self.stopping:
            return
        if sample.kind == zenoh.SampleKind.PUT:
            log.info("%s is up (%s)", service, instance)
        else:
            log.info("%s is gone (%s)", service, instance)

    def is_alive(self, service: str) -> bool:
        with self._alive_lock:
            return bool(self._alive.get(service))

    def _show_progress(self) -> None:
        if self._metrics_printed:  # lingering after the mission: its final state is on screen already
            return
        if getattr(self.clock, "synced", False):
            self.progress.on_time(self.clock.now())
        self.output.progress(self.progress.bar() if self.output.bar else self.progress.line())

    # ------------------------------------------------------------------ children

    def _child(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> Child:
        policy = RestartPolicy(max_per_minute=self.config.max_restarts)
        return Child(name, argv, env=env, on_line=self.output.line, policy=policy)

    def _start(self, child: Child, ready_text: str | None = None) -> None:
        child.start(ready_text)
        log.info("started %s (pid %d): %s", child.name, child.pid, " ".join(child.argv))

    def _start_router(self) -> bool:
        launch = self.config.launch
        self.router = self._child(ROUTER, router_argv(launch, self.config.router_listen))
        self._start(self.router, ROUTER_READY)
        deadline = time.monotonic() + self.config.router_timeout
        while not self.router.ready.wait(0.05):
            if self.stopping:
                return False
            if not self.router.running():
                self.router.flush_output()
                log.error(
                    "the router %s before it was ready (its output is above)",
                    describe_exit(self.router.returncode() or 0),
                )
                return False
            if time.monotonic() > deadline:
                log.error("the router did not report ready within %.0f s", self.config.router_timeout)
                return False
        return True

    def _start_children(self) -> None:
        """Start every child that waits for nobody; the others start from :meth:`_tick`."""
        launch = self.config.launch
        selected = {spec.name for spec in self.config.services}
        for spec in self.config.services:
            self.children.append(self._child(spec.name, service_argv(spec, launch)))
            waits = tuple(dep for dep in spec.after if dep in selected)
            if waits:
                self._waiting[spec.name] = waits
                log.info("%s starts once %s %s up", spec.name, " and ".join(waits), "is" if len(waits) == 1 else "are")
        for name, argv in self.config.extra_children:
            self.children.append(self._child(name, argv, env=launch.zenoh_env()))
        for child in self.children:
            if child.name not in self._waiting:
                self._start(child)

    def _start_waiting(self, now: float) -> None:
        for child in self.children:
            waits = self._waiting.get(child.name)
            if waits is None:
                continue
            missing = [dep for dep in waits if not self.is_alive(dep)]
            if missing and now - self._started < self.config.start_timeout:
                continue
            if missing:
                log.warning(
                    "starting %s although %s did not come up within %.0f s",
                    child.name,
                    ", ".join(missing),
                    self.config.start_timeout,
                )
            del self._waiting[child.name]
            self._start(child)

    def _tick(self) -> None:
        now = time.monotonic()
        if self._waiting and not self.stopping:
            self._start_waiting(now)
        for child in ([self.router] if self.router else []) + self.children:
            self._watch(child, now)
        lingering = self.config.linger and self.progress.done  # the mission ended: nothing left to time out
        expired = self.config.timeout is not None and now - self._started > self.config.timeout
        if expired and not lingering and not self.stopping:
            log.error("the mission did not end within %.0f s (--timeout)", self.config.timeout)
            self._fail(f"timeout after {self.config.timeout:.0f} s")

    def _watch(self, child: Child, now: float) -> None:
        if child.popen is None or child.running() or child.gave_up or self.stopping:
            return
        if child.restart_at is not None:
            if now >= child.restart_at:
                self._start(child, ROUTER_READY if child is self.router else None)
                log.warning("restarted %s (pid %d, start %d)", child.name, child.pid, child.starts)
            return
        if child.exit_reported:
            return
        child.exit_reported = True
        code = child.returncode() or 0
        child.reap_group()  # its last lines first, then ours
        how = describe_exit(code)
        if code == 0:
            child.gave_up = True
            log.warning("%s %s on its own; not restarting it", child.name, how)
            return
        if code == CONFIG_ERROR:
            child.gave_up = True
            log.error("%s %s: its configuration is wrong (see its output above); not restarting it", child.name, how)
            self._fail(f"{child.name}: configuration error")
            return
        delay = child.policy.next_delay(now, child.ran_for())
        if delay is None:
            child.gave_up = True
            log.error(
                "%s %s; it was restarted %d times in the last minute: giving up",
                child.name,
                how,
                child.policy.restarts_last_minute,
            )
            self._fail(f"{child.name} keeps crashing")
            return
        child.restart_at = now + delay
        log.warning(
            "%s %s after %.1f s; restarting it in %.1f s (%d restart(s) in the last minute)",
            child.name,
            how,
            child.ran_for(),
            delay,
            child.policy.restarts_last_minute,
        )

    def _fail(self, reason: str) -> None:
        self.exit_code = 1
        self.stop_reason = reason
        self.stop()

    def _print_metrics(self) -> None:
        """The final progress line and the metrics table, once, when the mission has ended."""
        if not self.progress.done or self._metrics_printed:
            return
        self._metrics_printed = True
        self.output.end_progress()
        self.output.line("up", "final progress " + self.progress.line())
        for line in ["mission metrics:", *self.progress.metrics_text().splitlines()]:
            self.output.line("up", line)

    # ------------------------------------------------------------------ the whole run

    def main(self) -> int:
        """Start everything, supervise until told to stop, stop everything. Returns the exit code."""
        self.install_signal_handlers()
        self.run_dir = RunDir.create(self.config.run_base)
        self.output.attach_log(self.run_dir.log)
        launch = self.config.launch
        launch.run_dir = self.run_dir.path
        log.info(
            "run folder %s; namespace %s; services %s",
            self.run_dir.path,
            launch.namespace,
            ", ".join(s.name for s in self.config.services) or "none",
        )
        try:
            if self.config.start_router and not self._start_router():
                if not self.stopping:
                    self._fail("the router did not start")
                return self.exit_code
            where = launch.config_file(SUPERVISOR_ROLE) or ",".join(launch.connect)
            try:
                self.open()
            except Exception as exc:
                log.error("could not join the Zenoh network (%s): %s", where, exc)
                self._fail("no Zenoh session")
                return self.exit_code
            if not self.stopping:
                self._start_children()
            if not self.stopping:
                log.info("supervising; Ctrl-C stops everything")
            self.run()  # until stop(); closes the session on the way out
            return self.exit_code
        finally:
            self._shutdown()

    def _shutdown(self) -> None:
        self._take_signal()  # one that came before the worker loop ran
        if self.stop_reason.startswith("received"):
            log.info("%s: stopping everything (a second signal kills at once)", self.stop_reason)
        self.close()
        # Services first: they may still publish on their way out, through a router that is up. The
        # recorder after them: it settles on what reached it once nothing is published any more, so a
        # run's last poses and its mission_done make it into the recording even on a loaded machine.
        recorders = [child for child in self.children if child.name == RECORDER_NAME]
        others = [child for child in self.children if child.name != RECORDER_NAME]
        killed = stop_all(others, self.config.stop_timeout, self._hurried)
        killed += stop_all(recorders, max(self.config.stop_timeout, RECORDER_STOP_TIMEOUT), self._hurried)
        if self.router is not None:
            killed += stop_all([self.router], self.config.stop_timeout, self._hurried)
        if killed:
            log.warning("had to SIGKILL %s: it did not stop in time", ", ".join(killed))
        everyone = ([self.router] if self.router else []) + self.children
        log.info("stopped (%s)", self.stop_reason or "done")
        self.output.end_progress()
        self._print_metrics()
        if self.run_dir is not None:
            self.run_dir.write_json(
                "run.json",
                {
                    "namespace": self.config.launch.namespace,
                    "services": [s.name for s in self.config.services],
                    "children": {
                        c.name: {"argv": c.argv, "starts": c.starts, "last_exit": c.returncode()} for c in everyone
                    },
                    "stop_reason": self.stop_reason or "done",
                    "exit_code": self.exit_code,
                    "mission_done": self.progress.done,
                    "wall_seconds": round(time.monotonic() - self._started, 3),
                },
            )
            self.run_dir.close()
        self.output.close()
