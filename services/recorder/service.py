"""``Recorder``: a service that hears a namespace and hands every message to its recording profiles.

Handlers run inline (on Zenoh's thread, under one lock): nothing waits in an inbox, so when the
service is told to stop everything heard so far is already written, and the files are closed whole.
Each message comes with the very bytes it travelled as (the subscriptions here are the Service's
inline ones plus the payload), which the default profile keeps for ``arroch replay``.

The files are made once the recorder has joined Zenoh (the profiles' ``start``); a start that fails
removes what it made (``abort``), so a failed ``arroch record`` never blocks the next attempt.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Protocol

import zenoh

from protocol.codec import decoder_for
from protocol.errors import ProtocolError
from protocol.messages import Message
from runtime.clock import SimClock, WallClock
from runtime.service import Service
from runtime.transport import ZenohOptions, on_zenoh_thread

from .logtail import LogFollower, LogLine
from .timebase import Timebase
from .topics import recorded_keys

LOG_POLL = 0.25  # wall seconds between two looks at the followed log file
RESEND_TICK = 0.2  # wall seconds between a viewer's subscription and the state sent again for it
PROFILE_TICK = 1.0  # wall seconds between two calls of the profiles' tick (batches written when old)
# On stop, what is still on its way lands first: the last messages (mission_done among them) come
# right before the supervisor's SIGTERM, behind a lockstep run's dense poses and frames. On a loaded
# machine the recorder ran 15 site-s (about 1 wall s) behind, still draining after 2 s: the longest
# wait is generous, and ``arroch up`` gives the recorder RECORDER_STOP_TIMEOUT to use it.
SETTLE_QUIET, SETTLE_MAX = 0.5, 20.0  # wall s without a message that ends the wait; its longest


class RecordingProfile(Protocol):
    def start(self, at: int) -> None: ...
    def origin_fixed(self) -> None: ...
    def handle(self, msg: Message, key: str, payload: bytes) -> None: ...
    def log_line(self, line: LogLine, at: int, file: str = "") -> None: ...
    def resend(self, topic: str, at: int) -> None: ...
    def tick(self) -> None: ...
    def close(self) -> None: ...
    def abort(self) -> None: ...


class Recorder(Service):
    def __init__(
        self,
        namespace: str,
        zenoh_options: ZenohOptions,
        profiles: list[RecordingProfile],
        timebase: Timebase,
        *,
        log_file: Path | None = None,
        clock: WallClock | SimClock | None = None,
        name: str = "recorder",
    ) -> None:
        super().__init__(name, namespace, zenoh_options, clock=clock)
        self.profiles = profiles
        self.time = timebase
        self.log_file = log_file
        self.follower = LogFollower(log_file) if log_file is not None else None
        self.messages = 0
        self._lock = threading.Lock()
        self._closed = False
        self._resend: set[str] = set()  # topics a viewer subscribed to since the last tick
        for profile in profiles:
            sink = getattr(profile, "sink", None)
            if getattr(sink, "server", None) is not None:
                sink.on_subscribe = self._viewer_subscribed

    def _viewer_subscribed(self, topic: str) -> None:
        # Called before the subscription takes effect: what is sent for it goes out on the next timer tick.
        with self._lock:
            self._resend.add(topic)

    def _resend_pending(self) -> None:
        with self._lock:
            topics, self._resend = self._resend, set()
            if self._closed:
                return
            for topic in topics:
                for profile in self.profiles:
                    profile.resend(topic, self._now())

    def setup(self) -> None:
        with self._lock:
            try:
                for profile in self.profiles:
                    profile.start(self._now())
                    if self.time.fixed:  # the wall clock: known from the start
                        profile.origin_fixed()
            except BaseException:
                self._closed = True
                for profile in self.profiles:
                    profile.abort()
                raise
        for key, msg_type in recorded_keys(self.keys):
            self._subscribe_with_payload(key, msg_type)
        if self.follower is not None:
            self.every(LOG_POLL, self._follow_log, first=0.0)
        self.every(RESEND_TICK, self._resend_pending)
        self.every(PROFILE_TICK, self._tick)

    def _subscribe_with_payload(self, key: str, msg_type: type[Message]) -> None:
        """Like an inline :meth:`subscribe`, handing the payload on too (a bad one is counted and dropped)."""
        decode = decoder_for(msg_type)
        put = zenoh.SampleKind.PUT

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            sample_key = str(sample.key_expr)
            try:
                msg = decode(payload)
            except ProtocolError as exc:
                if sample.kind == put:
                    self.note_bad_message(sample_key, payload, exc, subscription=key)
                return
            self.count("received")
            try:
                self._on_message(msg, sample_key, payload)
            except Exception:
                self.log.exception("recording a message on %s failed", sample_key)

        self.hold(self.session.declare_subscriber(key, on_zenoh_thread(on_sample)))

    def _now(self) -> int:
        """Log time now: the site clock's, once it and the origin are known; until then the wall clock."""
        if self.time.fixed and getattr(self.clock, "synced", True):
            return self.time.at(self.clock.now())
        return time.time_ns()

    def _on_message(self, msg: Message, key: str, payload: bytes) -> None:
        with self._lock:
            if self._closed:
                return
            self.messages += 1
            self.count("recorded")  # in the stats queryable's answer: what made it into the recording
            if self.time.fix(msg.stamp):
                for profile in self.profiles:
                    profile.origin_fixed()
            for profile in self.profiles:
                profile.handle(msg, key, payload)

    def _follow_log(self) -> None:
        assert self.follower is not None and self.log_file is not None
        lines = self.follower.poll()
        if not lines:
            return
        at = self._now()  # stamped when read: the log's own times are wall times, not site times
        with self._lock:
            if self._closed:
                return
            for line in lines:
                for profile in self.profiles:
                    profile.log_line(line, at, self.log_file.name)

    def _tick(self) -> None:
        with self._lock:
            if not self._closed:
                for profile in self.profiles:
                    profile.tick()

    def _settle(self) -> None:
        """Wait (the session still open) until no message came for SETTLE_QUIET s, at most SETTLE_MAX s."""
        deadline = time.monotonic() + SETTLE_MAX
        seen = -1
        while seen != self.messages and time.monotonic() < deadline:
            seen = self.messages
            time.sleep(SETTLE_QUIET)

    def teardown(self) -> None:
        if not self._closed:
            self._settle()
        if self.follower is not None and not self._closed:
            self._follow_log()  # the last lines
        with self._lock:
            if self._closed:
                return
            self._closed = True
            for profile in self.profiles:
                try:
                    profile.close()
                except Exception:
                    self.log.exception("could not close %s", type(profile).__name__)
        self.log.info("recorded %d messages", self.messages)
