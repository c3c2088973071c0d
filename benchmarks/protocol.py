"""Protocol-layer figures: codec cost, and pose round-trip latency against raw zenoh-python.

Prints one JSON object on stdout (progress goes to stderr):

- ``codec``: encode, decode and encode+decode µs for a RobotPose and for an Intent with a
  200-point trajectory (median of many timed loops);
- ``latency``: RobotPose round trips between this process and echo processes over loopback TCP:
  - ``protocol``: ``arroch ping serve`` (a Service relaying inline, on Zenoh's thread: each pose is
    validated, then the bytes received go back out), timed by :class:`runtime.ping.PingSender`
    (encode → Zenoh → validate → Zenoh → decode and validate, then the hand-off to the waiting
    thread; the pose is stamped before the clock starts, as the raw side's bytes are made before);
  - ``protocol_worker``: the same through the Service's worker thread (``ping serve --worker``,
    which decodes, queues, and re-encodes on the worker);
  - ``raw``: a plain zenoh-python echo of the very same payload bytes, no codec and no Service;
  - ``protocol_sender`` and ``protocol_echo``: where the protocol's extra time goes, each end alone.
    ``protocol_sender`` is the PingSender against the raw echo (the pinger's encoding, decoding and
    hand-off); ``protocol_echo`` is the raw pinger against ``arroch ping serve`` (the relay's check).
  Like is compared with like: the raw side uses the Service's publisher options
  (:func:`runtime.service.publisher_options`), its session options (the same command-line and
  environment path, shared memory off in every process; the raw and protocol pingers even share
  one session), and its subscriber mode (callbacks on Zenoh's own thread,
  :func:`runtime.transport.on_zenoh_thread`).

  The figures come from ``--runs`` runs, each with freshly started echo processes (a process's
  luck with the machine, worth ±10-15 % here, does not carry over), and within a run from small
  batches of each variant in random order, so that load changes hit every variant alike. Reported:
  the p50/p99 of all round trips of each variant and their ratios; ``*_paired``, the median over all
  rounds of the ratio of two variants' batch medians in that round (the same few milliseconds of
  machine state); ``per_run``, each run's figures; and ``*_runs_median``, the median over runs of
  each run's paired ratio, which is what the floor is checked on.
- ``floors``: protocol p50 ≤ 1.1 × raw p50 (``protocol_over_raw_p50_runs_median``), RobotPose
  encode+decode ≤ 20 µs.

Transport: peer to peer by default (this process listens on a free port, the echoes connect), or
through ``arroch router`` with ``--router``. Shared memory is off in every process, so the
figures are those of the TCP path (a pose is far below the size where Zenoh would use it anyway).

``python benchmarks/protocol.py [--pings N] [--runs R] [--batch B] [--router] [--check]``
(``--check``: exit 1 when a floor is missed). ``--raw-echo`` is the raw echo process itself.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import queue
import random
import signal
import statistics
import subprocess
import sys
import threading
import time
import timeit
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a plain script from a checkout

import zenoh  # noqa: E402

from protocol.codec import decode, encode  # noqa: E402
from protocol.keys import Keys  # noqa: E402
from protocol.messages import Intent, RobotPose  # noqa: E402
from runtime.ping import PingSender, summarize  # noqa: E402
from runtime.service import publisher_options  # noqa: E402
from runtime.signals import StopSignals  # noqa: E402
from runtime.transport import ZenohOptions, build_config, free_tcp_port, on_zenoh_thread, options_from  # noqa: E402

FLOOR_RATIO = 1.1
FLOOR_POSE_CODEC_US = 20.0
VARIANTS = ("protocol", "protocol_worker", "raw", "protocol_sender", "protocol_echo")
AGAINST_RAW = ("protocol", "protocol_worker", "protocol_sender", "protocol_echo")


def progress(text: str) -> None:
    print(f"[protocol bench] {text}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------- codec


def _per_call_us(fn: Callable[[], object], number: int, repeat: int) -> float:
    """Median over ``repeat`` loops of ``number`` calls, in µs per call."""
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def sample_pose() -> RobotPose:
    return RobotPose(
        robot="r0", x=3.25, y=5.5, theta=1.2, vel=0.5, omega=-0.1, src="sim-4242", seq=123456, stamp=1712.25
    )


def sample_intent(points: int = 200) -> Intent:
    trajectory = [[100.0 + 0.1 * i, 1.0 + 0.05 * i, 5.0 - 0.02 * i, 0.001 * i] for i in range(points)]
    return Intent(
        robot="r0",
        plan_id=17,
        action_id=42,
        action="approach",
        args=["d_storage"],
        trajectory=trajectory,
        src="planner-4242",
        seq=99,
        stamp=100.0,
    )


def bench_codec(quick: bool) -> dict:
    out = {}
    for name, msg, number in (("RobotPose", sample_pose(), 2000), ("Intent200", sample_intent(), 100)):
        cls = type(msg)
        payload = encode(msg)
        assert decode(payload, cls) == msg
        repeat = 7 if quick else 31
        # Default arguments bind this round's message (a closure would see the loop's later values).
        enc = _per_call_us(lambda msg=msg: encode(msg), number, repeat)
        dec = _per_call_us(lambda payload=payload, cls=cls: decode(payload, cls), number, repeat)
        both = _per_call_us(lambda msg=msg, cls=cls: decode(encode(msg), cls), number, repeat)
        out[name] = {
            "bytes": len(payload),
            "encode_us": round(enc, 2),
            "decode_us": round(dec, 2),
            "encode_decode_us": round(both, 2),
        }
        progress(f"codec {name}: {len(payload)} B, encode {enc:.1f} µs, decode {dec:.1f} µs, both {both:.1f} µs")
    return out


# ---------------------------------------------------------------------------- raw zenoh


def raw_echo(args: argparse.Namespace) -> int:
    """The raw echo process: every payload on robot/*/pose goes back as it is on ping/reply."""

    keys = Keys(args.namespace)
    # The session options come the way `arroch ping serve` gets them (options and environment).
    opts = options_from(args)
    signals = StopSignals()
    signals.install()
    with zenoh.open(build_config(opts)) as session:
        pub = session.declare_publisher(keys.ping_reply(), **publisher_options())
        sub = session.declare_subscriber(keys.robot_pose("*"), on_zenoh_thread(lambda sample: pub.put(sample.payload)))
        print("raw echo ready", flush=True)
        signals.wait()
        sub.undeclare()
        pub.undeclare()
    return 0


class RawPinger:
    """PingSender's twin in raw zenoh-python: same session, same payload bytes, no codec.

    Payloads are made before timing starts (a raw user has bytes already); echoes are
    time-stamped in the callback and handed over through a queue, exactly as PingSender does."""

    def __init__(self, session: zenoh.Session, namespace: str, payload_of: Callable[[int], bytes]) -> None:
        keys = Keys(namespace)
        self._payload_of = payload_of
        self._echoes: queue.SimpleQueue[tuple[bytes, int]] = queue.SimpleQueue()
        self._pub = session.declare_publisher(keys.robot_pose("ping"), **publisher_options())
        self._sub = session.declare_subscriber(keys.ping_reply(), on_zenoh_thread(self._on_echo))
        self._n = 0

    def _on_echo(self, sample: zenoh.Sample) -> None:
        self._echoes.put((sample.payload.to_bytes(), time.perf_counter_ns()))

    def ping_once(self, timeout: float = 1.0) -> float | None:
        self._n += 1
        payload = self._payload_of(self._n)
        sent_at = time.perf_counter_ns()
        self._pub.put(payload)
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                echo, received_at = self._echoes.get(timeout=remaining)
            except queue.Empty:
                return None
            if echo == payload:
                return (received_at - sent_at) / 1000.0
        return None

    def run_pings(self, count: int) -> list[float]:
        return [rtt for rtt in (self.ping_once() for _ in range(count)) if rtt is not None]

    def wait_for_server(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.ping_once(0.1) is not None:
                return True
        return False

    def close(self) -> None:
        self._sub.undeclare()
        self._pub.undeclare()


# ---------------------------------------------------------------------------- latency


class Children:
    """Processes started with subprocess (never fork: Zenoh is open here), all stopped at exit."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def start(self, *commands: tuple[list[str], str], timeout: float = 30.0) -> None:
        """Start every ``(argv, ready line)`` at once, then wait until each has printed its line."""
        env = dict(os.environ, ARROCH_ZENOH_SHM="0", ARROCH_LOG_LEVEL="WARNING", PYTHONUNBUFFERED="1")
        started = [
            (
                argv,
                ready,
                subprocess.Popen(
                    argv,
                    cwd=ROOT,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    text=True,
                    start_new_session=True,
                ),
            )
            for argv, ready in commands
        ]
        self.procs.extend(proc for _, _, proc in started)
        deadline = time.monotonic() + timeout
        for argv, ready, proc in started:
            assert proc.stdout is not None
            while True:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{argv} not ready within {timeout} s")
                line = proc.stdout.readline()
                if not line:
                    raise RuntimeError(f"{argv} exited ({proc.wait()}) before it was ready")
                if ready in line:
                    break
            # Keep draining its output so a chatty child never blocks on a full pipe.
            threading.Thread(target=proc.stdout.read, daemon=True).start()

    def stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)
        self.procs.clear()


@dataclass
class Run:
    """One run's round trips (µs) and, per variant, the median of each of its batches."""

    samples: dict[str, list[float]] = field(default_factory=lambda: {name: [] for name in VARIANTS})
    batch_p50: dict[str, list[float]] = field(default_factory=lambda: {name: [] for name in VARIANTS})

    def paired(self, name: str) -> list[float]:
        """Per round: this variant's batch median over raw's batch median in the same round."""
        return [a / b for a, b in zip(self.batch_p50[name], self.batch_p50["raw"], strict=True) if b > 0]


def _peer_pair(endpoint: str) -> tuple[ZenohOptions, list[str]]:
    """This process's options listening on ``endpoint``, and the echo's options connecting to it."""
    return ZenohOptions(mode="peer", listen=[endpoint], shared_memory=False), ["--mode", "peer", "--connect", endpoint]


def one_run(args: argparse.Namespace, index: int, rounds: int) -> tuple[Run, dict]:
    """Fresh echo processes, then ``rounds`` rounds of one batch per variant in random order."""
    arroch = [sys.executable, "-m", "services.cli"]
    children = Children()
    run_id = uuid.uuid4().hex[:6]
    # Namespaces of equal length, so the three variants' keys are the same size on the wire.
    ns = {
        "protocol": f"bp{run_id}",
        "protocol_worker": f"bw{run_id}",
        "raw": f"br{run_id}",
        "protocol_sender": f"bs{run_id}",
        "protocol_echo": f"be{run_id}",
    }
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    pingers: list = []
    try:
        if args.router:
            children.start(([*arroch, "router", "--listen", endpoint], "router ready"))
            mine = worker_mine = lone_mine = ZenohOptions(mode="client", connect=[endpoint], shared_memory=False)
            theirs = worker_theirs = lone_theirs = ["--mode", "client", "--connect", endpoint]
            transport = "client → arroch router → client, TCP loopback"
        else:
            # The protocol, raw and protocol_echo pingers share this process's listening session (so
            # they take the same links); the two other PingSenders each have their own, so no variant
            # is routed through another.
            mine, theirs = _peer_pair(endpoint)
            worker_mine, worker_theirs = _peer_pair(f"tcp/127.0.0.1:{free_tcp_port()}")
            lone_mine, lone_theirs = _peer_pair(f"tcp/127.0.0.1:{free_tcp_port()}")
            transport = "peer ↔ peer, TCP loopback"

        sender = PingSender(ns["protocol"], mine).open()
        pingers.append(sender)
        worker_sender = PingSender(ns["protocol_worker"], worker_mine).open()
        pingers.append(worker_sender)
        lone_sender = PingSender(ns["protocol_sender"], lone_mine).open()
        pingers.append(lone_sender)

        def raw_payload(n: int) -> bytes:
            # What PingSender puts on the wire for its n-th ping: the same bytes, made beforehand.
            msg = sender.make_pose(n)
            msg.src, msg.seq, msg.stamp = sender.src, n, sender.clock.now()
            return encode(msg)

        raw = RawPinger(sender.session, ns["raw"], raw_payload)
        raw_to_protocol = RawPinger(sender.session, ns["protocol_echo"], raw_payload)
        pingers[:0] = [raw, raw_to_protocol]  # closed before the session they use
        serve = [*arroch, "ping", "serve", "--namespace"]
        raw_echo = [sys.executable, __file__, "--raw-echo", "--namespace"]
        children.start(
            ([*serve, ns["protocol"], *theirs], "ping serve ready"),
            (
                [*arroch, "ping", "serve", "--worker", "--namespace", ns["protocol_worker"], *worker_theirs],
                "ping serve ready",
            ),
            ([*raw_echo, ns["raw"], *theirs], "raw echo ready"),
            ([*raw_echo, ns["protocol_sender"], *lone_theirs], "raw echo ready"),
            ([*serve, ns["protocol_echo"], *theirs], "ping serve ready"),
        )
        pinger_of = {
            "protocol": sender,
            "protocol_worker": worker_sender,
            "raw": raw,
            "protocol_sender": lone_sender,
            "protocol_echo": raw_to_protocol,
        }
        for name, pinger in pinger_of.items():
            if not pinger.wait_for_server(15):
                raise RuntimeError(f"the {name} echo never answered")

        batches: dict[str, Callable[[int], list[float]]] = {
            name: (pinger.run_pings if isinstance(pinger, RawPinger) else partial(pinger.run_pings, rate=0, warmup=0))
            for name, pinger in pinger_of.items()
        }
        for run_batch in batches.values():  # warm-up, uncounted
            run_batch(args.warmup)
        run = Run()
        rng = random.Random(index)
        for _ in range(rounds):
            order = list(VARIANTS)
            rng.shuffle(order)
            for name in order:
                batch = batches[name](args.batch)
                run.samples[name].extend(batch)
                run.batch_p50[name].append(statistics.median(batch) if batch else float("nan"))
        # Like for like on the wire: the same payload size (at a typical seq) and key lengths.
        info = {
            "transport": transport,
            "payload_bytes": len(sender.typical_payload()),
            "raw_payload_bytes": len(raw_payload(1000)),
        }
        return run, info
    finally:
        for pinger in pingers:
            pinger.close()
        children.stop()


def bench_latency(args: argparse.Namespace) -> dict:
    rounds = max(1, args.pings // (args.batch * args.runs))
    runs: list[Run] = []
    info: dict = {}
    progress(
        f"{args.runs} runs of {rounds} rounds of {args.batch} pings per variant, variants in random order each round"
    )
    started = time.monotonic()
    for index in range(args.runs):
        run, info = one_run(args, index, rounds)
        runs.append(run)
        figures = ", ".join(f"{name} {statistics.median(run.samples[name]):.0f}" for name in VARIANTS)
        progress(
            f"  run {index + 1}/{args.runs}: p50 µs {figures}; protocol/raw paired "
            f"{statistics.median(run.paired('protocol')):.3f} ({time.monotonic() - started:.1f} s)"
        )

    sent = rounds * args.batch * args.runs
    result: dict = {
        "transport": info["transport"],
        "endpoint_kind": "router" if args.router else "peer",
        "shared_memory": False,
        "payload_bytes": info["payload_bytes"],
        "raw_payload_bytes": info["raw_payload_bytes"],
        "pings_per_variant": sent,
        "batch": args.batch,
        "runs": args.runs,
        "rounds_per_run": rounds,
    }
    for name in VARIANTS:
        s = summarize([x for run in runs for x in run.samples[name]], sent)
        result[name] = {k: round(v, 1) if isinstance(v, float) else v for k, v in s.to_dict().items()}
        progress(f"{name:16s} p50 {s.p50_us:6.0f} µs  p99 {s.p99_us:6.0f} µs  ({s.received}/{sent})")
    per_run: list[dict] = [
        {f"{name}_p50_us": round(statistics.median(run.samples[name]), 1) for name in VARIANTS} for run in runs
    ]
    for name in AGAINST_RAW:
        for q in ("p50", "p99"):
            result[f"{name}_over_raw_{q}"] = round(result[name][f"{q}_us"] / result["raw"][f"{q}_us"], 3)
        result[f"{name}_over_raw_p50_paired"] = round(
            statistics.median([r for run in runs for r in run.paired(name)]), 3
        )
        for figures, run in zip(per_run, runs, strict=True):
            figures[f"{name}_over_raw_p50_paired"] = round(statistics.median(run.paired(name)), 3)
        result[f"{name}_over_raw_p50_runs_median"] = round(
            statistics.median(f[f"{name}_over_raw_p50_paired"] for f in per_run), 3
        )
    result["per_run"] = per_run
    return result


# ---------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--pings", type=int, default=6000, help="timed round trips per variant, all runs together (default 6000)"
    )
    parser.add_argument(
        "--runs", type=int, default=None, help="runs, each with fresh echo processes (default 5; 2 with --quick)"
    )
    parser.add_argument("--batch", type=int, default=20, help="pings per variant per round (default 20)")
    parser.add_argument(
        "--warmup",
        type=int,
        default=None,
        help="uncounted pings per variant at the start of a run (default 200; 50 with --quick)",
    )
    parser.add_argument(
        "--router", action="store_true", help="go through `arroch router` (client mode) instead of peer to peer"
    )
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (for tests)")
    parser.add_argument("--check", action="store_true", help="exit 1 if a floor is missed")
    parser.add_argument("--raw-echo", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--namespace", help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="peer", help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.raw_echo:
        return raw_echo(args)
    if args.runs is None:
        args.runs = 2 if args.quick else 5
    if args.warmup is None:
        args.warmup = 50 if args.quick else 200
    for name in ("pings", "runs", "batch"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1")
    os.environ.setdefault("RUST_LOG", "error")
    # SIGTERM (a `timeout`, say) unwinds like an exception, so each run's echo processes are stopped.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))

    started = time.monotonic()
    load_before = os.getloadavg()
    codec = bench_codec(args.quick)
    latency = bench_latency(args)
    pose_codec = codec["RobotPose"]["encode_decode_us"]
    # Checked on the median over runs of each run's paired ratio: neither one unlucky echo process
    # nor a burst of load elsewhere on the machine decides it. The pooled ratio is given beside it.
    ratio = latency["protocol_over_raw_p50_runs_median"]
    floors = {
        "protocol_over_raw_p50_max": FLOOR_RATIO,
        "protocol_over_raw_p50": ratio,
        "protocol_over_raw_p50_basis": (
            "median over runs of the per-round paired p50 ratio (latency.protocol_over_raw_p50_runs_median)"
        ),
        "protocol_over_raw_p50_pooled": latency["protocol_over_raw_p50"],
        "ratio_met": ratio <= FLOOR_RATIO,
        "pose_encode_decode_us_max": FLOOR_POSE_CODEC_US,
        "pose_encode_decode_us": pose_codec,
        "codec_met": pose_codec <= FLOOR_POSE_CODEC_US,
    }
    floors["met"] = floors["ratio_met"] and floors["codec_met"]
    report = {
        "benchmark": "protocol",
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "zenoh": metadata.version("eclipse-zenoh"),
            "msgspec": metadata.version("msgspec"),
            "load_average_before": [round(x, 2) for x in load_before],
            "load_average_after": [round(x, 2) for x in os.getloadavg()],
        },
        "codec": codec,
        "latency": latency,
        "floors": floors,
        "seconds": round(time.monotonic() - started, 1),
    }
    print(json.dumps(report, indent=2))
    progress(f"done in {report['seconds']} s; floors {'met' if floors['met'] else 'MISSED'}")
    return 1 if args.check and not floors["met"] else 0


if __name__ == "__main__":
    sys.exit(main())
