"""The small base every ARROCH service process is built on.

A :class:`Service` owns one Zenoh session and one worker thread (the caller's, in :meth:`run`).
Zenoh callbacks only enqueue raw payloads; decoding, validation and the service's handlers
all run on the worker, one message at a time, so service code needs no locks and a slow
handler never stalls Zenoh's receive thread.

What it takes care of, so services don't:

- publishing with the envelope stamped (``src``, per-sender ``seq``, ``stamp`` from the clock);
- decoding with validation; a bad payload is dropped, counted per key, and logged at most once
  per sender per minute;
- bounded inboxes: streams declared ``latest=True`` (poses, camera frames) keep only the newest
  payload per key; other subscriptions queue up to ``inbox_size`` and count what overflowed;
- a liveliness token ``arroch/<site>/@liveliness/<service>/<id>`` and a ``stats/<service>/<id>``
  queryable answering with the counters;
- SIGINT/SIGTERM: stop the loop, undeclare, close the session (bounded, so exit never hangs).
"""

from __future__ import annotations

import collections
import logging
import os
import queue
import signal
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, TypeVar

import zenoh

from .clock import SimClock, WallClock
from .codec import ENCODING, decode, encode
from .errors import ProtocolError
from .keys import Keys
from .messages import Clock as ClockMessage
from .messages import Event, Message
from .transport import ZenohOptions, open_session

M = TypeVar("M", bound=Message)
Handler = Callable[[Any, str], None]  # (message, key) -> None

BAD_LOG_INTERVAL = 60.0  # seconds between two log lines about one sender's bad messages
CLOSE_TIMEOUT = 1.5  # seconds granted to zenoh's session.close()


@dataclass
class _Subscription:
    key: str
    msg_type: type[Message]
    handler: Handler
    latest: bool


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
        self.instance = instance or f"{name}-{os.getpid()}"
        self.src = self.instance
        self.keys = Keys(namespace)
        self.log = logging.getLogger(f"arroch.{name}")
        self.clock = clock if clock is not None else SimClock()
        self._options = zenoh_options
        self._session: zenoh.Session | None = None
        self._declared: list[Any] = []
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._seq = 0
        self._seq_lock = threading.Lock()
        self._inbox: queue.Queue = queue.Queue(maxsize=inbox_size)
        self._latest: dict[str, tuple[_Subscription, bytes]] = {}
        self._latest_lock = threading.Lock()
        self._timers: list[list[Any]] = []  # [next_due_monotonic, period, fn]
        self._stop = threading.Event()
        self._last_bad_log: dict[tuple[str, str], float] = {}
        self.counters: collections.Counter[str] = collections.Counter()

    # ------------------------------------------------------------------ lifecycle

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("service is not open: call open() first")
        return self._session

    def open(self) -> "Service":
        self._session = open_session(self._options)
        token = self._session.liveliness().declare_token(self.keys.liveliness(self.name, self.instance))
        self._declared.append(token)
        self._declared.append(self._session.declare_queryable(self.keys.stats(self.name, self.instance), self._answer_stats))
        if isinstance(self.clock, SimClock):
            self.subscribe(self.keys.clock(), ClockMessage, lambda msg, key: self.clock.update(msg), latest=True)
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
        return self._stop.is_set()

    def install_signal_handlers(self) -> None:
        def _handle(signum: int, _frame: Any) -> None:
            self.log.info("received %s, stopping", signal.Signals(signum).name)
            self.stop()

        signal.signal(signal.SIGINT, _handle)
        signal.signal(signal.SIGTERM, _handle)

    def run(self) -> None:
        """Process messages and timers until :meth:`stop` (or a signal), then close."""
        try:
            while not self._stop.is_set():
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
        # session.close() can block on a dead link; never let it hold the process hostage.
        closer = threading.Thread(target=session.close, name="zenoh-close", daemon=True)
        closer.start()
        closer.join(CLOSE_TIMEOUT)
        if closer.is_alive():
            self.log.warning("zenoh session did not close within %.1f s; exiting anyway", CLOSE_TIMEOUT)
        self.log.info("%s %s stopped", self.name, self.instance)

    def __enter__(self) -> "Service":
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
            self.counters["handler_errors"] += 1
            self.log.exception("handler %s failed", getattr(fn, "__name__", fn))

    # ------------------------------------------------------------------ subscribing

    def subscribe(self, key: str, msg_type: type[M], handler: Callable[[M, str], None], *, latest: bool = False) -> None:
        """Call ``handler(message, key)`` on the worker for each valid message on ``key``.

        ``latest=True`` for state streams where only the newest value per key matters: at most one
        payload per key waits, so a slow consumer sees fresh data and memory stays bounded.
        """
        sub = _Subscription(key, msg_type, handler, latest)

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            self._enqueue(sub, str(sample.key_expr), sample.payload.to_bytes())

        self._declared.append(self.session.declare_subscriber(key, on_sample))

    def _enqueue(self, sub: _Subscription, key: str, payload: bytes) -> None:
        if sub.latest:
            with self._latest_lock:
                pending = key in self._latest
                self._latest[key] = (sub, payload)
            if pending:
                self.counters["superseded"] += 1
                return
            item: Any = ("latest", key)
        else:
            item = (sub, key, payload)
        try:
            self._inbox.put_nowait(item)
        except queue.Full:
            self.counters["dropped_inbox_full"] += 1
            if item[0] == "latest":
                with self._latest_lock:
                    self._latest.pop(key, None)

    def _dispatch(self, item: Any) -> None:
        if item[0] == "latest":
            with self._latest_lock:
                entry = self._latest.pop(item[1], None)
            if entry is None:
                return
            sub, payload = entry
            key = item[1]
        else:
            sub, key, payload = item
        message = self.decode_or_count(payload, sub.msg_type, key)
        if message is not None:
            self.counters["received"] += 1
            self._guarded(sub.handler, message, key)

    def decode_or_count(self, payload: bytes, msg_type: type[M], key: str) -> M | None:
        """Decode a payload; on failure count it, log it (rate-limited per sender) and return None."""
        try:
            return decode(payload, msg_type)
        except ProtocolError as exc:
            self.note_bad_message(key, payload, exc)
            return None

    def note_bad_message(self, key: str, payload: bytes, exc: Exception) -> None:
        self.counters["bad_messages"] += 1
        self.counters[f"bad_messages:{key}"] += 1
        sender = _guess_sender(payload)
        now = time.monotonic()
        last = self._last_bad_log.get((key, sender))
        if last is None or now - last >= BAD_LOG_INTERVAL:
            self._last_bad_log[(key, sender)] = now
            self.log.warning("dropped bad message on %s from %s: %s (further ones from it counted, logged once a minute)", key, sender, exc)

    # ------------------------------------------------------------------ publishing

    def next_seq(self) -> int:
        with self._seq_lock:
            self._seq += 1
            return self._seq

    def stamp(self, msg: M) -> M:
        msg.src = self.src
        msg.seq = self.next_seq()
        msg.stamp = self.clock.now()
        return msg

    def publish(self, key: str, msg: Message, *, stamp: bool = True) -> None:
        """Stamp (unless told not to) and publish; publishers are declared once per key."""
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = self.session.declare_publisher(
                key, encoding=zenoh.Encoding(ENCODING), congestion_control=zenoh.CongestionControl.BLOCK
            )
            self._publishers[key] = publisher
            self._declared.append(publisher)
        if stamp:
            self.stamp(msg)
        publisher.put(encode(msg))
        self.counters["published"] += 1

    # ------------------------------------------------------------------ queries

    def serve(self, key: str, answer: Callable[[zenoh.Query], Message | None]) -> None:
        """Answer queries on ``key`` with ``answer(query)`` (runs on Zenoh's thread: keep it quick).

        ``None`` means nothing to say (the querier gets no reply)."""

        def on_query(query: zenoh.Query) -> None:
            try:
                reply = answer(query)
                if reply is not None:
                    query.reply(key, encode(reply), encoding=zenoh.Encoding(ENCODING))
            except Exception:
                self.counters["handler_errors"] += 1
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
        stats = Event(kind="stats", data={"service": self.name, "instance": self.instance, **dict(self.counters)})
        query.reply(query.key_expr, encode(self.stamp(stats)), encoding=zenoh.Encoding(ENCODING))


def _guess_sender(payload: bytes) -> str:
    """Best-effort sender of an undecodable payload, for rate-limited logging only."""
    try:
        import msgpack

        data = msgpack.unpackb(payload, raw=False, max_str_len=256, max_array_len=64, max_map_len=64, max_bin_len=0)
        src = data.get("src") if isinstance(data, dict) else None
        return src if isinstance(src, str) and len(src) <= 128 else "unknown"
    except Exception:
        return "unknown"
