"""Load: 50 robots publishing their poses at 20 Hz and a 30 frames/s camera stream into the AR client,
all on one machine. How old are the positions the overlay shows, what is dropped where, and do the
queues stay bounded?

Usage::

    .venv/bin/python benchmarks/load.py [--seconds 20] [--warmup 3] [--robots 50] [--pose-rate 20] [--fps 30]

Processes (each a real one, over a Zenoh router on localhost): ``arroch router``; ``arroch ar`` (wall
clock, source ``sim``: it subscribes to ``camera/tablet/frame``); a pose generator (this script,
``--role poses``) moving ``--robots`` robots (``l0``, ``l1``, ... on circles in the storage room, in
the tablet's view) and publishing each one's RobotPose at ``--pose-rate``; a camera feed (``--role
camera``) publishing the simulator's snapshots of the storage room's tagged wall (a slow pan, as the
tablet tests use) as CameraFrames at ``--fps``; and this process, which reads every Overlay and asks
the AR client for its counters four times a second.

Figures (measured after ``--warmup``, for ``--seconds``):

* ``pose_to_overlay_ms``: for every robot in every overlay, the overlay's arrival minus the stamp of
  the RobotPose it was drawn from (the AR client says which: ``pose_stamps``) — the age of what the
  human sees, publication, queueing, the frame's processing and the overlay's delivery included;
  p50, p99, mean, max;
* ``frame_to_overlay_ms``: a frame's stamp to its overlay's arrival;
* ``stages``: per stage, what was sent and what became of it (totals over the whole run, read after
  the generators stopped and everything drained): poses generator → AR client (handled, superseded
  by a newer pose of the same robot before the worker got to it, lost), frames camera → AR client
  (processed, superseded, refused as bad, lost), overlays AR client → this process (lost);
* ``queues``: the AR client's inbox depth (now, and its high-water mark) and waiting latest-slots,
  sampled over the run: maxima per third of the run, so growth would show; the AR client's
  resident memory at the start and end of the measurement.

Prints one JSON document on stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib import figures  # noqa: E402
from benchmarks.lib.figures import log  # noqa: E402
from protocol.messages import CameraFrame, Event, RobotPose  # noqa: E402
from runtime.clock import WallClock  # noqa: E402
from runtime.service import Service  # noqa: E402
from runtime.transport import ZenohOptions, free_tcp_port  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402

CAMERA = "tablet"
LINGER = 0.5  # s a generator waits after its last put: a session closed at once may drop what is queued
# Robots stand in the storage room (x 6..11, y 0..4), in front of the tablet's view of its south wall.
AREA = (6.6, 0.6, 10.4, 2.6)
SAMPLE_PERIOD = 0.25  # s between two looks at the AR client's counters


def summary(values: list[float]) -> dict[str, float]:
    return figures.summary(values, percentiles=(50, 99), scale=1.0, digits=2)


def client(name: str, namespace: str, endpoint: str) -> Service:
    return Service(name, namespace, ZenohOptions(mode="client", connect=[endpoint]), clock=WallClock())


# --------------------------------------------------------------------------- the generators (own processes)


def run_poses(args: argparse.Namespace) -> int:
    """``--robots`` robots on small circles, each pose published at ``--pose-rate`` (stamped on the wall clock)."""
    service = client("loadposes", args.namespace, args.connect).open()
    service.install_signal_handlers()
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = AREA
    centres = np.column_stack([rng.uniform(x0, x1, args.robots), rng.uniform(y0, y1, args.robots)])
    phases = rng.uniform(0.0, 2.0 * math.pi, args.robots)
    keys = [service.keys.robot_pose(f"l{i}") for i in range(args.robots)]
    for key in keys:
        service.advertise(key)
    period = 1.0 / args.pose_rate
    started = next_due = time.monotonic()
    try:
        while not service.stopping:
            t = time.monotonic() - started
            for i, key in enumerate(keys):
                angle = 0.5 * t + phases[i]  # 0.2 m circles at 0.1 m/s
                x, y = centres[i] + 0.2 * np.array([math.cos(angle), math.sin(angle)])
                service.publish(
                    key, RobotPose(robot=f"l{i}", x=float(x), y=float(y), theta=angle + math.pi / 2, vel=0.1)
                )
            next_due += period
            time.sleep(max(0.0, next_due - time.monotonic()))
    finally:
        print(f"sent {service.counters['published']}", flush=True)  # the benchmark's count of this stage
        time.sleep(LINGER)
        service.close()
    return 0


def run_camera(args: argparse.Namespace) -> int:
    """The simulator's snapshots of the tablet's slow pan, as CameraFrames at ``--fps``, round and round."""
    from services.sim.camera import encode_jpeg
    from tests.tablet.helpers import snapshots

    shots = snapshots(6)
    jpegs = [encode_jpeg(frame) for frame in shots.frames]
    fx, fy, cx, cy, width, height = shots.cameras[0].intrinsics
    service = client("loadcamera", args.namespace, args.connect).open()
    service.install_signal_handlers()
    key = service.keys.camera_frame(CAMERA)
    service.advertise(key)
    period = 1.0 / args.fps
    next_due = time.monotonic()
    n = 0
    try:
        while not service.stopping:
            service.publish(
                key,
                CameraFrame(
                    camera=CAMERA,
                    jpeg=jpegs[n % len(jpegs)],
                    width=int(width),
                    height=int(height),
                    intrinsics=[fx, fy, cx, cy],
                ),
            )
            n += 1
            next_due += period
            time.sleep(max(0.0, next_due - time.monotonic()))
    finally:
        print(f"sent {service.counters['published']}", flush=True)
        time.sleep(LINGER)
        service.close()
    return 0


# --------------------------------------------------------------------------- the measurement


class Observer:
    """Every Overlay, as it arrives: its pose ages and frame age (raw msgpack: ``pose_stamps`` is an
    extra field the Overlay type does not declare)."""

    def __init__(self, service: Service) -> None:
        self.lock = threading.Lock()
        self.recording = False
        self.received = 0
        self.pose_ages: list[float] = []
        self.frame_ages: list[float] = []
        self.robots_per_overlay: list[int] = []
        service._declared.append(service.session.declare_subscriber(service.keys.overlay(CAMERA), self._on))

    def _on(self, sample) -> None:  # noqa: ANN001
        arrived = time.time()
        data = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        with self.lock:
            self.received += 1
            if not self.recording:
                return
            stamps = data.get("pose_stamps") or {}
            self.pose_ages += [(arrived - s) * 1000.0 for s in stamps.values()]
            self.robots_per_overlay.append(len(stamps))
            if data.get("stamp"):
                self.frame_ages.append((arrived - data["stamp"] + data.get("latency", 0.0)) * 1000.0)


def stats_of(service: Service, name: str) -> dict:
    replies = service.query(service.keys.stats(name, "*"), Event, timeout=2.0)
    return dict(replies[0].data) if replies else {}


def accounted(s: dict) -> dict[str, int]:
    """From the AR client's counters ``s``: what became of the frames (processed, superseded, refused
    as bad) and of the poses (handled, superseded) that reached it."""
    frames_processed, frames_bad = s.get("frames", 0), s.get("bad_frames", 0)
    return {
        "frames_processed": frames_processed,
        "frames_bad": frames_bad,
        "frames_superseded": per_key(s, "superseded", f"/camera/{CAMERA}/frame"),
        "poses_handled": s.get("received", 0) - frames_processed - frames_bad,
        "poses_superseded": per_key(s, "superseded", "/pose"),
    }


def settled_stats(bench: Service, sent: dict[str, int], observer: Observer) -> dict:
    """The AR client's counters once everything in flight has landed: every frame and pose sent is
    accounted for and every overlay published received, or the counters stopped moving for a second
    (a message really lost), or 15 s passed. A fixed pause undercounted a frame still being worked on
    at a loaded machine's pace."""
    deadline = time.monotonic() + 15.0
    last: tuple[int, ...] = ()
    still_since = time.monotonic()
    while True:
        s = stats_of(bench, "ar")
        a = accounted(s)
        frames = a["frames_processed"] + a["frames_bad"] + a["frames_superseded"]
        poses = a["poses_handled"] + a["poses_superseded"]
        published = s.get("published", 0)
        if frames >= sent["camera"] and poses >= sent["poses"] and observer.received >= published:
            return s
        now = time.monotonic()
        counters = (frames, poses, published, observer.received)
        if counters != last:
            last, still_since = counters, now
        elif now - still_since > 1.0 or now > deadline:
            return s
        time.sleep(0.1)


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return round(int(line.split()[1]) / 1024.0, 1)
    return float("nan")


def per_key(stats: dict, name: str, part: str) -> int:
    """The sum of ``name:<key>`` counters whose key contains ``part``."""
    return sum(v for k, v in stats.items() if k.startswith(f"{name}:") and part in k)


def measure(args: argparse.Namespace) -> dict:
    procs: list[Proc] = []
    namespace = f"load{free_tcp_port()}"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    me = [sys.executable, str(Path(__file__).resolve()), "--namespace", namespace, "--connect", endpoint]
    bench = client("loadbench", namespace, endpoint)
    try:
        procs.append(Proc(arroch("router", "--listen", endpoint), name="router"))
        procs[-1].wait_for("router ready", timeout=30)
        ar = Proc(
            arroch(
                "ar",
                "--namespace",
                namespace,
                "--connect",
                endpoint,
                "--clock",
                "wall",
                "--no-feedback",
                "--camera",
                CAMERA,
            ),
            name="ar",
        )
        procs.append(ar)
        ar.wait_for("waiting for frames", timeout=60)
        bench.open()
        observer = Observer(bench)
        procs.append(Proc([*me, "--role", "camera", "--fps", str(args.fps)], name="camera"))
        procs.append(
            Proc(
                [*me, "--role", "poses", "--robots", str(args.robots), "--pose-rate", str(args.pose_rate)], name="poses"
            )
        )
        log(
            f"load: {args.robots} robots at {args.pose_rate:g} Hz, camera at {args.fps:g} frames/s; warming up "
            f"{args.warmup:g} s"
        )
        deadline = time.monotonic() + 60
        while observer.received == 0:  # the camera process renders its snapshots first
            if time.monotonic() > deadline:
                raise RuntimeError("no overlay within 60 s:\n" + "\n".join(p.output[-2000:] for p in procs))
            time.sleep(0.1)
        time.sleep(args.warmup)
        samples: list[dict] = []
        rss_start = rss_mb(ar.popen.pid)
        with observer.lock:
            observer.recording = True
        started = time.monotonic()
        while (elapsed := time.monotonic() - started) < args.seconds:
            s = stats_of(bench, "ar")
            if s:
                samples.append(
                    {
                        "t": round(elapsed, 2),
                        "inbox_depth": s.get("inbox_depth", 0),
                        "inbox_depth_max": s.get("inbox_depth_max", 0),
                        "latest_waiting": s.get("latest_waiting", 0),
                    }
                )
            time.sleep(SAMPLE_PERIOD)
        with observer.lock:
            observer.recording = False
        rss_end = rss_mb(ar.popen.pid)
        overlays_in_window = len(observer.robots_per_overlay)
        # Stop the generators (each prints what it sent), let everything in flight land, then account
        # for every message.
        sent = {}
        for proc in procs[2:]:
            proc.stop()
            sent[proc.name] = int(proc.wait_for("sent ", timeout=5).split()[-1])
        final = settled_stats(bench, sent, observer)
        return report(args, observer, samples, final, sent, overlays_in_window, (rss_start, rss_end))
    finally:
        bench.close()
        for proc in reversed(procs):
            proc.stop()


def report(
    args: argparse.Namespace,
    observer: Observer,
    samples: list[dict],
    s: dict,
    sent: dict[str, int],
    overlays: int,
    rss: tuple[float, float],
) -> dict:
    """The JSON document: ``s`` is the AR client's final counters, ``sent`` what each generator sent."""
    a = accounted(s)
    frames_processed, frames_bad, frames_superseded = a["frames_processed"], a["frames_bad"], a["frames_superseded"]
    poses_handled, poses_superseded = a["poses_handled"], a["poses_superseded"]
    thirds = [[x for x in samples if k * args.seconds / 3 <= x["t"] < (k + 1) * args.seconds / 3] for k in range(3)]
    return {
        "benchmark": "load",
        "robots": args.robots,
        "pose_rate_hz": args.pose_rate,
        "fps": args.fps,
        "seconds": args.seconds,
        "pose_to_overlay_ms": summary(observer.pose_ages),
        "frame_to_overlay_ms": summary(observer.frame_ages),
        "overlays_per_s": round(overlays / args.seconds, 2),
        "robots_per_overlay": summary([float(n) for n in observer.robots_per_overlay]),
        "stages": {
            "poses_to_ar": {
                "sent": sent["poses"],
                "handled": poses_handled,
                "superseded": poses_superseded,
                "lost": sent["poses"] - poses_handled - poses_superseded,
            },
            "frames_to_ar": {
                "sent": sent["camera"],
                "processed": frames_processed,
                "superseded": frames_superseded,
                "bad": frames_bad,
                "lost": sent["camera"] - frames_processed - frames_superseded - frames_bad,
            },
            "overlays_to_observer": {
                "sent": s.get("published", 0),
                "received": observer.received,
                "lost": s.get("published", 0) - observer.received,
            },
            "ar_inbox_full_drops": s.get("dropped_inbox_full", 0),
            "ar_bad_messages": s.get("bad_messages", 0),
        },
        "queues": {
            "inbox_depth_max": max([x["inbox_depth_max"] for x in samples], default=0),
            "latest_waiting_max": max([x["latest_waiting"] for x in samples], default=0),
            "inbox_depth_max_per_third": [max([x["inbox_depth"] for x in third], default=0) for third in thirds],
            "latest_waiting_max_per_third": [max([x["latest_waiting"] for x in third], default=0) for third in thirds],
            "samples": len(samples),
            "ar_rss_mb": {"start": rss[0], "end": rss[1]},
        },
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count()},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0, help="measuring time (default 20)")
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds of load before measuring (default 3)")
    parser.add_argument("--robots", type=int, default=50, help="robots publishing poses (default 50)")
    parser.add_argument("--pose-rate", type=float, default=20.0, help="poses per robot per second (default 20)")
    parser.add_argument("--fps", type=float, default=30.0, help="camera frames per second (default 30)")
    parser.add_argument("--role", choices=("bench", "poses", "camera"), default="bench", help=argparse.SUPPRESS)
    parser.add_argument("--namespace", help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == "poses":
        return run_poses(args)
    if args.role == "camera":
        return run_camera(args)
    print(json.dumps(measure(args), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
