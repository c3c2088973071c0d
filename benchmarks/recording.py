"""What recording costs a mission, and how large a recording gets.

Usage::

    .venv/bin/python benchmarks/recording.py [--pairs 3] [--realtime-seconds 60]

1. ``ratio``: the default lockstep mission (what ``arroch demo`` runs: planner, restrictor, sim with
   the tablet camera, AR client; seed 1) under ``arroch up``, with its recorder (the default) and with
   ``--no-record``, in interleaved pairs; the wall time is the whole run's (``run.json``
   ``wall_seconds``: start-up, mission, shut-down). The figure is the median over pairs of each
   pair's ratio, so both runs of a pair meet about the same load on this shared machine.
2. ``recording``: the recorded mission's file: size, messages, channels.
3. ``processing``: the recorder's own work on that mission, timed in this process: every recorded
   message through the default profile into a new MCAP file (median of 5 passes), as a share of the
   recorded run's wall time — what recording adds to the machine's load, free of the other
   processes' noise.
4. ``realtime_30min``: the same mission in real time (``--mode realtime``, camera at its default
   2 frames per wall second, 640x480 JPEG) for ``--realtime-seconds`` wall seconds; its bytes per
   second, per kind of channel, times 1800 is the size of a 30-minute real-time recording; the same
   messages recorded again with ``--image-scale 0.5`` give the size with frames kept at half size.

Prints one JSON document on stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import make_reader

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

MISSION = [
    "--services",
    "planner,restrictor,sim,ar",
    "--camera",
    "tablet",
    "--seed",
    "1",
    "--progress",
    "off",
    "--log-level",
    "WARNING",
]


def up(run_base: Path, *args: str, timeout: float) -> Path:
    """Run ``arroch up`` into a fresh run folder; return the folder."""
    run_base.mkdir(parents=True, exist_ok=True)
    before = set(run_base.iterdir())
    argv = [sys.executable, "-m", "services.cli", "up", *MISSION, "--run-dir", str(run_base), *args]
    subprocess.run(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=timeout + 60)
    (run,) = set(run_base.iterdir()) - before
    return run


def bytes_per_kind(path: Path) -> tuple[dict[str, int], dict[str, int], float]:
    """Payload bytes and messages per kind of channel, and the recording's site-time span."""
    sizes: dict[str, int] = {}
    counts: dict[str, int] = {}
    first = last = None
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            topic = channel.topic
            kind = (
                "camera"
                if "/camera/" in topic or topic.startswith("/arroch/ar/")
                else "poses"
                if topic == "/tf" or topic.endswith("/pose")
                else "other"
            )
            sizes[kind] = sizes.get(kind, 0) + len(message.data)
            counts[kind] = counts.get(kind, 0) + 1
            first = message.log_time if first is None else min(first, message.log_time)
            last = message.log_time if last is None else max(last, message.log_time)
    return sizes, counts, ((last or 0) - (first or 0)) / 1e9


def rerecord(recording: Path, image_scale: float = 1.0, passes: int = 5) -> tuple[float, int, int]:
    """Every recorded message through the default profile into a new file: (median seconds, messages, bytes)."""
    from protocol.keys import Keys
    from protocol.site import load_site
    from services.recorder.profile import FoxgloveProfile
    from services.recorder.reading import messages, metadata
    from services.recorder.sink import FoxgloveSink
    from services.recorder.timebase import Timebase
    from services.recorder.topics import key_of

    keys = Keys(metadata(recording)["namespace"])
    site = load_site()
    recorded = list(messages(recording))
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(passes):
            path = Path(tmp) / f"{k}.mcap"
            timebase = Timebase(time.time_ns())
            profile = FoxgloveProfile(FoxgloveSink(path), keys, site, timebase, image_scale=image_scale)
            start = time.perf_counter()
            profile.start(timebase.at(0.0))
            profile.origin_fixed()
            for rec in recorded:
                profile.handle(rec.message, key_of(keys, rec.topic), rec.payload)
            profile.close()
            times.append(time.perf_counter() - start)
            size = path.stat().st_size
    return statistics.median(times), len(recorded), size


def processing(recording: Path, wall: float) -> dict:
    cpu, count, _size = rerecord(recording)
    return {
        "messages": count,
        "seconds": round(cpu, 4),
        "us_per_message": round(cpu / count * 1e6, 1),
        "share_of_run_wall": round(cpu / wall, 4),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, default=3, help="interleaved pairs of missions (default 3)")
    parser.add_argument(
        "--realtime-seconds",
        type=float,
        default=60.0,
        help="wall seconds of the real-time run (default 60; 0 skips it)",
    )
    args = parser.parse_args()
    out: dict = {"benchmark": "recording"}
    with tempfile.TemporaryDirectory(prefix="arroch-bench-rec-") as tmp:
        base = Path(tmp)
        walls: dict[str, list[float]] = {"recorded": [], "not_recorded": []}
        ratios = []
        recording = None
        for k in range(args.pairs):
            pair = {}
            # Alternate which goes first, so neither always meets a warmer machine.
            order = ("recorded", "not_recorded") if k % 2 == 0 else ("not_recorded", "recorded")
            for variant in order:
                flags = ["--mode", "lockstep", "--until-done", "--timeout", "300"]
                flags += ["--record"] if variant == "recorded" else ["--no-record"]
                run = up(base / variant, *flags, timeout=300)
                info = json.loads((run / "run.json").read_text())
                if not info.get("mission_done"):
                    print(f"pair {k}: {variant} mission did not finish: {info.get('stop_reason')}", file=sys.stderr)
                    return 1
                pair[variant] = float(info["wall_seconds"])
                walls[variant].append(pair[variant])
                if variant == "recorded":
                    recording = run / "run.mcap"
            ratios.append(pair["recorded"] / pair["not_recorded"])
            print(
                f"pair {k}: recorded {pair['recorded']:.1f} s, not recorded {pair['not_recorded']:.1f} s, "
                f"ratio {ratios[-1]:.3f}",
                file=sys.stderr,
                flush=True,
            )
        out["lockstep_mission"] = {
            "pairs": args.pairs,
            "wall_s_recorded": walls["recorded"],
            "wall_s_not_recorded": walls["not_recorded"],
            "ratios": [round(r, 3) for r in ratios],
            "ratio_median": round(statistics.median(ratios), 3),
        }
        assert recording is not None
        sizes, counts, span = bytes_per_kind(recording)
        with open(recording, "rb") as f:
            summary = make_reader(f).get_summary()
        out["recording"] = {
            "bytes": recording.stat().st_size,
            "messages": sum(counts.values()),
            "channels": len(summary.channels),
            "site_seconds": round(span, 1),
            "payload_bytes_by_kind": sizes,
            "messages_by_kind": counts,
        }
        out["processing"] = processing(recording, float(statistics.median(walls["recorded"])))
        if args.realtime_seconds > 0:
            print(f"real-time mission for {args.realtime_seconds:g} s", file=sys.stderr, flush=True)
            run = up(
                base / "realtime",
                "--mode",
                "realtime",
                "--timeout",
                f"{args.realtime_seconds:g}",
                timeout=args.realtime_seconds,
            )
            path = run / "run.mcap"
            sizes, counts, span = bytes_per_kind(path)
            size = path.stat().st_size
            per_s = size / span if span > 0 else 0.0
            out["realtime_30min"] = {
                "measured_site_seconds": round(span, 1),
                "file_bytes": size,
                "bytes_per_second": round(per_s),
                "payload_bytes_per_second_by_kind": {k: round(v / span) for k, v in sizes.items()},
                "messages_per_second_by_kind": {k: round(v / span, 1) for k, v in counts.items()},
                "estimate_30min_mb": round(per_s * 1800 / 1e6, 1),
                # Frames kept at half size (arroch record --image-scale 0.5): the file shrinks as the same
                # messages recorded again at 0.5 do against recorded again at 1.
                "estimate_30min_mb_image_scale_0.5": round(
                    per_s * 1800 / 1e6 * rerecord(path, 0.5, passes=1)[2] / rerecord(path, 1.0, passes=1)[2], 1
                ),
                "camera": "640x480 JPEG at 2 frames per wall second (the sim's defaults)",
            }
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
