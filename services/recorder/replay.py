"""``arroch replay FILE``: publish a recording's ARROCH messages back onto Zenoh.

Each message goes out as it was recorded (same bytes: ``src``, ``seq`` and ``stamp`` unchanged) on
its key in the chosen namespace (default: the recorded one), so the AR client, the tablet page or the
planner can be fed a recorded mission. Pace: the recording's own (site seconds = wall seconds),
``--rate K`` times faster, ``--fast`` (no waiting), or ``--step`` (Enter publishes the next
``--step-size`` site seconds). ``--hold-camera`` lets what came before each camera frame land
(``--settle``), publishes the frame and waits for the AR client's overlay of it (as the lockstep sim
does), so overlays are drawn over the world they show. ``--loop`` plays the recording again and
again until Ctrl-C (what ``arroch demo --linger`` shows after its mission): each pass after the first
goes out re-timed, every site time (stamps, the clock, paths, door deadlines) shifted past the last
pass and each sender renamed ``<src>~<pass>``, since receivers drop a sender's messages that are
older than what they have (a pose stamped earlier, a clock with a lower ``seq``).

Examples:
  arroch replay runs/20260101-120000/run.mcap --only 'robot/*/pose' --only 'intent/*' --only clock
  arroch replay run.mcap --fast --hold-camera --skip 'ar/*' --namespace replayed
"""

from __future__ import annotations

import argparse
import fnmatch
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TextIO

import msgspec

from protocol.codec import encode
from protocol.messages import CameraFrame, Clock, DoorState, Intent, Message, Overlay, RobotCommand
from runtime.runner import add_common_arguments, leave_if_close_overran, zenoh_options
from runtime.service import Service
from runtime.transport import BLOCK_WAIT_BEFORE_CLOSE_US, NoRouter, ZenohOptions, through_local_router

from .reading import Recorded, RecordingError, message_topics, messages, metadata
from .topics import MESSAGE_PREFIX, key_of

log = logging.getLogger("arroch.replay")
PROGRESS_EVERY = 5.0  # wall seconds between two progress lines
LISTENER_POLL = 0.02  # wall s between looks for a subscriber before the first message
# Wall seconds the replay waits at most for its last messages to leave before it closes: as long as
# Zenoh lets a blocked link wait before closing it (a slow subscriber holds the router's queue that long).
DRAIN_TIMEOUT = BLOCK_WAIT_BEFORE_CLOSE_US / 1e6
LOOP_GAP = 2.0  # site seconds between the end of one --loop pass and the start of the next


class Pacer:
    """When to publish a message recorded at site time ``t``: now, later, or after the user says so."""

    def __init__(self, rate: float | None, step: float | None = None, prompt: Callable[[str], str] = input) -> None:
        self.rate = rate  # None: as fast as possible
        self.step = step
        self.prompt = prompt
        self._origin: tuple[float, float] | None = None  # (site time, wall time) of the first message
        self._step_until: float | None = None

    def wait(self, t: float, stopping: Callable[[], bool]) -> None:
        if self.step is not None:
            if self._step_until is None or t > self._step_until:
                self.prompt(f"t = {t:.2f} s: Enter publishes the next {self.step:g} s ")
                self._step_until = t + self.step
            return
        if self.rate is None:
            return
        if self._origin is None:
            self._origin = (t, time.monotonic())
        due = self._origin[1] + (t - self._origin[0]) / self.rate
        while not stopping():
            left = due - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, 0.1))


def selected(topic: str, only: list[str], skip: list[str]) -> bool:
    """Patterns match the key below the namespace (``robot/*/pose``, ``camera/tablet/frame``, ``clock``)."""
    rest = topic[len(MESSAGE_PREFIX) :]
    if only and not any(fnmatch.fnmatchcase(rest, p) for p in only):
        return False
    return not any(fnmatch.fnmatchcase(rest, p) for p in skip)


def retimed(record: Recorded, offset: float, suffix: str) -> Recorded:
    """``record`` as a later ``--loop`` pass sends it: every site time ``offset`` later, its sender
    ``src + suffix`` (a new sender, whose ``seq`` may start again)."""
    msg = record.message
    changes: dict[str, object] = {"stamp": msg.stamp + offset, "src": msg.src + suffix}
    if isinstance(msg, Clock):
        changes["time"] = msg.time + offset
    elif isinstance(msg, (Intent, RobotCommand)):
        changes["trajectory"] = [[row[0] + offset, *row[1:]] for row in msg.trajectory]
    elif isinstance(msg, DoorState) and msg.until > 0:
        changes["until"] = msg.until + offset
    moved: Message = msgspec.structs.replace(msg, **changes)
    return Recorded(record.topic, record.time + offset, encode(moved), moved)


class Replayer(Service):
    """Publishes recorded payloads; with ``hold_camera``, waits for each frame's overlay."""

    def __init__(
        self, namespace: str, options: ZenohOptions, *, hold_camera: float | None = None, settle: float = 0.05
    ) -> None:
        super().__init__("replay", namespace, options)
        self.hold_camera = hold_camera
        self.settle = settle
        self.published = 0
        self.holds_timed_out = 0
        self._answered: dict[str, int] = {}  # camera -> newest frame_seq with an overlay
        self._overlay = threading.Condition()

    def setup(self) -> None:
        if self.hold_camera is not None:
            self.subscribe(self.keys.overlay(), Overlay, self._on_overlay, inline=True)

    def _on_overlay(self, msg: Overlay, key: str) -> None:
        with self._overlay:
            self._answered[msg.camera] = max(self._answered.get(msg.camera, -1), msg.frame_seq)
            self._overlay.notify_all()

    def put(self, record: Recorded) -> None:
        key = key_of(self.keys, record.topic)
        if self.hold_camera is not None and isinstance(record.message, CameraFrame):
            # Receivers take each key on a thread of its own: let what went before the frame (poses,
            # intents) land first, as it had in the recorded run, where time stood still meanwhile.
            time.sleep(self.settle)
        # advertise() declares a key's publisher once; camera frames are bulk (batched), the rest go as they come.
        self.advertise(key, express=not isinstance(record.message, CameraFrame)).put(record.payload)
        self.published += 1
        if self.hold_camera is not None and isinstance(record.message, CameraFrame):
            frame = record.message
            deadline = time.monotonic() + self.hold_camera
            with self._overlay:
                while self._answered.get(frame.camera, -1) < frame.seq and not self.stopping:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        self.holds_timed_out += 1
                        break
                    self._overlay.wait(min(left, 0.1))

    def await_listener(self, topics: Iterable[str], timeout: float) -> bool:
        """Wait up to ``timeout`` wall s until some subscriber anywhere takes one of the recorded
        ``topics`` (Zenoh's matching status of a publisher on each key): on a loaded machine a
        viewer's subscription can take seconds to reach a session that has just joined, and what is
        published before then reaches no one. True when one does."""
        probes = [self.session.declare_publisher(key_of(self.keys, topic)) for topic in topics]
        try:
            deadline = time.monotonic() + timeout
            while not any(probe.matching_status.matching for probe in probes):
                if self.stopping or time.monotonic() >= deadline:
                    return False
                time.sleep(LISTENER_POLL)
            return True
        finally:
            for probe in probes:
                probe.undeclare()

    def replay(self, records: Iterable[Recorded], pacer: Pacer, out: TextIO = sys.stderr) -> int:
        last_note = time.monotonic()
        for record in records:
            if self.stopping:
                return 130
            pacer.wait(record.time, lambda: self.stopping)
            self.put(record)
            if time.monotonic() - last_note > PROGRESS_EVERY:
                last_note = time.monotonic()
                print(f"replay: t = {record.time:.1f} s, {self.published} messages published", file=out, flush=True)
        return 0


def replay_main(args: argparse.Namespace) -> int:
    path = Path(args.file)
    if args.rate is not None and args.rate <= 0:
        log.error("--rate must be positive, got %g", args.rate)
        return 2
    try:
        recorded = metadata(path)
    except RecordingError as exc:
        log.error("%s", exc)
        return 2
    namespace = args.namespace or recorded.get("namespace")
    if not namespace:
        log.error("%s names no namespace (not recorded by arroch record?): give --namespace", path)
        return 2
    rate = None if args.fast else (args.rate or 1.0)
    pacer = Pacer(rate, args.step_size if args.step else None)
    try:
        # A replay into a router of its own would reach no one: say what to start instead.
        options, _ = through_local_router(zenoh_options(args), become=False)
    except NoRouter as exc:
        log.error("%s", exc)
        return 1
    replayer = Replayer(
        namespace, options, hold_camera=args.hold_timeout if args.hold_camera else None, settle=args.settle
    )
    replayer.install_signal_handlers()
    try:
        replayer.open()
    except Exception as exc:
        log.error("could not join Zenoh: %s", exc)
        return 1
    try:
        topics = [t for t in message_topics(path) if selected(t, args.only or [], args.skip or [])]
        if args.wait_for_listener > 0 and not replayer.await_listener(topics, args.wait_for_listener):
            log.warning("nothing subscribed to a replayed key in %g s: replaying anyway", args.wait_for_listener)
        time.sleep(args.delay)  # subscribers discover the new publisher first
        code = replayer.replay(_passes(path, args), pacer)
        replayer.drain(DRAIN_TIMEOUT)  # the last messages leave before the session closes
    except RecordingError as exc:
        log.error("%s", exc)
        code = 2
    except EOFError:
        code = 0  # stepping, and the input ended
    finally:
        replayer.close()
    held = f", {replayer.holds_timed_out} camera hold(s) timed out" if args.hold_camera else ""
    print(
        f"replay: {replayer.published} messages published on namespace {namespace}{held}", file=sys.stderr, flush=True
    )
    return leave_if_close_overran(replayer, code)


def _passes(path: Path, args: argparse.Namespace) -> Iterator[Recorded]:
    """The selected records once, or with ``--loop`` pass after pass (re-timed) until the replay stops."""
    first = last = None  # site times of the first pass's first and last record (they come in time order)
    k = 0
    while True:
        offset = 0.0 if first is None or last is None else k * (last - first + LOOP_GAP)
        for record in messages(path, start=args.start, end=args.end):
            if not selected(record.topic, args.only or [], args.skip or []):
                continue
            if k == 0:
                first = record.time if first is None else first
                last = record.time
            yield record if k == 0 else retimed(record, offset, f"~{k}")
        if not args.loop or first is None:
            return
        k += 1


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    add_common_arguments(parser)
    parser.add_argument("file", metavar="FILE", help="a recording (.mcap) of arroch record")
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, metavar="K", help="K times the recorded pace (default 1)")
    pace.add_argument("--fast", action="store_true", help="publish without waiting")
    pace.add_argument("--step", action="store_true", help="wait for Enter before each --step-size site seconds")
    parser.add_argument(
        "--step-size", type=float, default=1.0, metavar="S", help="with --step: site seconds per Enter (default 1)"
    )
    parser.add_argument(
        "--only", action="append", metavar="PATTERN", help="replay only keys matching (e.g. 'robot/*/pose'; repeatable)"
    )
    parser.add_argument("--skip", action="append", metavar="PATTERN", help="do not replay keys matching (repeatable)")
    parser.add_argument(
        "--loop", action="store_true", help="play it again and again (later passes re-timed) until Ctrl-C"
    )
    parser.add_argument("--start", type=float, metavar="T", help="from site time T")
    parser.add_argument("--end", type=float, metavar="T", help="up to site time T")
    parser.add_argument(
        "--hold-camera", action="store_true", help="after each camera frame, wait for its overlay (ar/<cid>/overlay)"
    )
    parser.add_argument(
        "--hold-timeout", type=float, default=3.0, metavar="S", help="longest wait for an overlay (default 3 s)"
    )
    parser.add_argument(
        "--settle",
        type=float,
        default=0.05,
        metavar="S",
        help="with --hold-camera: wall seconds before each frame (default 0.05)",
    )
    parser.add_argument(
        "--wait-for-listener",
        type=float,
        default=10.0,
        metavar="S",
        help="wait up to S wall s for a subscriber of a replayed key before the first message (default 10; 0: none)",
    )
    parser.add_argument(
        "--delay",
        type=float,
        default=0.5,
        metavar="S",
        help="wall seconds between joining Zenoh and the first message (default 0.5)",
    )
