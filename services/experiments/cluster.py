"""Trials on a Dask distributed cluster (``--cluster tcp://HOST:PORT``).

Each trial is self-contained: on the worker that takes it, it starts its own Zenoh router and its
own planner, restrictor and sim (:func:`run_on_worker`), and hands back a :class:`~.trial.TrialOutcome`;
nothing of a trial crosses machines but its description and its outcome. The sweep records outcomes
as they come back, exactly as it records the local pool's, so the same sweep gives the same
``trials.csv`` either way (the rows are put in the sweep's order at the end).

The workers need the project installed (the same code: ``timing.csv`` records each trial's code
fingerprint). ``distributed`` is an optional dependency (``pip install 'arroch[cluster]'``).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from .design import SweepSpec, TrialKey
from .routers import Router, RouterError
from .trial import Trial, TrialConfig, TrialOutcome

log = logging.getLogger("arroch.experiment")

POLL = 0.2  # wall s between two looks at the submitted trials


class ClusterError(RuntimeError):
    """The cluster cannot be used (not installed, not reachable)."""


def run_on_worker(spec_json: dict[str, Any], key: tuple[Any, ...], config: TrialConfig) -> TrialOutcome:
    """One trial on a worker: a router of its own, the trial, the router stopped."""
    spec = SweepSpec.from_json(spec_json)
    trial_key = TrialKey(*key)
    try:
        router = Router(config.log_level).start()
    except RouterError as exc:
        return TrialOutcome(trial_key, "error", f"router on the worker: {exc}")
    try:
        namespace = f"exp{os.getpid()}t{threading.get_ident() % 100000}{trial_key.ident().replace('.', '_')}"
        return Trial(spec, trial_key, router, config, threading.Event(), namespace).run()
    finally:
        router.stop()


class ClusterPool:
    """Submits trials to the scheduler at ``address`` and yields their outcomes as they finish."""

    def __init__(self, address: str, *, timeout: float) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ClusterError("--cluster needs the 'distributed' package: pip install 'arroch[cluster]'") from None
        try:
            self.client = Client(address, timeout=f"{timeout:g}s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        self.address = address
        self._futures: list[Any] = []

    def workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def run(
        self,
        spec: SweepSpec,
        keys: list[TrialKey],
        config: TrialConfig,
        cancelled: Callable[[], bool],
        idle: Callable[[], None] = lambda: None,
    ) -> Iterator[TrialOutcome]:
        """Every trial of ``keys``, submitted at once; outcomes in the order they finish. ``cancelled``
        is asked (and ``idle`` called) a few times a second; once it says so the rest is cancelled."""
        spec_json = spec.to_json()
        # events_dir and recordings_dir are paths on this machine: a worker elsewhere keeps no event
        # log and runs no recorder (a failed trial's reason and services' output still come back).
        remote = dataclasses.replace(config, events_dir=None, record="none", recordings_dir=None)
        self._futures = [
            self.client.submit(
                run_on_worker,
                spec_json,
                dataclasses.astuple(key),
                remote,
                key=f"arroch-trial-{key.ident()}",
                pure=False,
            )
            for key in keys
        ]
        remaining = dict(zip(self._futures, keys, strict=True))
        while remaining:
            if cancelled():
                self.cancel()
                return
            finished = [future for future in remaining if future.done()]
            if not finished:
                idle()
                time.sleep(POLL)
                continue
            for future in finished:
                key = remaining.pop(future)
                try:
                    yield future.result()
                except Exception as exc:  # the worker died or the task raised: the trial failed, the sweep goes on
                    yield TrialOutcome(key, "error", f"on the cluster: {type(exc).__name__}: {exc}")

    def cancel(self) -> None:
        if self._futures:
            self.client.cancel(self._futures)

    def close(self) -> None:
        self.client.close()
