"""``arroch ping``: RobotPose round trips through the protocol layer, to check a link and time it.

``arroch ping serve`` is a :class:`~runtime.service.Service` that hears every ``robot/*/pose``
(RobotPose), validates it and republishes it unchanged (envelope included) on ``ping/reply``.

``arroch ping send`` publishes RobotPoses on ``robot/<robot>/pose`` one at a time and times each
until its echo comes back: encode → Zenoh → decode (validation) in the server, which relays the
bytes it got → Zenoh → decode.
It waits for a server first (up to ``--wait`` seconds), sends a few uncounted warm-up pings, then
prints p50/p90/p99 round-trip times (``--json``: one JSON object on stdout).

The server echoes every pose it hears, including a simulator's, so a sender recognises its own
echoes by the envelope's ``src`` and ``seq``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import queue
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

from protocol.codec import encode
from protocol.messages import RobotPose

from .clock import make_clock
from .runner import add_common_arguments, namespace_from, run_service
from .service import Service
from .transport import ZenohOptions, options_from

log = logging.getLogger("arroch.ping")

PAD_FIELD = "pad"  # unknown to RobotPose: receivers ignore it, so it only adds bytes on the wire


class PingServer(Service):
    """Echoes every valid RobotPose heard on ``robot/*/pose`` onto ``ping/reply``, unchanged.

    ``inline=True`` (the default) relays on Zenoh's receive thread (:meth:`Service.relay`): each
    payload is validated and the bytes received go back out, so the echo is the sender's own
    message, padding included. ``inline=False`` goes through the worker like an ordinary handler,
    which decodes and re-encodes (fields unknown to RobotPose, such as padding, are dropped); kept
    to measure that path: ``ping serve --worker``.
    """

    def __init__(self, namespace: str, zenoh_options: ZenohOptions, *, inline: bool = True, **kwargs) -> None:
        super().__init__("ping", namespace, zenoh_options, **kwargs)
        self.inline = inline

    def setup(self) -> None:
        self.reply_key = self.keys.ping_reply()
        if self.inline:
            self.relay(self.keys.robot_pose("*"), RobotPose, self.reply_key)
        else:
            self.advertise(self.reply_key)  # declared up front, so listeners match before the first echo
            # sample_key=False: the echo goes to ping/reply whatever robot's key the pose came on.
            self.subscribe(self.keys.robot_pose("*"), RobotPose, self._echo, sample_key=False)
        print(f"ping serve ready: {self.keys.robot_pose('*')} -> {self.keys.ping_reply()}", flush=True)

    def _echo(self, msg: RobotPose, key: str) -> None:
        # stamp=False keeps src/seq/stamp: the echo is the sender's own message, so it can match it.
        self.publish(self.reply_key, msg, stamp=False)

    def teardown(self) -> None:
        log.info("echoed %d poses (%d bad payloads)", self.counters["published"], self.counters["bad_messages"])


@dataclass
class LatencySummary:
    """Round-trip statistics in microseconds."""

    sent: int
    received: int
    lost: int
    p50_us: float
    p90_us: float
    p99_us: float
    min_us: float
    max_us: float
    mean_us: float
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Flat and JSON-safe: figures that do not exist (no echo at all) are None, not NaN."""
        out = asdict(self)
        out.update(out.pop("extra"))
        return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in out.items()}


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """The ``q``-quantile (0..1) of already sorted values, by linear interpolation; NaN if empty."""
    if not sorted_values:
        return math.nan
    pos = q * (len(sorted_values) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


def summarize(samples_us: Sequence[float], sent: int) -> LatencySummary:
    values = sorted(samples_us)
    return LatencySummary(
        sent=sent,
        received=len(values),
        lost=sent - len(values),
        p50_us=percentile(values, 0.50),
        p90_us=percentile(values, 0.90),
        p99_us=percentile(values, 0.99),
        min_us=values[0] if values else math.nan,
        max_us=values[-1] if values else math.nan,
        mean_us=sum(values) / len(values) if values else math.nan,
    )


class PingSender(Service):
    """Sends RobotPoses and times their echoes. Drive it from the thread that opened it.

    Echoes are decoded inline (on Zenoh's thread), time-stamped there and handed over through a
    queue, so the figure is the protocol layer's round trip and not this thread's wake-up time.
    """

    def __init__(self, namespace: str, zenoh_options: ZenohOptions, *, robot: str = "ping", **kwargs) -> None:
        super().__init__("pingsend", namespace, zenoh_options, **kwargs)
        self.robot = robot
        self.pose_key = self.keys.robot_pose(robot)
        self.sent = 0  # timed pings sent by the last run_pings()
        self._echoes: queue.SimpleQueue[tuple[int, int]] = queue.SimpleQueue()

    def setup(self) -> None:
        # Stamped by ping_once, before the clock starts: the raw baseline has its bytes ready too.
        self._send = self.sender(self.pose_key, RobotPose, stamp=False)
        self.subscribe(self.keys.ping_reply(), RobotPose, self._on_echo, inline=True)

    def _on_echo(self, msg: RobotPose, key: str) -> None:
        if msg.src == self.src:  # the server echoes everyone's poses; keep ours
            self._echoes.put((msg.seq, time.perf_counter_ns()))

    def make_pose(self, n: int) -> RobotPose:
        """The n-th ping's pose (not yet stamped)."""
        # Vary the content a little so nothing along the way could serve a cached answer.
        return RobotPose(robot=self.robot, x=1.0 + n % 100 * 0.01, y=2.0, theta=0.5, vel=0.25, omega=0.0)

    def ping_once(self, n: int, timeout: float, pad: bytes | None = None) -> float | None:
        """One round trip; its time in µs, or None if no echo came within ``timeout`` seconds."""
        msg = self.stamp(self.make_pose(n))
        sent_at = time.perf_counter_ns()
        if pad:
            self.publish(self.pose_key, msg, stamp=False, extra={PAD_FIELD: pad})
        else:
            self._send(msg)
        # Until the echo is in, this thread only waits: each slice is a blocking get, so that the
        # echo, on another thread, never waits for this one (the stop request is seen between slices).
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                seq, received_at = self._echoes.get(timeout=min(remaining, 0.1))
            except queue.Empty:
                if self.stopping:
                    return None
                continue
            if seq == msg.seq:
                return (received_at - sent_at) / 1000.0
            # An echo of an earlier ping that had timed out: skip it.
        return None

    def wait_for_server(self, timeout: float) -> bool:
        """Ping every 0.1 s until an echo comes back (the server may still be starting)."""
        deadline = time.monotonic() + timeout
        n = 0
        while not self.stopping and time.monotonic() < deadline:
            if self.ping_once(n, min(0.1, max(deadline - time.monotonic(), 0.001))) is not None:
                return True
            n += 1
        return False

    def typical_payload(self, pad: bytes | None = None) -> bytes:
        """What a ping looks like on the wire (its size varies by a byte or two with ``seq``)."""
        msg = self.make_pose(0)
        msg.src, msg.seq, msg.stamp = self.src, 1000, self.clock.now()
        return encode(msg, {PAD_FIELD: pad} if pad is not None else None)

    def padding_for(self, payload_bytes: int) -> bytes | None:
        """Padding that brings an encoded ping to about ``payload_bytes`` (None when already that large)."""
        base = len(self.typical_payload(b""))
        if payload_bytes <= base:
            return None
        # A bin header is 2 bytes up to 255, 3 up to 65535, 5 above; trim until the total fits.
        pad = payload_bytes - base
        while pad > 0 and len(self.typical_payload(b"\0" * pad)) > payload_bytes:
            pad -= 1
        return b"\0" * pad

    def run_pings(
        self, count: int, rate: float, *, timeout: float = 1.0, warmup: int = 10, pad: bytes | None = None
    ) -> list[float]:
        """``count`` timed round trips at most ``rate`` per second (0: back to back); their µs."""
        for n in range(warmup):
            if self.stopping:
                break
            self.ping_once(n, timeout, pad)
        period = 1.0 / rate if rate > 0 else 0.0
        samples: list[float] = []
        self.sent = 0
        next_at = time.monotonic()
        for n in range(count):
            if self.stopping:
                break
            self.sent += 1
            rtt = self.ping_once(n, timeout, pad)
            if rtt is not None:
                samples.append(rtt)
            if period:
                next_at += period
                delay = next_at - time.monotonic()
                if delay > 0:
                    self._stop.wait(delay)
                else:
                    next_at = time.monotonic()  # fell behind: no burst to catch up
        return samples


def _zenoh_and_namespace(args: argparse.Namespace) -> tuple[ZenohOptions, str]:
    return options_from(args), namespace_from(args)


def run_serve(args: argparse.Namespace) -> int:
    def build() -> PingServer:
        opts, namespace = _zenoh_and_namespace(args)
        return PingServer(namespace, opts, inline=not args.worker, clock=make_clock(args.clock))

    return run_service(build)


def run_send(args: argparse.Namespace) -> int:
    try:
        opts, namespace = _zenoh_and_namespace(args)
        sender = PingSender(namespace, opts, robot=args.robot, clock=make_clock(args.clock))
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    sender.install_signal_handlers()
    try:
        sender.open()
    except Exception as exc:
        log.error("could not start: %s", exc)
        sender.close()
        return 1
    try:
        if not sender.wait_for_server(args.wait):
            if sender.stopping:
                return 0
            log.error(
                "no ping server answered on %s within %.0f s (is `arroch ping serve` running in namespace %s?)",
                sender.keys.ping_reply(),
                args.wait,
                sender.keys.site,
            )
            return 1
        pad = sender.padding_for(args.payload_bytes) if args.payload_bytes else None
        payload_len = len(sender.typical_payload(pad))
        samples = sender.run_pings(args.count, args.rate, timeout=args.timeout, warmup=args.warmup, pad=pad)
        summary = summarize(samples, sender.sent)
        summary.extra = {
            "payload_bytes": payload_len,
            "rate_hz": args.rate,
            "namespace": sender.keys.site,
            "interrupted": sender.stopping,
        }
    finally:
        sender.close()
    if args.json:
        print(json.dumps(summary.to_dict()))
    else:
        print(
            f"ping {summary.extra['namespace']}: {summary.received}/{summary.sent} echoes of a {payload_len}-byte "
            "RobotPose; "
            f"round trip p50 {summary.p50_us:.0f} µs, p90 {summary.p90_us:.0f} µs, p99 {summary.p99_us:.0f} µs "
            f"(min {summary.min_us:.0f}, max {summary.max_us:.0f})"
        )
    sys.stdout.flush()
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "ping",
        help="RobotPose round trips through the protocol layer (serve | send)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="ping_command", metavar="ACTION", required=True)

    serve = actions.add_parser("serve", help="echo every robot/*/pose onto ping/reply until SIGINT/SIGTERM")
    add_common_arguments(serve)
    serve.add_argument(
        "--worker",
        action="store_true",
        help="echo on the service's worker thread instead of inline on Zenoh's thread (slower; for measuring)",
    )
    serve.set_defaults(func=run_serve)

    send = actions.add_parser("send", help="send RobotPoses, time their echoes, print p50/p90/p99")
    add_common_arguments(send)
    send.add_argument("--count", type=_positive_int, default=100, help="timed pings (default 100)")
    send.add_argument(
        "--rate", type=float, default=100.0, help="pings per second at most; 0 = back to back (default 100)"
    )
    send.add_argument(
        "--payload-bytes",
        type=int,
        default=0,
        metavar="N",
        help="pad each ping with a field receivers ignore, to N bytes on the wire (an inline server's echoes come back "
        "padded too)",
    )
    send.add_argument("--robot", default="ping", help="robot id in the pose key robot/<id>/pose (default ping)")
    send.add_argument("--timeout", type=float, default=1.0, help="seconds before a ping counts as lost (default 1)")
    send.add_argument("--warmup", type=int, default=10, help="uncounted pings first (default 10)")
    send.add_argument("--wait", type=float, default=10.0, help="seconds to wait for a server to answer (default 10)")
    send.add_argument("--json", action="store_true", help="print one JSON object instead of a line")
    send.set_defaults(func=run_send)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive integer")
    return value
