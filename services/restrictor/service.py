"""The restrictor process: feedback in, acknowledgements and the active ConstraintSet out, over Zenoh.

I/O (keys under ``arroch/<namespace>/``):

- subscribes to ``feedback`` (Feedback) and answers each with a FeedbackAck published on
  ``feedback/ack/<src>``;
- answers queries on ``feedback`` whose payload is a Feedback with the FeedbackAck as reply
  (and publishes it on ``feedback/ack/<src>`` as well), so a client can wait for its answer
  either way; a retry with the same ``seq`` gets the same answer;
- publishes ``constraints`` (ConstraintSet) at start-up and on every change, and serves the
  current one on a ``constraints`` queryable for late joiners;
- serves the constraint library it accepts, with the site's choices resolved, on the
  ``constraints/library`` queryable (:mod:`protocol.constraint_library`): the feedback buttons
  of the AR client and the tablet page are built from this answer;
- drops expired constraints (window end reached on the site clock) and publishes the new version.

In a lockstep mission (the restrictor's part of the handshake, :mod:`runtime.lockstep`) the
restrictor's clock lags the simulator's by however many clock messages are still on their way, which
depends on the machine's load. So there a feedback's window starts at the feedback's own stamp
(:func:`~runtime.lockstep.feedback_time`), and constraints expire only when feedback is handled,
never on a timer: a ConstraintSet published between two world versions would reach the planner at a
moment of the machine's choosing, and the same seed would not give the same mission.

All state changes run on the service's worker thread: query callbacks only hand the query over
(Zenoh's thread must stay quick), and the worker replies once the feedback is applied.

Windows start at the site clock, so with ``--clock sim`` feedback needs the simulator's time. A
restrictor restarted mid-mission has not heard it yet when the first (re-sent) feedback arrives:
feedback then waits up to CLOCK_WAIT wall seconds for the first clock message (it comes twice a
second even while lockstep time stands still) before it is refused for want of a clock.
"""

from __future__ import annotations

import collections
import queue
import time
from pathlib import Path

import zenoh

from protocol.codec import ENCODING, decode, encode
from protocol.constraint_library import encode_library
from protocol.errors import ProtocolError
from protocol.messages import ConstraintSet, Feedback, FeedbackAck
from runtime.clock import SimClock, WallClock
from runtime.lockstep import expires_on_timer, feedback_time, in_lockstep
from runtime.service import Service
from runtime.transport import ZenohOptions

from .active import DEFAULT_MAX_ACTIVE, ActiveSet, Outcome
from .library import Library, SiteLike, library_for_site
from .store import StateStore
from .validate import quote

EXPIRY_PERIOD = 0.2  # wall seconds between expiry checks
QUERY_POLL = 0.02  # wall seconds between looks at pending feedback queries
MAX_PENDING_QUERIES = 1000
CLOCK_WAIT = 2.0  # wall seconds feedback may wait for the site clock before it is refused


class RestrictorService(Service):
    def __init__(
        self,
        *,
        site: SiteLike,
        library: Library,
        namespace: str,
        zenoh_options: ZenohOptions,
        state_dir: str | Path | None,
        clock: WallClock | SimClock | None = None,
        max_active: int = DEFAULT_MAX_ACTIVE,
        fresh: bool = False,
        instance: str | None = None,
    ) -> None:
        super().__init__("restrictor", namespace, zenoh_options, clock=clock, instance=instance)
        # The library never changes while the process runs: its answer is encoded once.
        self._library_reply = encode_library(self.instance, site.name, library_for_site(site, library))
        # Opening the store first means a bad state directory is reported before any Zenoh session.
        self.store = StateStore(state_dir, site.name)
        try:
            if fresh:
                self.store.clear()
            self.active = ActiveSet(library, site, self.store, max_active=max_active)
        except Exception:
            self.store.close()
            raise
        self._current: ConstraintSet | None = None
        self._queries: queue.Queue[zenoh.Query] = queue.Queue(maxsize=MAX_PENDING_QUERIES)
        # Feedback waiting for the site clock, in arrival order: (arrival, feedback, its query if any)
        self._held: collections.deque[tuple[float, Feedback, zenoh.Query | None]] = collections.deque()
        self.log.info(
            "state %s: %d active constraint(s), version %d",
            self.store.where,
            len(self.active.constraints),
            self.active.version,
        )

    def setup(self) -> None:
        self.subscribe(self.keys.feedback(), Feedback, self._on_feedback)
        self.serve(self.keys.feedback(), self._take_feedback_query)
        self.serve(self.keys.constraints(), lambda _query: self._current)
        self.hold(self.session.declare_queryable(self.keys.constraint_library(), self._answer_library))
        self.every(QUERY_POLL, self._answer_queries, first=0.0)
        self.every(EXPIRY_PERIOD, self._expire, first=0.0)
        self._publish_set()  # the restored set, for anyone already listening

    def _answer_library(self, query: zenoh.Query) -> None:
        try:  # on Zenoh's thread: the reply is ready-made
            query.reply(self.keys.constraint_library(), self._library_reply, encoding=zenoh.Encoding(ENCODING))
        except Exception:
            self.count("handler_errors")
            self.log.exception("answering a library query failed")

    def teardown(self) -> None:
        while True:  # queries still waiting get no reply; dropping them ends them for the querier
            try:
                self._queries.get_nowait().drop()
            except queue.Empty:
                break
        for _, _, query in self._held:
            if query is not None:
                query.drop()
        self._held.clear()
        self.store.close()

    # ------------------------------------------------------------------ feedback

    def _now(self) -> float | None:
        return self.clock.now() if self.clock.synced else None

    def _feedback_time(self, feedback: Feedback) -> float | None:
        """The site time a feedback takes effect at (see the module docstring)."""
        now = self._now()
        if now is None:
            return None
        return feedback_time(now, feedback.stamp, lockstep=in_lockstep(self.clock))

    def _on_feedback(self, feedback: Feedback, _key: str) -> None:
        self._take(feedback, None)

    def _take(self, feedback: Feedback, query: zenoh.Query | None) -> None:
        """Answer now, or hold the feedback (behind any already held) until the clock is known (at
        most MAX_PENDING_QUERIES of them: beyond that, feedback is answered at once, refused)."""
        if (self._held or self._now() is None) and len(self._held) < MAX_PENDING_QUERIES:
            if not self._held:
                self.log.info("feedback waits for the site clock (no clock message yet)")
            self._held.append((time.monotonic(), feedback, query))
            self.count("feedback_held")
            return
        self._answer(feedback, query)

    def _release_held(self) -> None:
        """Answer held feedback once the clock is known, or once it has waited CLOCK_WAIT (refused then)."""
        while self._held:
            arrived, feedback, query = self._held[0]
            if self._now() is None and time.monotonic() - arrived < CLOCK_WAIT:
                return
            self._held.popleft()
            self._answer(feedback, query)

    def _answer(self, feedback: Feedback, query: zenoh.Query | None) -> None:
        try:
            ack = self._respond(feedback)
            if query is not None:
                self._reply(query, ack)
        finally:
            if query is not None:
                query.drop()  # ends the query for the querier, replied or not

    def _take_feedback_query(self, query: zenoh.Query) -> None:
        """Zenoh's thread: keep the query for the worker (no reply yet)."""
        if query.payload is None:
            return None  # e.g. a wildcard query that happens to cover this key: not feedback
        try:
            self._queries.put_nowait(query)
        except queue.Full:
            self.count("dropped_queries")
            query.drop()
        return None

    def _answer_queries(self) -> None:
        self._release_held()
        while True:
            try:
                query = self._queries.get_nowait()
            except queue.Empty:
                return
            self._answer_query(query)

    def _answer_query(self, query: zenoh.Query) -> None:
        """Reply to a query (ending it), or hand its feedback to :meth:`_take`, which ends it later."""
        payload = query.payload.to_bytes()
        try:
            feedback = decode(payload, Feedback)
        except ProtocolError as exc:
            self.note_bad_message(self.keys.feedback(), payload, exc)
            # The querier is waiting: tell it what is wrong rather than let it time out.
            ack = FeedbackAck(to="", feedback_seq=0, accepted=False, reason=f"not a valid Feedback: {exc}"[:1000])
            try:
                self._reply(query, self.stamp(ack))
            finally:
                query.drop()
            return
        self.count("received")
        self._take(feedback, query)

    def _reply(self, query: zenoh.Query, ack: FeedbackAck) -> None:
        query.reply(self.keys.feedback(), encode(ack), encoding=zenoh.Encoding(ENCODING))

    def _respond(self, feedback: Feedback) -> FeedbackAck:
        """Apply feedback, publish its ack (and the set if it changed); returns the stamped ack."""
        outcome = self.active.handle(feedback, self._feedback_time(feedback))
        self._log_outcome(feedback, outcome)
        ack = self.stamp(outcome.ack)
        try:
            ack_key = self.keys.feedback_ack(feedback.src)
        except ValueError:  # a src that cannot be a key chunk: only a querier can get its answer
            self.count("unaddressable_acks")
        else:
            self.publish(ack_key, ack, stamp=False)
        if outcome.changed:
            self._publish_set()
        return ack

    def _log_outcome(self, feedback: Feedback, outcome: Outcome) -> None:
        sender = f"{quote(feedback.src)}/{feedback.seq}"
        if outcome.expired:
            self.count("expired", len(outcome.expired))
            self.log.info("expired %s", ", ".join(outcome.expired))
        if outcome.duplicate:
            self.count("feedback_duplicate")
            self.log.info("duplicate feedback %s: answered again", sender)
        elif outcome.ack.accepted:
            self.count("feedback_accepted")
            self.log.info(
                "feedback %s accepted: %s (version %d)", sender, outcome.ack.reason, outcome.ack.constraints_version
            )
        else:
            self.count("feedback_refused")
            self.log.info("feedback %s refused: %s", sender, outcome.ack.reason)

    # ------------------------------------------------------------------ the set

    def _expire(self) -> None:
        now = self._now()
        if now is None or not expires_on_timer(lockstep=in_lockstep(self.clock)):
            return  # lockstep: expiry comes with the next feedback (module docstring)
        gone = self.active.expire(now)
        if gone:
            self.count("expired", len(gone))
            self.log.info("expired %s at t=%.1f", ", ".join(gone), now)
            self._publish_set()

    def _publish_set(self) -> None:
        message = self.active.message()
        self.publish(self.keys.constraints(), message)
        # Swapping one reference is atomic, so the queryable (Zenoh's thread) reads a whole set.
        self._current = message
        self.log.debug("published constraints version %d (%d active)", message.version, len(message.constraints))
