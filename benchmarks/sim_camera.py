"""Virtual camera throughput: frames per second at 640x480 and 1280x720 on the default site.

For each size, frames of the office site are rendered with pybullet's ER_TINY_RENDERER (one core,
as the simulator does) from a cycle of tablet poses: three inside storage facing its tagged walls,
one in the corridor looking along it (the scene with the most on screen). Per frame it times the
render alone and the whole CameraFrame (render + JPEG at quality 90, what ``arroch sim --camera``
publishes), and reports frames per second, mean/p50/p95 milliseconds (wall clock, and CPU time of
this process, which is what an idle core would give when other work shares the machine) and the
JPEG size. A supersampled 640x480 (2x, anti-aliased) is measured too.

Prints one JSON document. Usage: ``python benchmarks/sim_camera.py [--frames 12]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.lib.stdio import c_stdout_to_stderr  # noqa: E402

POSES = (  # x, y, z, yaw°, pitch°
    (8.0, 2.0, 1.3, -70.0, 5.0),
    (8.2, 1.2, 1.25, 100.0, 4.0),
    (7.5, 2.0, 1.4, 180.0, -5.0),
    (2.0, 5.0, 1.6, 0.0, -10.0),
)
SIZES = ((640, 480, 1), (1280, 720, 1), (640, 480, 2))


def _stats(ms: list[float]) -> dict[str, float]:
    ordered = sorted(ms)
    return {
        "mean_ms": round(statistics.fmean(ms), 1),
        "p50_ms": round(ordered[len(ordered) // 2], 1),
        "p95_ms": round(ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))], 1),
        "fps": round(1000.0 / statistics.fmean(ms), 2),
    }


def measure(frames: int) -> dict:
    with c_stdout_to_stderr():
        from protocol.site import load_site
        from services.sim.camera import CameraSpec, frame_message
        from services.sim.world import World

        site = load_site(None)
        started = time.perf_counter()
        world = World(site)
        build_s = time.perf_counter() - started
    bodies = len(world.names)
    results = {}
    with world:
        for width, height, supersample in SIZES:
            cams = [CameraSpec.from_degrees(*pose, width, height, 60.0, supersample) for pose in POSES]
            world.render(cams[0])  # warm-up (texture upload, caches)
            render_ms, frame_ms, frame_cpu_ms, jpeg_kb = [], [], [], []
            for i in range(frames):
                cam = cams[i % len(cams)]
                c0, t0 = time.process_time(), time.perf_counter()
                image = world.render(cam)
                t1 = time.perf_counter()
                frame = frame_message("bench", image, cam)
                c2, t2 = time.process_time(), time.perf_counter()
                render_ms.append((t1 - t0) * 1000.0)
                frame_ms.append((t2 - t0) * 1000.0)
                frame_cpu_ms.append((c2 - c0) * 1000.0)
                jpeg_kb.append(len(frame.jpeg) / 1024.0)
            key = f"{width}x{height}" + (f"@{supersample}x" if supersample > 1 else "")
            results[key] = {
                "render": _stats(render_ms),
                "frame": _stats(frame_ms),
                # CPU seconds of this process: the figure on an idle core, whatever else runs here.
                "frame_cpu": _stats(frame_cpu_ms),
                "jpeg_kB": round(statistics.fmean(jpeg_kb), 1),
            }
    return {
        "benchmark": "sim_camera",
        "renderer": "ER_TINY_RENDERER",
        "site": site.name,
        "bodies": bodies,
        "world_build_s": round(build_s, 3),
        "frames_per_size": frames,
        "cpu_count": os.cpu_count(),
        "results": results,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=12, help="frames per size (default 12)")
    args = parser.parse_args()
    if args.frames < 1:
        parser.error("--frames must be >= 1")
    print(json.dumps(measure(args.frames), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
