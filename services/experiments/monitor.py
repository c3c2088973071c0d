"""The runner's own view of a trial over Zenoh: who is up, and how much planning the mission took.

One Zenoh client session per router (:class:`RouterMonitor`) serves every trial that uses that
router; each trial opens a :class:`TrialWatch` on its own namespace, which listens to

- the liveliness tokens of its services, so the sim is started only once the planner and the
  restrictor are listening (as ``arroch up`` does: the sim starts the mission clock, and the
  human's first feedback must find a restrictor);
- ``plan`` (TeamPlan), to count the plans the planner published and add up their solve times: the
  planner's share of a trial's wall time; and, for the point sweeps, to keep what each plan says
  (:class:`~.plan_changes.PlanRecord`: how feedback changed the plans).

Handlers run on Zenoh's threads and only update counters under a lock, so they never slow a link.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import zenoh

from protocol.codec import decoder_for
from protocol.errors import ProtocolError
from protocol.keys import Keys
from protocol.messages import TeamPlan
from runtime.transport import ZenohOptions, open_session

from .plan_changes import PlanRecord

log = logging.getLogger("arroch.experiment")


class TrialWatch:
    """What one trial's namespace shows. Close it when the trial ends."""

    def __init__(self, session: zenoh.Session, namespace: str) -> None:
        self.keys = Keys(namespace)
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._alive: dict[str, set[str]] = {}
        self.plans = 0
        self.solve_time = 0.0
        self.records: list[PlanRecord] = []
        self._decode_plan = decoder_for(TeamPlan)
        self._declared: list[Any] = [
            # history=True: a token declared before this subscriber counts too.
            session.liveliness().declare_subscriber(self.keys.liveliness("*", "*"), self._on_token, history=True),
            session.declare_subscriber(self.keys.plan(), self._on_plan),
        ]

    def _on_token(self, sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")
        service, instance = parts[-2], parts[-1]
        with self._changed:
            instances = self._alive.setdefault(service, set())
            if sample.kind == zenoh.SampleKind.PUT:
                instances.add(instance)
            else:
                instances.discard(instance)
            self._changed.notify_all()

    def _on_plan(self, sample: zenoh.Sample) -> None:
        try:
            plan = self._decode_plan(sample.payload.to_bytes())
        except ProtocolError:
            return  # the planner's own tests cover its messages; a bad one is simply not counted
        record = PlanRecord.of(plan)
        with self._lock:
            self.plans += 1
            self.solve_time += plan.solve_time
            self.records.append(record)

    def alive(self, service: str) -> bool:
        with self._lock:
            return bool(self._alive.get(service))

    def wait_alive(self, services: tuple[str, ...], timeout: float) -> list[str]:
        """Wait up to ``timeout`` s (or ``0.2`` s steps, so callers can poll other things) for every
        service in ``services`` to be up; returns those still missing."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                missing = [s for s in services if not self._alive.get(s)]
                remaining = deadline - time.monotonic()
                if not missing or remaining <= 0:
                    return missing
                self._changed.wait(min(remaining, 0.2))

    def planning(self) -> tuple[int, float]:
        """(plans published, their total solve time in s) so far."""
        with self._lock:
            return self.plans, self.solve_time

    def plan_records(self) -> list[PlanRecord]:
        """What every plan published so far said."""
        with self._lock:
            return list(self.records)

    def close(self) -> None:
        for entity in self._declared:
            try:
                entity.undeclare()
            except Exception:  # the session may already be gone; nothing is left to release
                pass
        self._declared.clear()


class RouterMonitor:
    """One Zenoh client session on one router, shared by the trials that use that router."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self._session: zenoh.Session | None = open_session(ZenohOptions(mode="client", connect=[endpoint]))

    def watch(self, namespace: str) -> TrialWatch:
        if self._session is None:
            raise RuntimeError(f"the monitor of {self.endpoint} is closed")
        return TrialWatch(self._session, namespace)

    def close(self) -> None:
        session, self._session = self._session, None
        if session is None:
            return
        # close() can block on a dead link (the router already stopped): never hold the sweep on it.
        closer = threading.Thread(target=session.close, name="monitor-close", daemon=True)
        closer.start()
        closer.join(2.0)
        if closer.is_alive():
            log.debug("the Zenoh session on %s did not close within 2 s", self.endpoint)
