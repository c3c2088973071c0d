"""The small base every ARROCH service process is built on.

A :class:`Service` owns one Zenoh session and one worker thread (the caller's, in :meth:`run`).
Zenoh callbacks only decode and validate payloads (bounded work: payloads are size-limited) and
enqueue the valid messages; the service's handlers all run on the worker, one message at a time,
so service code needs no locks and a slow handler never stalls Zenoh's receive thread. Checking
on arrival keeps bad payloads out of the inbox: however many arrive, they take no room from valid
messages.

A subscription declared ``inline=True`` skips the worker: the payload is decoded and the handler
called on Zenoh's own receive thread (:func:`runtime.transport.on_zenoh_thread`; other callbacks
run on a Python thread zenoh-python feeds from it). That saves two thread hand-offs (tens of µs per
message on a loaded machine) for cheap, thread-safe handlers such as the site clock or an echo;
such handlers run concurrently with the worker and with each other.

What it takes care of, so services don't:

- publishing with the envelope stamped (``src``, per-sender ``seq``, ``stamp`` from the clock);
- decoding with validation; a bad payload is dropped, counted per key, and logged at most once
  per sender per minute;
- bounded inboxes: streams declared ``latest=True`` (poses, camera frames) keep only the newest
  valid message per key and subscription (checked on arrival, so a bad payload never displaces a
  good one); other subscriptions queue up to ``inbox_size`` and count what overflowed;
- bounded counters: per-key counts (bad, superseded, dropped) for at most ``MAX_KEYED_COUNTERS``
  keys; payloads on further keys are counted under their subscription's key expression;
- cheap counting on the hot path: ``received``, ``published`` and ``seq`` are lock-free tallies
  (``itertools.count``), folded into :attr:`Service.counters` when they are read;
- a liveliness token ``arroch/<site>/@liveliness/<service>/<id>`` and a ``stats/<service>/<id>``
  queryable answering with the counters (also to wildcard queries such as ``stats/**``, each service
  replying on its own key so replies are not merged);
- SIGINT/SIGTERM: stop the loop, undeclare, close the session (bounded, so exit never hangs).
"""

from __future__ import annotations

import collections
import itertools
import logging
import os
import queue
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, TypeVar

import msgspec
import zenoh

from protocol.codec import ENCODING, decode, decoder_for, encode, encoder_for, validator_for
from protocol.errors import ProtocolError
from protocol.keys import Keys
from protocol.messages import Clock as ClockMessage
from protocol.messages import Event, Message

from .clock import SimClock, WallClock
from .signals import StopSignals
from .transport import ZenohOptions, on_zenoh_thread, open_session

M = TypeVar("M", bound=Message)
Handler = Callable[[Any, str], None]  # (message, key) -> None

BAD_LOG_INTERVAL = 60.0  # seconds between two log lines about one sender's bad messages
# Publisher options of every Service (and of raw-Zenoh baselines that want to compare like with like).
# BLOCK: a reliable stream never silently drops under load. Express: messages are not batched, which
# Zenoh documents as better latency for less throughput; ARROCH's messages are few, small and
# latency-bound (poses at 20 Hz, plans, feedback). Bulk streams can opt out in advertise().
CONGESTION_CONTROL = zenoh.CongestionControl.BLOCK
EXPRESS = True
# Zenoh's defaults, spelled out so that a baseline built with publisher_options() cannot differ.
PRIORITY = zenoh.Priority.DATA
RELIABILITY = zenoh.Reliability.RELIABLE
CLOSE_TIMEOUT = 1.5  # seconds granted to zenoh's session.close()
DRAIN_ASK = 5.0  # seconds one barrier query of drain() waits before it is asked again
MAX_BAD_SENDERS = 1024  # senders remembered for log rate limiting; older ones are forgotten
# Distinct ``<counter>:<key>`` counters a service keeps: a peer putting on ever new keys under a
# wildcard subscription (robot/<anything>/pose) must not grow the counters, and the stats reply with
# them, without bound.
MAX_KEYED_COUNTERS = 256
# Counters bumped for every message, kept as lock-free tallies (see _Tally) rather than under the lock.
TALLIED = ("received", "published")


class _Tally:
    """A count any thread may add one to without a lock.

    ``add()`` is an ``itertools.count``'s ``__next__``: one C call, which the GIL makes atomic. On the
    cold caches a message callback runs on, that costs a fraction of taking a lock and updating a
    Counter. ``take()`` returns what was added since the previous ``take()`` (each take consumes one
    value of the count itself); takes must not run concurrently (the Service holds its lock)."""

    __slots__ = ("add", "_last")

    def __init__(self) -> None:
        self.add: Callable[[], int] = itertools.count().__next__
        self._last = -1  # what the previous take()'s own add() returned

    def take(self) -> int:
        now = self.add()
        added, self._last = now - self._last - 1, now
        return added


# eq=False: subscriptions are compared and hashed by identity, so they can key the latest-slots.
@dataclass(eq=False)
class _Subscription:
    key: str
    msg_type: type[Message]
    handler: Handler
    latest: bool
    inline: bool = False


class Service:
    """Base of a service process. Subclasses declare their I/O in ``setup()`` and react in handlers."""

    def __init__(
        self,
        name: str,
        namespace: str,
        zenoh_options: ZenohOptions,
        *,
        instance: str | None = None,
        clock: WallClock | SimClock | None = None,
        inbox_size: int = 10_000,
    ) -> None:
        self.name = name
        self.instance = instance or _default_instance(name)
        self.src = self.instance
        self.keys = Keys(namespace)
        self.log = logging.getLogger(f"arroch.{name}")
        self.clock = clock if clock is not None else SimClock()
        self._options = zenoh_options
        self._session: zenoh.Session | None = None
        self._declared: list[Any] = []
        self._publishers: dict[str, zenoh.Publisher] = {}
        # Per-sender message counter: itertools.count's next() is atomic under the GIL (no lock).
        self.next_seq: Callable[[], int] = itertools.count(1).__next__
        self._inbox: queue.Queue = queue.Queue(maxsize=inbox_size)
        # Newest waiting payload per (subscription, key): two latest-subscriptions matching the same
        # key each get their own slot, so neither steals the other's sample.
        self._latest: dict[tuple[_Subscription, str], bytes] = {}
        self._latest_lock = threading.Lock()
        self._publishers_lock = threading.Lock()
        self._timers: list[list[Any]] = []  # [next_due_monotonic, period, fn]
        self._stop = threading.Event()
        self.signals = StopSignals()  # set by signal handlers; the worker loop turns it into a stop
        self._last_bad_log: dict[str, float] = {}  # sender -> monotonic time of its last log line
        self._counters_lock = threading.Lock()
        self._counters: collections.Counter[str] = collections.Counter()
        self._tallies = {name: _Tally() for name in TALLIED}
        self._keyed_counters = 0  # distinct "<counter>:<key>" entries in counters
        self._inbox_max = 0  # the deepest the inbox has been (stats: inbox_depth_max)
        self.close_timed_out = False  # set when zenoh's close() overran CLOSE_TIMEOUT

    # ------------------------------------------------------------------ lifecycle

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("service is not open: call open() first")
        return self._session

    def open(self) -> Service:
        self._session = open_session(self._options)
        token = self._session.liveliness().declare_token(self.keys.liveliness(self.name, self.instance))
        self._declared.append(token)
        self._declared.append(
            self._session.declare_queryable(self.keys.stats(self.name, self.instance), self._answer_stats)
        )
        if isinstance(self.clock, SimClock):
            # Inline: SimClock.update is cheap and locked, and the clock must not lag behind a slow
            # handler on the worker (nor stall in processes that never call run()).
            self.subscribe(self.keys.clock(), ClockMessage, lambda msg, key: self.clock.update(msg), inline=True)
        self.setup()
        self.log.info("%s %s up on namespace %s", self.name, self.instance, self.keys.site)
        return self

    def setup(self) -> None:
        """Declare subscriptions, publishers, queryables and timers. Override."""

    def teardown(self) -> None:
        """Last words before the session closes (e.g. persist state). Override."""

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set() or self.signals.received

    def install_signal_handlers(self) -> None:
        """SIGINT/SIGTERM stop the service. The handlers only note the signal (see
        :mod:`runtime.signals`); :meth:`run` logs it and stops within 0.1 s."""
        self.signals.install()

    def on_stop_signal(self) -> None:
        """Called once on the worker when a stop signal was noted. Override to say more."""
        self.log.info("received %s, stopping", self.signals.name)
        self.stop()

    def run(self) -> None:
        """Process messages and timers until :meth:`stop` (or a signal), then close."""
        try:
            while not self._stop.is_set():
                if self.signals.received:
                    self.on_stop_signal()
                    self._stop.set()
                    break
                timeout = self._run_due_timers()
                try:
                    item = self._inbox.get(timeout=min(timeout, 0.1))
                except queue.Empty:
                    continue
                self._dispatch(item)
        finally:
            self.close()

    def close(self) -> None:
        if self._session is None:
            return
        try:
            self.teardown()
        except Exception:
            self.log.exception("teardown failed")
        session, self._session = self._session, None
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except Exception:  # already gone with a broken link: nothing more to do
                pass
        self._declared.clear()
        self._publishers.clear()
        if not close_within(session, CLOSE_TIMEOUT):
            self.close_timed_out = True
            self.log.warning("zenoh session did not close within %.1f s; exiting anyway", CLOSE_TIMEOUT)
        self.log.info("%s %s stopped", self.name, self.instance)

    def drain(self, timeout: float) -> bool:
        """Wait until everything published so far has left this process; ``False`` after ``timeout``.

        Zenoh's ``session.close()`` drops what its send queues still hold, and a subscriber that
        reads slowly keeps them full (a BLOCK publisher waits on it through the router): a fast
        ``arroch replay`` that closed 0.5 s after its last message lost up to a third of them.
        So a query goes out behind the last message, at the lowest priority (sent only once every
        queue above it is empty) and BLOCK like the data, and a second session of this process
        answers it. The router handles one link's messages in order, so its reply means the router
        has taken every message before it; the router, which stays up, delivers them from there.
        Without a router between the two sessions (peers linked directly) the reply proves less."""
        if self._session is None:
            return True
        key = self.keys.drain(f"{self.instance}-{os.urandom(4).hex()}")
        answered = False
        helper = open_session(self._options)
        try:
            queryable = helper.declare_queryable(key, lambda query: query.reply(key, b""))
            deadline = time.monotonic() + timeout
            while not answered and time.monotonic() < deadline:
                # Until the router has seen the helper's queryable, the query goes nowhere: ask again.
                replies = self._session.get(
                    key,
                    timeout=max(0.1, min(DRAIN_ASK, deadline - time.monotonic())),
                    priority=zenoh.Priority.BACKGROUND,
                    congestion_control=zenoh.CongestionControl.BLOCK,
                )
                answered = any(reply.ok is not None for reply in replies)
                if not answered:
                    time.sleep(0.05)
            queryable.undeclare()
        finally:
            close_within(helper, CLOSE_TIMEOUT)
        if not answered:
            self.log.warning("what was published may not all have left within %.1f s", timeout)
        return answered

    def __enter__(self) -> Service:
        return self.open()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ timers

    def every(self, period: float, fn: Callable[[], None], *, first: float | None = None) -> None:
        """Call ``fn`` on the worker every ``period`` wall seconds (first after ``first``, default ``period``)."""
        self._timers.append([time.monotonic() + (period if first is None else first), period, fn])

    def _run_due_timers(self) -> float:
        now = time.monotonic()
        wait = 0.1
        for timer in self._timers:
            if timer[0] <= now:
                timer[0] = max(timer[0] + timer[1], now)  # no burst of catch-up calls after a stall
                self._guarded(timer[2])
            wait = min(wait, max(timer[0] - time.monotonic(), 0.0))
        return wait

    def _guarded(self, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:
            self._handler_failed(fn)

    def _handler_failed(self, fn: Callable[..., None]) -> None:
        """Count and log the exception being handled; the service carries on."""
        self.count("handler_errors")
        self.log.exception("handler %s failed", getattr(fn, "__name__", fn))

    # ------------------------------------------------------------------ counters

    @property
    def counters(self) -> collections.Counter[str]:
        """The service's counters, up to date (``received``, ``published``, ``bad_messages``... and
        whatever the service counts). From threads other than the worker, add with :meth:`count`."""
        with self._counters_lock:
            self._fold_tallies()
            return self._counters

    def _fold_tallies(self) -> None:
        """Add what the tallies counted since the last fold to the counters (lock held)."""
        for name, tally in self._tallies.items():
            added = tally.take()
            if added:
                self._counters[name] += added

    def count(self, name: str, n: int = 1) -> None:
        """Add ``n`` to counter ``name``. Safe from any thread (Zenoh callbacks, inline handlers,
        the worker): ``counter[k] += 1`` alone is a read and a write, and loses counts under races."""
        tally = self._tallies.get(name)
        if tally is not None and n == 1:
            tally.add()
            return
        with self._counters_lock:
            self._counters[name] += n

    def count_keyed(self, name: str, key: str, subscription: str | None = None) -> None:
        """Add one to counter ``name`` and to its per-key counter ``name:key`` (bounded: see
        :data:`MAX_KEYED_COUNTERS`)."""
        with self._counters_lock:
            self._counters[name] += 1
            self._counters[self._keyed_name(name, key, subscription)] += 1

    def _keyed_name(self, name: str, key: str, subscription: str | None) -> str:
        """``name:key``, or once :data:`MAX_KEYED_COUNTERS` are in use and the key is new,
        ``name:<subscription>`` (``name:(other keys)`` without one). Called with the counters lock held."""
        keyed = f"{name}:{key}"
        if keyed in self._counters:
            return keyed
        if self._keyed_counters >= MAX_KEYED_COUNTERS:
            keyed = f"{name}:{subscription or '(other keys)'}"
            if keyed in self._counters:
                return keyed
        self._keyed_counters += 1
        return keyed

    def counters_snapshot(self) -> dict[str, int]:
        """A consistent copy of the counters."""
        with self._counters_lock:
            self._fold_tallies()
            return dict(self._counters)

    # ------------------------------------------------------------------ subscribing

    def subscribe(
        self,
        key: str,
        msg_type: type[M],
        handler: Callable[[M, str], None],
        *,
        latest: bool = False,
        inline: bool = False,
        sample_key: bool = True,
        ordered: bool = False,
    ) -> None:
        """Call ``handler(message, key)`` on the worker for each valid message on ``key``.

        ``latest=True`` for state streams where only the newest value per key matters: at most one
        payload per key waits, so a slow consumer sees fresh data and memory stays bounded.

        ``inline=True`` decodes and calls the handler on Zenoh's receive thread instead, as soon as
        the sample arrives (no queue, so ``latest`` does not apply). Only for handlers that are quick
        (a slow one stalls the link) and thread-safe (they run beside the worker).

        ``sample_key=False`` hands the handler this subscription's ``key`` itself rather than each
        sample's own key, for handlers that do not look at it: with a wildcard, asking Zenoh for the
        sample's key costs two calls into it per message. (Bad payloads are still counted per key.)

        ``ordered=True`` decodes and queues each message on Zenoh's receive thread. Otherwise
        zenoh-python hands every subscription's samples to a Python thread of that subscription's
        own, so messages on different keys may reach the worker in another order than they came in.
        Ordered subscriptions of one service queue in the order their messages arrived over the link:
        a sender's status, event and clock, published in that order, are handled in that order.
        (Decoding then holds up the link: for small messages.)
        """
        if latest and inline:
            raise ValueError("a subscription is either latest (queued on the worker) or inline, not both")
        if latest and not sample_key:
            raise ValueError("a latest subscription keeps the newest message per key: it needs sample_key")
        sub = _Subscription(key, msg_type, handler, latest, inline)
        decode_msg = decoder_for(msg_type)
        refuse = self._refuser(key)
        # A key without wildcards is the key of every sample it receives: no need to ask Zenoh.
        given_key = key if _is_concrete(key) or not sample_key else None  # the key handlers get, if known
        # Each path is one flat function, asking Zenoh (each attribute is a call into Rust) only
        # what it needs: on a round trip the handler runs on a cold cache, where every extra frame
        # and call costs several times what a micro-benchmark says.
        if inline:
            add_received = self._tallies["received"].add

            def on_sample(sample: zenoh.Sample) -> None:
                payload = sample.payload.to_bytes()
                try:
                    message = decode_msg(payload)
                except ProtocolError as exc:
                    refuse(sample, payload, exc)
                    return
                add_received()
                try:
                    handler(message, given_key or str(sample.key_expr))
                except Exception:
                    self._handler_failed(handler)

        else:
            # Decoded on arrival, so only valid messages wait for the worker: a flood of bad payloads
            # takes no room in the inbox (valid messages are never dropped for it) and, on a latest
            # subscription, never displaces a good message from its slot.
            def on_sample(sample: zenoh.Sample) -> None:
                payload = sample.payload.to_bytes()
                try:  # (only the decoding raises ProtocolError)
                    self._enqueue(sub, given_key or str(sample.key_expr), decode_msg(payload))
                except ProtocolError as exc:
                    refuse(sample, payload, exc)

        # Inline: on Zenoh's receive thread itself, not on the Python thread zenoh-python would
        # hand the sample to (one thread wake-up less per message).
        self._declared.append(
            self.session.declare_subscriber(key, on_zenoh_thread(on_sample) if inline or ordered else on_sample)
        )

    def subscribe_foreign(
        self,
        key: str,
        decode_payload: Callable[[bytes], Any],
        handler: Callable[[Any, str], None],
        *,
        latest: bool = False,
        ordered: bool = False,
        history: bool = False,
    ) -> None:
        """Like :meth:`subscribe`, for payloads that are not ARROCH messages (e.g. ROS 2 CDR):
        ``decode_payload(bytes)`` runs on arrival, and whatever it raises counts the payload as a bad
        message (dropped, logged at most once a minute); its result goes to ``handler(value, key)``
        on the worker. ``latest`` and ``ordered`` mean what they mean for :meth:`subscribe`.
        ``history``: an advanced subscriber that also gets what transient-local (cached) publishers
        published before it was declared, including publishers that appear later."""
        sub = _Subscription(key, object, handler, latest)  # type: ignore[arg-type]
        refuse = self._refuser(key)

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            try:
                value = decode_payload(payload)
            except Exception as exc:  # any decoder's complaint: the payload is bad, not the service
                refuse(sample, payload, ProtocolError("payload", str(exc) or type(exc).__name__))
                return
            self._enqueue(sub, str(sample.key_expr), value)

        callback = on_zenoh_thread(on_sample) if ordered else on_sample
        if history:
            import zenoh.ext

            self._declared.append(
                zenoh.ext.declare_advanced_subscriber(
                    self.session, key, callback, history=zenoh.ext.HistoryConfig(detect_late_publishers=True)
                )
            )
            return
        self._declared.append(self.session.declare_subscriber(key, callback))

    def hold(self, entity: Any) -> Any:
        """Undeclare ``entity`` (a token, publisher, subscriber... declared on :attr:`session`) when
        the service closes. Returns it."""
        self._declared.append(entity)
        return entity

    def relay(self, key: str, msg_type: type[Message], to_key: str) -> None:
        """Republish every valid ``msg_type`` payload heard on ``key`` on ``to_key``, as it came.

        Each payload is checked like an inline subscription's (on Zenoh's thread; a bad one is
        counted and dropped, never passed on; a valid one counts as received and as published), and
        then the very bytes received go out again: nothing is re-encoded, so the envelope (``src``,
        ``seq``, ``stamp``) and any fields unknown to ``msg_type`` travel on unchanged."""
        put = self.advertise(to_key).put  # declared now: never inside a Zenoh callback
        check = validator_for(msg_type)  # decoding's checks (the message it builds is dropped)
        refuse = self._refuser(key)
        add_received, add_published = self._tallies["received"].add, self._tallies["published"].add

        def on_sample(sample: zenoh.Sample) -> None:
            received = sample.payload  # put back as it is: no copy, no encoding
            payload = received.to_bytes()
            try:
                check(payload)
            except ProtocolError as exc:
                return refuse(sample, payload, exc)
            put(received)  # first: the echo's latency is what a relay is for
            add_received()
            add_published()

        self._declared.append(self.session.declare_subscriber(key, on_zenoh_thread(on_sample)))

    def _refuser(self, key: str) -> Callable[[zenoh.Sample, bytes, ProtocolError], None]:
        """What a subscription on ``key`` does with a payload its check refused: count it and log it
        (:meth:`note_bad_message`), unless the sample is a DELETE, which has no payload to check.
        (The kind is asked only then: a valid PUT never pays for that call into Zenoh.)"""
        put_kind = zenoh.SampleKind.PUT
        fixed_key = key if _is_concrete(key) else None

        def refuse(sample: zenoh.Sample, payload: bytes, exc: ProtocolError) -> None:
            if sample.kind == put_kind:
                self.note_bad_message(fixed_key or str(sample.key_expr), payload, exc, subscription=key)

        return refuse

    def _enqueue(self, sub: _Subscription, key: str, message: Message) -> None:
        """Queue a decoded message for the worker (a latest-subscription: put it in its slot)."""
        if sub.latest:
            slot = (sub, key)
            with self._latest_lock:
                pending = slot in self._latest
                self._latest[slot] = message
            if pending:
                self.count_keyed("superseded", key, sub.key)
                return
            item: Any = ("latest", slot)
        else:
            item = (sub, key, message)
        try:
            self._inbox.put_nowait(item)
        except queue.Full:
            self.count_keyed("dropped_inbox_full", key, sub.key)
            if item[0] == "latest":
                with self._latest_lock:
                    self._latest.pop(slot, None)
            return
        depth = len(self._inbox.queue)  # a read of the deque's length: no lock needed for a high-water mark
        if depth > self._inbox_max:
            self._inbox_max = depth

    def _dispatch(self, item: Any) -> None:
        if item[0] == "latest":
            slot = item[1]
            with self._latest_lock:
                message = self._latest.pop(slot, None)
            if message is None:
                return
            sub, key = slot
        else:
            sub, key, message = item
        self.count("received")
        self._guarded(sub.handler, message, key)

    def decode_or_count(self, payload: bytes, msg_type: type[M], key: str) -> M | None:
        """Decode a payload; on failure count it, log it (rate-limited per sender) and return None."""
        try:
            return decode(payload, msg_type)
        except ProtocolError as exc:
            self.note_bad_message(key, payload, exc)
            return None

    def note_bad_message(self, key: str, payload: bytes, exc: Exception, *, subscription: str | None = None) -> None:
        """Count a bad payload (in total and per key) and log it at most once per sender per minute.

        Payloads too broken to name a sender share the sender ``unknown``. ``subscription`` is the key
        expression it arrived through, where it is counted once the per-key counters are full."""
        sender = _guess_sender(payload)
        now = time.monotonic()
        with self._counters_lock:
            self._counters["bad_messages"] += 1
            self._counters[self._keyed_name("bad_messages", key, subscription)] += 1
            last = self._last_bad_log.get(sender)
            should_log = last is None or now - last >= BAD_LOG_INTERVAL
            if should_log:
                if len(self._last_bad_log) >= MAX_BAD_SENDERS:
                    # A flood of forged sender ids must not grow memory without bound: forget the
                    # senders whose minute is over (or, failing that, everyone).
                    stale = [s for s, t in self._last_bad_log.items() if now - t >= BAD_LOG_INTERVAL]
                    for s in stale or list(self._last_bad_log):
                        del self._last_bad_log[s]
                self._last_bad_log[sender] = now
        if should_log:
            self.log.warning(
                "dropped bad message on %s from %s: %s (further ones from it counted, logged once a minute)",
                key,
                sender,
                exc,
            )

    # ------------------------------------------------------------------ publishing

    def stamp(self, msg: M) -> M:
        msg.src = self.src
        msg.seq = self.next_seq()
        msg.stamp = self.clock.now()
        return msg

    def advertise(self, key: str, *, express: bool = EXPRESS) -> zenoh.Publisher:
        """Declare the publisher for ``key`` now rather than at the first :meth:`publish`.

        Call it in ``setup()`` for keys published from inline handlers, so no Zenoh declaration
        happens inside a Zenoh callback; it also lets subscribers match before the first message.
        ``express=False`` lets Zenoh batch the key's messages (throughput over latency)."""
        publisher = self._publishers.get(key)
        if publisher is None:
            with self._publishers_lock:  # publish() may run on the worker and in inline handlers
                publisher = self._publishers.get(key)
                if publisher is None:
                    publisher = self.session.declare_publisher(key, **publisher_options(express=express))
                    self._publishers[key] = publisher
                    self._declared.append(publisher)
        return publisher

    def sender(
        self, key: str, msg_type: type[M], *, stamp: bool = True, express: bool = EXPRESS
    ) -> Callable[[M], None]:
        """A function publishing ``msg_type`` messages on ``key``: ``send(msg)`` does what
        ``publish(key, msg, stamp=stamp)`` does, with the publisher declared, the encoder and the
        counter looked up once, here. For a stream published often (on a cold cache, publish()'s
        lookups cost about as much as encoding a pose). Not to be called after :meth:`close`."""
        put = self.advertise(key, express=express).put
        encode_msg = encoder_for(msg_type)
        add_published = self._tallies["published"].add
        stamp_msg = self.stamp

        def send(msg: M) -> None:
            if stamp:
                stamp_msg(msg)
            payload = encode_msg(msg)
            put(payload)
            add_published()  # once put: a put that raised is not counted, as in publish()

        return send

    def publish(self, key: str, msg: Message, *, stamp: bool = True, extra: Mapping[str, Any] | None = None) -> None:
        """Stamp (unless told not to) and publish; publishers are declared once per key.

        ``extra`` adds fields unknown to the message type (see :func:`protocol.codec.encode`)."""
        publisher = self._publishers.get(key) or self.advertise(key)
        if stamp:
            self.stamp(msg)
        payload = encode(msg, extra)
        publisher.put(payload)
        self._tallies["published"].add()  # once put (a put that raised is not counted); one C call

    # ------------------------------------------------------------------ queries

    def serve(self, key: str, answer: Callable[[zenoh.Query], Message | None]) -> None:
        """Answer queries on ``key`` with ``answer(query)`` (runs on Zenoh's thread: keep it quick).

        ``None`` means nothing to say (the querier gets no reply)."""

        # A concrete key answers on itself; a wildcard queryable answers on the key it was asked.
        concrete = _is_concrete(key)

        def replies(query: zenoh.Query) -> list[tuple[str, Message]]:
            reply = answer(query)
            return [] if reply is None else [(key if concrete else str(query.key_expr), reply)]

        self.serve_each(key, replies)

    def serve_each(self, key: str, answer: Callable[[zenoh.Query], Iterable[tuple[str, Message]]]) -> None:
        """Answer queries on ``key`` with every ``(reply key, message)`` of ``answer(query)`` (on
        Zenoh's thread); each reply key must match the query's key (one per robot of ``robot/*/...``)."""

        def on_query(query: zenoh.Query) -> None:
            try:
                for reply_key, reply in answer(query):
                    query.reply(reply_key, encode(reply), encoding=zenoh.Encoding(ENCODING))
            except Exception:
                self.count("handler_errors")
                self.log.exception("answering a query on %s failed", key)

        self._declared.append(self.session.declare_queryable(key, on_query))

    def query(self, key: str, msg_type: type[M], *, payload: Message | None = None, timeout: float = 2.0) -> list[M]:
        """Ask ``key``; return the valid replies of ``msg_type`` (bad ones are counted)."""
        body = encode(self.stamp(payload)) if payload is not None else None
        replies = self.session.get(key, payload=body, timeout=timeout)
        out: list[M] = []
        for reply in replies:
            if reply.ok is None:
                continue
            msg = self.decode_or_count(reply.ok.payload.to_bytes(), msg_type, key)
            if msg is not None:
                out.append(msg)
        return out

    def _answer_stats(self, query: zenoh.Query) -> None:
        # Reply on this service's own key, not the query's: for ``stats/**`` the latter would be the
        # same key for every service, and Zenoh's reply consolidation would keep only one of them.
        try:
            # Gauges beside the counters: how much waits on the worker now, and the most that ever did.
            gauges = {
                "inbox_depth": self._inbox.qsize(),
                "inbox_depth_max": self._inbox_max,
                "latest_waiting": len(self._latest),
            }
            stats = Event(
                kind="stats",
                data={"service": self.name, "instance": self.instance, **self.counters_snapshot(), **gauges},
            )
            query.reply(
                self.keys.stats(self.name, self.instance), encode(self.stamp(stats)), encoding=zenoh.Encoding(ENCODING)
            )
        except Exception:
            self.count("handler_errors")
            self.log.exception("answering a stats query failed")


def close_within(session: zenoh.Session, timeout: float) -> bool:
    """Close ``session``, waiting at most ``timeout`` s; False when it had not closed by then.
    session.close() can block on a dead link: it never holds the process hostage."""
    closer = threading.Thread(target=session.close, name="zenoh-close", daemon=True)
    closer.start()
    closer.join(timeout)
    return not closer.is_alive()


def publisher_options(*, express: bool = EXPRESS) -> dict[str, Any]:
    """The options every Service publisher is declared with (``declare_publisher(key, **options)``)."""
    return {
        "encoding": zenoh.Encoding(ENCODING),
        "congestion_control": CONGESTION_CONTROL,
        "priority": PRIORITY,
        "express": express,
        "reliability": RELIABILITY,
    }


_instances_lock = threading.Lock()
_instances_made: collections.Counter[str] = collections.Counter()


def _is_concrete(key: str) -> bool:
    """True when ``key`` has no wildcard, so it is the key of every sample it matches."""
    return "*" not in key and "$" not in key


def _default_instance(name: str) -> str:
    """``<name>-<pid>``, with ``-<k>`` for the k-th further service of that name in this process:
    two instances must never share ``src`` (receivers tell messages apart by ``src`` and ``seq``),
    nor their liveliness and stats keys."""
    with _instances_lock:
        k = _instances_made[name]
        _instances_made[name] += 1
    return f"{name}-{os.getpid()}" if k == 0 else f"{name}-{os.getpid()}-{k}"


class _Sender(msgspec.Struct):
    src: Annotated[str, msgspec.Meta(max_length=128)] = "unknown"


_read_sender = msgspec.msgpack.Decoder(_Sender).decode


def _guess_sender(payload: bytes) -> str:
    """Best-effort sender of an undecodable payload, for rate-limited logging only."""
    try:
        return _read_sender(payload).src
    except Exception:
        return "unknown"
