"""Tablet latency: a camera frame sent by the page → that frame's overlay drawn, on localhost.

Usage::

    .venv/bin/python benchmarks/tablet_latency.py [--seconds 12] [--warmup 3] [--sizes 640x480,1280x720]

For each camera size: a Zenoh router, ``arroch tablet`` (with the camera's intrinsics file) and a
headless Chromium (Debian's ``chromium``) whose fake camera plays the simulator's snapshots of the
office site (a tablet panning slowly across the storage room's tagged wall, rendered at that size by
``services.sim.world.World``, the intrinsics file being the snapshots' own) with a robot and its
intent in view (published on Zenoh), so the server localises and draws a real scene. The page measures with
``performance.now()`` for every answered frame (``window.arroch.stats()``):

* ``capture_to_drawn``: the frame grabbed from the <video> → its overlay drawn on the canvas
  (JPEG encoding in the browser, the WebSocket both ways, decoding, localisation and projection on
  the server, drawing);
* ``sent_to_drawn``: ``ws.send`` of the frame → its overlay drawn (the link round trip plus drawing);
* ``server_ms``: the server's own time for the frame (decode → overlay message).

Reports median, p95 and mean in milliseconds, the achieved frames per second (at most 15: the page's
limit), the frame size and JPEG bytes the page chose, and how many frames the page gave up on.
Browser and server share this machine's cores. Prints one JSON document on stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib import figures  # noqa: E402
from benchmarks.lib.figures import log  # noqa: E402
from protocol.messages import Intent, RobotPose  # noqa: E402
from runtime.service import Service  # noqa: E402
from runtime.transport import ZenohOptions, free_tcp_port  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402
from tests.tablet.browser import Browser, chromium_path  # noqa: E402
from tests.tablet.helpers import ROBOT_XY, fake_camera, snapshots, start_tablet  # noqa: E402


def summary(values: list[float]) -> dict[str, float]:
    return figures.summary(values, percentiles=(50, 95), scale=1.0, digits=2)


def measure(width: int, height: int, seconds: float, warmup: float, workdir: Path) -> dict:
    procs: list[Proc] = []

    def spawn(argv: list[str], *, name: str = "", env: dict[str, str] | None = None) -> Proc:
        proc = Proc(argv, name=name, env=env)
        procs.append(proc)
        return proc

    video, intrinsics = fake_camera(workdir, snapshots(6, width, height))
    namespace = f"bench{width}"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    client = Service("bench", namespace, ZenohOptions(mode="client", connect=[endpoint]))
    try:
        spawn(arroch("router", "--listen", endpoint), name="router").wait_for("router ready", timeout=20)
        server = start_tablet(spawn, endpoint, namespace, workdir / "state", "--intrinsics", str(intrinsics), "--no-qr")
        client.open()
        time.sleep(0.5)
        x, y = ROBOT_XY
        now = time.time()
        client.publish(client.keys.robot_pose("r0"), RobotPose(robot="r0", x=x, y=y, theta=0.0))
        client.publish(
            client.keys.intent("r0"),
            Intent(robot="r0", trajectory=[[now + 2.0 * k, x + 0.5 * k, y, 0.0] for k in range(60)]),
        )
        with Browser(fake_camera=video, window=(1280, 800)) as page:
            page.navigate(server.url)
            page.wait_for(
                "window.arroch && window.arroch.state().overlay && window.arroch.state().overlay.ok", timeout=60
            )
            time.sleep(warmup)
            before = page.evaluate("window.arroch.stats()")
            started = time.monotonic()
            time.sleep(seconds)
            after = page.evaluate("window.arroch.stats()")
            elapsed = time.monotonic() - started
            state = page.evaluate("window.arroch.state()")
        samples = [s for s in after["samples"] if s["seq"] > (before["samples"][-1]["seq"] if before["samples"] else 0)]
        return {
            "camera": f"{width}x{height}",
            "frames": len(samples),
            "fps": round(len(samples) / elapsed, 2),
            "localised": round(sum(1 for s in samples if s["ok"]) / max(len(samples), 1), 3),
            "capture_to_drawn_ms": summary([s["capture_to_drawn"] for s in samples]),
            "sent_to_drawn_ms": summary([s["sent_to_drawn"] for s in samples]),
            "server_ms": summary([s["server_ms"] for s in samples]),
            "frame_sizes": sorted({f"{s['width']}x{s['height']}" for s in samples}),
            "jpeg_bytes_mean": round(float(np.mean([s["bytes"] for s in samples])), 0) if samples else 0,
            "given_up": after["given_up"] - before["given_up"],
            "overlay_primitives": state["overlay"]["primitives"] if state["overlay"] else 0,
        }
    finally:
        client.close()
        for proc in reversed(procs):
            proc.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=12.0, help="measuring time per camera size (default 12)")
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds before measuring (default 3)")
    parser.add_argument("--sizes", default="640x480,1280x720", help="camera sizes (default 640x480,1280x720)")
    args = parser.parse_args()
    if chromium_path() is None:
        print(
            json.dumps(
                {"benchmark": "tablet_latency", "skipped": "no Chromium on this machine (apt-get install chromium)"}
            )
        )
        return 0
    results = []
    for size in args.sizes.split(","):
        w, h = (int(v) for v in size.lower().split("x"))
        log(f"tablet latency at {w}x{h} ...")
        with tempfile.TemporaryDirectory(prefix="arroch-tablet-bench-") as tmp:
            results.append(measure(w, h, args.seconds, args.warmup, Path(tmp)))
        log(json.dumps(results[-1]))
    print(
        json.dumps(
            {
                "benchmark": "tablet_latency",
                "what": (
                    "page: camera frame captured/sent -> its overlay drawn, localhost, performance.now() in the page"
                ),
                "machine": {"python": platform.python_version(), "cpus": __import__("os").cpu_count()},
                "chromium": chromium_path(),
                "results": results,
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
