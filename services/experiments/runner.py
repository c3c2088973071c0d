"""A sweep: every trial of a :class:`~.design.SweepSpec`, ``jobs`` at a time, recorded as they end.

The results folder (``--out``):

- ``sweep.json``: the spec (what decides the results); ``--resume`` refuses a folder whose spec differs;
- ``trials.csv``: one row per trial (:mod:`.record`), appended as trials end, in the sweep's order
  once it is complete, so the same spec gives the same file byte for byte;
- ``timing.csv``: the wall-clock side of each trial (not byte-identical by nature);
- ``metrics.jsonl``: each finished trial's full metrics from the sim;
- ``params.json``: the model the results come from (:mod:`.params`);
- ``runs.json``: one entry per session (start, wall time, jobs, routers, trials run, how it ended);
- ``logs/<trial>.log``: the services' output of each trial that failed (timeout or error) or whose
  mission did not end (unfinished);
- ``events/<trial>.jsonl``: every trial's event log, with ``--keep-events`` (to compare two runs);
- the report (:mod:`.report`), unless ``--no-report``.

Workers are threads, each running one trial at a time (the trial's processes do the work). A
router is started per worker, for all, or per trial (:mod:`.routers`). With ``--cluster`` the trials
run on a Dask distributed cluster instead, each with its own router on its worker (:mod:`.cluster`);
they are recorded the same way. SIGINT/SIGTERM cancels the sweep: running trials are stopped
(processes and all) and not recorded; ``--resume`` runs them again.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from runtime.signals import StopSignals, restore

from .design import SweepSpec, TrialKey
from .params import varied_paths, write_params
from .progress import Progress, ProgressLogHandler
from .provenance import code_fingerprint, dependency_versions
from .record import DONE, key_cells, key_of, timing_fields, timing_row, trial_fields, trial_row
from .routers import ROUTER_MODES, Router, RouterError
from .store import CsvStore, JsonlStore
from .trial import Trial, TrialConfig, TrialOutcome

log = logging.getLogger("arroch.experiment")

SPEC_FILE = "sweep.json"
TRIALS_FILE = "trials.csv"
TIMING_FILE = "timing.csv"
METRICS_FILE = "metrics.jsonl"
PARAMS_FILE = "params.json"
RUNS_FILE = "runs.json"
LOGS_DIR = "logs"
EVENTS_DIR = "events"


class SweepError(ValueError):
    """The sweep cannot start (wrong folder, spec mismatch, bad options)."""


@dataclass
class RunOptions:
    out: Path
    jobs: int = field(default_factory=lambda: os.cpu_count() or 1)
    router: str = "worker"
    resume: bool = False
    trial: TrialConfig = field(default_factory=TrialConfig)
    progress: str = "auto"  # auto, bar, line, off
    report: bool = True
    keep_events: bool = False  # DIR/events/<trial>.jsonl
    cluster: str | None = None  # a Dask scheduler's address: run the trials there instead of locally
    cluster_timeout: float = 20.0  # wall s to reach it
    rerun: tuple[str, ...] = ()  # with resume: recorded trials (by ident) to run again, as if never run

    def check(self) -> None:
        if self.jobs < 1:
            raise SweepError(f"--jobs must be >= 1 (got {self.jobs})")
        if self.router not in ROUTER_MODES:
            raise SweepError(f"--router must be one of {', '.join(ROUTER_MODES)} (got {self.router!r})")
        if not self.trial.timeout > 0:
            raise SweepError(f"--trial-timeout must be > 0 (got {self.trial.timeout})")
        if not self.cluster_timeout > 0:
            raise SweepError(f"--cluster-timeout must be > 0 (got {self.cluster_timeout})")
        if self.rerun and not self.resume:
            raise SweepError("--rerun needs --resume (it runs recorded trials of a sweep folder again)")


class Sweep:
    def __init__(self, spec: SweepSpec, options: RunOptions) -> None:
        options.check()
        self.spec = spec
        self.options = options
        self.out = options.out
        self.trials = CsvStore(self.out / TRIALS_FILE, trial_fields(spec))
        self.timing = CsvStore(self.out / TIMING_FILE, timing_fields(spec))
        self.metrics = JsonlStore(self.out / METRICS_FILE)
        self.cancel = threading.Event()
        self._record_lock = threading.Lock()
        self._todo: queue.Queue[TrialKey] = queue.Queue()
        self._counter = 0
        self._counter_lock = threading.Lock()
        self.failed = 0
        self.ran = 0
        self.progress: Progress | None = None
        self._worker_errors: list[str] = []

    # ------------------------------------------------------------------ folder

    def _prepare(self) -> list[TrialKey]:
        """Check/create the folder; on resume keep the finished trials. Returns the trials to run."""
        spec_path = self.out / SPEC_FILE
        if spec_path.exists():
            if not self.options.resume:
                raise SweepError(
                    f"{self.out} already holds a sweep: add --resume to continue it, or choose another --out"
                )
            try:
                old = SweepSpec.from_json(json.loads(spec_path.read_text(encoding="utf-8")))
            except (json.JSONDecodeError, ValueError) as exc:
                raise SweepError(f"{spec_path}: {exc}") from None
            differences = self.spec.differences(old)
            if differences:
                raise SweepError(
                    f"--resume: {self.out} holds another sweep ({'; '.join(differences)}); "
                    f"run it with the same options, or choose another --out"
                )
        elif self.trials.exists():
            raise SweepError(f"{self.out} has a {TRIALS_FILE} but no {SPEC_FILE}: not a sweep folder this command made")
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / LOGS_DIR).mkdir(exist_ok=True)
        if self.options.keep_events:
            self.options.trial.events_dir = (self.out / EVENTS_DIR).resolve()
            self.options.trial.events_dir.mkdir(exist_ok=True)
        spec_path.write_text(json.dumps(self.spec.to_json(), indent=2, sort_keys=True) + "\n", encoding="utf-8")
        wanted = set(self.spec.keys())
        unknown = sorted(set(self.options.rerun) - {key.ident() for key in wanted})
        if unknown:
            raise SweepError(f"--rerun: this sweep has no trial {', '.join(unknown)}")
        rows = self.trials.load()
        kept = [
            row
            for row in rows
            if row["status"] in DONE and key_of(row) in wanted and key_of(row).ident() not in self.options.rerun
        ]
        done = {key_of(row) for row in kept}
        dropped = len(rows) - len(kept)
        if dropped:
            log.info("resume: %d recorded trial(s) that timed out, failed or are to be rerun will run again", dropped)
        # Rewrite even when nothing was dropped: this also removes a line torn by a crash.
        self.trials.rewrite(kept)
        self.timing.rewrite([row for row in self.timing.load() if key_of(row) in done])
        self.metrics.rewrite([r for r in self.metrics.load() if key_of(r["key"]) in done])
        if done:
            log.info("resume: %d of %d trials already done", len(done), self.spec.trial_count())
        return [key for key in self.spec.schedule() if key not in done]

    # ------------------------------------------------------------------ recording

    def _record(self, outcome: TrialOutcome) -> None:
        ok = outcome.status in DONE
        with self._record_lock:
            self.trials.append(trial_row(self.spec, outcome))
            self.timing.append(timing_row(outcome))
            if outcome.metrics is not None:
                self.metrics.append({"key": key_cells(outcome.key), "metrics": outcome.metrics})
            log_path = self.out / LOGS_DIR / f"{outcome.key.ident()}.log"
            if not ok:
                self.failed += 1
            if outcome.status == "ok":
                log_path.unlink(missing_ok=True)  # an old failure of this trial, now run again
            else:  # a failure, or a mission that did not end: worth reading
                log_path.write_text(
                    "\n".join([f"status: {outcome.status}", f"reason: {outcome.reason}", "", *outcome.output]) + "\n",
                    encoding="utf-8",
                )
                log.warning(
                    "%s: %s: %s (services' output in %s)", outcome.key.ident(), outcome.status, outcome.reason, log_path
                )
            self.ran += 1
        if self.progress is not None:
            wall = outcome.timing.get("wall", 0.0)
            self.progress.finished(f"last {outcome.key.ident()} {outcome.status} {wall:.1f} s", ok)

    # ------------------------------------------------------------------ workers

    def _namespace(self) -> str:
        with self._counter_lock:
            self._counter += 1
            return f"exp{os.getpid()}n{self._counter}"

    def _worker(self, shared: Router | None) -> None:
        """Run trials from the queue until it is empty or the sweep is cancelled.

        Routers started here belong to this thread: the parent-death signal of their process is tied
        to the thread that started it, and this thread outlives every trial it runs."""
        own: Router | None = None
        try:
            while not self.cancel.is_set():
                try:
                    key = self._todo.get_nowait()
                except queue.Empty:
                    return
                router = shared
                if router is None and self.options.router == "worker":
                    if own is not None and not own.alive():
                        log.warning("this worker's router stopped; starting another")
                        own.stop()
                        own = None
                    if own is None:
                        own = Router(self.options.trial.log_level).start()
                    router = own
                per_trial = router is None
                try:
                    if per_trial:
                        try:
                            router = Router(self.options.trial.log_level).start()
                        except RouterError as exc:
                            self._record(TrialOutcome(key, "error", f"router: {exc}"))
                            continue
                    assert router is not None
                    outcome = Trial(self.spec, key, router, self.options.trial, self.cancel, self._namespace()).run()
                finally:
                    if per_trial and router is not None:
                        router.stop()
                if outcome.status == "cancelled":
                    return
                self._record(outcome)
        except Exception as exc:  # a bug or a router that cannot start: this worker stops, the others go on
            log.exception("a worker stopped: %s", exc)
            with self._record_lock:
                self._worker_errors.append(str(exc))
        finally:
            if own is not None:
                own.stop()

    # ------------------------------------------------------------------ the whole sweep

    def run(self) -> int:
        """Run the sweep. Exit code: 0 complete, 1 complete with failed trials or a worker that
        stopped, 130 cancelled (the folder can be resumed)."""
        todo = self._prepare()
        total = self.spec.trial_count()
        for key in todo:
            self._todo.put(key)
        started_at, started = time.time(), time.monotonic()
        jobs = min(self.options.jobs, max(1, len(todo)))
        log.info(
            "%s sweep: %d trials (%d to run) in %s, %d at a time, router per %s",
            self.spec.kind,
            total,
            len(todo),
            self.out,
            jobs,
            self.options.router,
        )
        handler: logging.Handler | None = None
        if self.options.progress != "off":
            bar = {"auto": None, "bar": True, "line": False}[self.options.progress]
            self.progress = Progress(total, total - len(todo), label=self.spec.kind, bar=bar)
            handler = ProgressLogHandler(self.progress)
            handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
            root = logging.getLogger()
            saved_handlers = root.handlers[:]
            root.handlers[:] = [handler]
        # The handlers only note the signal (runtime.signals): the loop below turns it into a cancel.
        signals = StopSignals()
        previous = (
            signals.install((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))
            if threading.current_thread() is threading.main_thread()
            else {}
        )
        shared: Router | None = None
        try:
            if self.options.cluster:
                self._run_on_cluster(todo, lambda: signals.received)
            else:
                if todo and self.options.router == "shared":
                    shared = Router(self.options.trial.log_level).start()
                self._run_locally(jobs, shared, lambda: signals.received)
            if signals.received:  # one that came as the last trial ended
                self.cancel.set()
        finally:
            if shared is not None:
                shared.stop()
            restore(previous)
            if self.progress is not None:
                self.progress.close()
                logging.getLogger().handlers[:] = saved_handlers
        return self._end(started_at, started, jobs, total)

    def _run_locally(self, jobs: int, shared: Router | None, stopping: Callable[[], bool]) -> None:
        """``jobs`` worker threads until the queue is empty or the sweep is cancelled."""
        workers = [
            threading.Thread(target=self._worker, args=(shared,), name=f"worker-{i}", daemon=True) for i in range(jobs)
        ]
        for worker in workers:
            worker.start()
        while any(w.is_alive() for w in workers):
            for worker in workers:
                worker.join(0.5)
                if stopping():
                    self.cancel.set()
            if self.progress is not None:
                self.progress.tick()

    def _run_on_cluster(self, todo: list[TrialKey], stopping: Callable[[], bool]) -> None:
        from .cluster import ClusterError, ClusterPool

        assert self.options.cluster is not None
        try:
            pool = ClusterPool(self.options.cluster, timeout=self.options.cluster_timeout)
        except ClusterError as exc:
            raise SweepError(str(exc)) from None
        try:
            log.info("cluster %s: %d worker(s); %d trial(s) submitted", self.options.cluster, pool.workers(), len(todo))
            idle = self.progress.tick if self.progress is not None else (lambda: None)
            for outcome in pool.run(self.spec, todo, self.options.trial, stopping, idle):
                if outcome.status != "cancelled":
                    self._record(outcome)
            if stopping():
                self.cancel.set()
        finally:
            pool.close()

    def _end(self, started_at: float, started: float, jobs: int, total: int) -> int:
        wall = time.monotonic() - started
        complete = len({key_of(row) for row in self.trials.load()}) == total
        ending = "cancelled" if self.cancel.is_set() else ("complete" if complete else "incomplete")
        self._note_session(started_at, wall, jobs, ending)
        if complete:
            self._finish()
        log.info(
            "%s: %d trial(s) run in %.1f s (%s), %d failed; results in %s",
            self.spec.kind,
            self.ran,
            wall,
            ending,
            self.failed,
            self.out,
        )
        if self.cancel.is_set():
            log.info("stopped: run the same command with --resume to finish the sweep")
            return 130
        return 1 if self.failed or self._worker_errors or not complete else 0

    def _note_session(self, started_at: float, wall: float, jobs: int, ending: str) -> None:
        path = self.out / RUNS_FILE
        try:
            sessions = json.loads(path.read_text(encoding="utf-8")) if path.exists() else []
        except json.JSONDecodeError:
            sessions = []
        sessions.append(
            {
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started_at)),
                "wall_time": round(wall, 3),
                "jobs": jobs,
                "router": self.options.router,
                "cluster": self.options.cluster,
                "trial_timeout": self.options.trial.timeout,
                "trials_run": self.ran,
                "failed": self.failed,
                "ended": ending,
                "cpu_count": os.cpu_count(),
                "code_at_end": code_fingerprint(),
                "versions": dependency_versions(),
            }
        )
        path.write_text(json.dumps(sessions, indent=2) + "\n", encoding="utf-8")

    def _finish(self) -> None:
        """The sweep is complete: rows in the sweep's order, the model's parameters, the report."""
        order = {key: i for i, key in enumerate(self.spec.keys())}
        self.trials.sort(lambda row: order[key_of(row)])
        self.timing.sort(lambda row: order[key_of(row)])
        records = sorted(self.metrics.load(), key=lambda r: order.get(key_of(r["key"]), len(order)))
        self.metrics.rewrite(records)
        write_params(self.out / PARAMS_FILE, (r["metrics"] for r in records), varied_paths(self.spec.factor_names()))
        if self.options.report:
            from .report import build_report  # matplotlib and scipy only when a report is made

            try:
                build_report(self.out)
            except Exception as exc:  # the results are safe; the report can be rebuilt from them
                log.error(
                    "the report was not built (%s: %s); once fixed: arroch experiment report %s",
                    type(exc).__name__,
                    exc,
                    self.out,
                )
                self._worker_errors.append(f"report: {exc}")
