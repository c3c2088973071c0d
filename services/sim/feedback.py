"""Sending the simulated human's feedback to the restrictor and waiting for its acknowledgement.

The sending itself is the restrictor's client helper (:func:`runtime.feedback_client.send_feedback`):
the Feedback goes out as a query on ``feedback``, and an ack published on ``feedback/ack/<src>``
counts too. An attempt with no ack within ``timeout`` wall seconds is repeated, ``retries`` times.
That blocks, so it runs on one background thread here; answers come back through :meth:`answers`,
read by the service's worker.

In lockstep the human's time stands still until her feedback is answered, so how long the ack takes
on the wall clock must not change the mission: there the sender never gives up on its own. It
repeats the attempt every ``timeout`` wall seconds until ``abort_after`` wall seconds have passed,
and then reports the answer as *aborted*: the sim ends the run as failed, loudly, rather than
going on without the constraint (which would make the outcome depend on the machine's load).
"""

from __future__ import annotations

import logging
import queue
import threading
from dataclasses import dataclass
from typing import Any

from protocol.messages import FeedbackAck
from runtime.service import Service

log = logging.getLogger("arroch.sim.feedback")


@dataclass(frozen=True)
class Answer:
    request: Any  # the engine's FeedbackRequest, handed back untouched
    ack: FeedbackAck | None  # None: no ack after every attempt
    aborted: bool = False  # lockstep: no ack within abort_after wall seconds (the run cannot go on faithfully)


class FeedbackSender:
    def __init__(self, service: Service, *, timeout: float, retries: int, abort_after: float | None = None) -> None:
        self._service = service
        self._timeout = timeout
        self._retries = retries
        self._abort_after = abort_after  # lockstep: keep trying this long (wall s), then abort
        self._stop = threading.Event()
        self._todo: queue.Queue = queue.Queue()
        self._answers: queue.Queue[Answer] = queue.Queue()
        self._thread = threading.Thread(target=self._run, name="feedback-sender", daemon=True)
        self._thread.start()

    def send(self, request: Any, kind: str, params: dict[str, Any]) -> None:
        """Queue one Feedback; its answer will come back with ``request``."""
        self._todo.put((request, kind, params))

    def answers(self) -> list[Answer]:
        out = []
        while True:
            try:
                out.append(self._answers.get_nowait())
            except queue.Empty:
                return out

    def close(self) -> None:
        """Stop sending. A query in flight is abandoned (the thread is a daemon and the session
        closes under it): shutting down must not wait out the retries of an absent restrictor."""
        self._stop.set()
        self._todo.put(None)
        self._thread.join(0.5)

    def _run(self) -> None:
        from runtime.feedback_client import send_feedback

        while not self._stop.is_set():
            item = self._todo.get()
            if item is None:
                return
            request, kind, params = item
            try:
                # Retries inside keep the same src and seq, so the restrictor can tell a repeat.
                budget = self._abort_after if self._abort_after is not None else self._timeout * (self._retries + 1)
                ack = send_feedback(self._service, kind, params, timeout=budget, retry=self._timeout)
            except Exception as exc:  # a session closing under us at shutdown, a broken link
                if self._stop.is_set():
                    return
                log.warning("sending feedback %s %s failed: %s", kind, params, exc)
                self._service.count("feedback_errors")
                ack = None
            if self._stop.is_set():
                return
            aborted = ack is None and self._abort_after is not None
            if ack is None and not aborted:
                log.warning("no ack for feedback %s %s after %d attempt(s)", kind, params, self._retries + 1)
            self._answers.put(Answer(request, ack, aborted))
