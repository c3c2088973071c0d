"""``Recorder``: a service that hears a namespace and hands every message to its recording profiles.

Handlers run inline (on Zenoh's thread, under one lock): nothing waits in an inbox, so when the
service is told to stop everything heard so far is already written, and the files are closed whole.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Protocol

from protocol.clock import SimClock, WallClock
from protocol.messages import Message
from protocol.service import Service
from protocol.transport import ZenohOptions

from .logtail import LogFollower
from .topics import recorded_keys

LOG_POLL = 0.25  # wall seconds between two looks at the followed log file
RESEND_TICK = 0.2  # wall seconds between a viewer's subscription and the state sent again for it


class RecordingProfile(Protocol):
    def start(self, t: float) -> None: ...
    def handle(self, msg: Message, key: str) -> None: ...
    def log_line(self, t: float, level: str, name: str, text: str) -> None: ...
    def close(self) -> None: ...


class Recorder(Service):
    def __init__(
        self,
        namespace: str,
        zenoh_options: ZenohOptions,
        profiles: list[RecordingProfile],
        *,
        log_file: Path | None = None,
        clock: WallClock | SimClock | None = None,
        name: str = "recorder",
    ) -> None:
        super().__init__(name, namespace, zenoh_options, clock=clock)
        self.profiles = profiles
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
                    resend = getattr(profile, "resend", None)
                    if resend is not None:
                        resend(topic, self._now())

    def setup(self) -> None:
        with self._lock:
            for profile in self.profiles:
                profile.start(self._now())
        for key, msg_type in recorded_keys(self.keys):
            self.subscribe(key, msg_type, self._on_message, inline=True)
        if self.follower is not None:
            self.every(LOG_POLL, self._follow_log, first=0.0)
        self.every(RESEND_TICK, self._resend_pending)

    def _now(self) -> float:
        return self.clock.now() if getattr(self.clock, "synced", True) else 0.0

    def _on_message(self, msg: Message, key: str) -> None:
        with self._lock:
            if self._closed:
                return
            self.messages += 1
            for profile in self.profiles:
                profile.handle(msg, key)

    def _follow_log(self) -> None:
        assert self.follower is not None
        lines = self.follower.poll()
        if not lines:
            return
        t = self._now()  # stamped when read: the log's own times are wall times
        with self._lock:
            if self._closed:
                return
            for line in lines:
                for profile in self.profiles:
                    profile.log_line(t, line.level, line.name, line.text)

    def teardown(self) -> None:
        if self.follower is not None:
            self._follow_log()  # the last lines
        with self._lock:
            self._closed = True
            for profile in self.profiles:
                try:
                    profile.close()
                except Exception:
                    self.log.exception("could not close %s", type(profile).__name__)
        self.log.info("recorded %d messages", self.messages)
