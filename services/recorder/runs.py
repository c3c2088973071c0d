"""``arroch runs show DIR``: a run's summary in a readable table, its recording's channels (message
counts and time spans) and a timeline PNG drawn from the recording."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from datetime import datetime
from pathlib import Path
from typing import Any, TextIO

from .reading import RecordingError, channel_stats, metadata
from .timebase import ORIGIN_KEY
from .timeline import build_timeline, draw_timeline

log = logging.getLogger("arroch.runs")
RECORDING = "run.mcap"


def _seconds(value: Any) -> str:
    if value is None:
        return "—"
    v = float(value)
    return f"{v:,.1f} s ({v / 60:.1f} min)" if v >= 60 else f"{v:.1f} s"


def _table(rows: list[tuple[str, str, str]], out: TextIO) -> None:
    width = [max(len(r[i]) for r in rows) for i in range(2)]
    for name, value, note in rows:
        print(f"  {name:<{width[0]}}  {value:<{width[1]}}  {note}".rstrip(), file=out)


def metrics_rows(m: dict[str, Any]) -> list[tuple[str, str, str]]:
    rows = [
        ("completed", "yes" if m.get("completed") else "no", "every object delivered and the human's own task done"),
        ("team completion time", _seconds(m.get("team_completion_time")), "the slowest agent's, the human included"),
    ]
    for agent, t in (m.get("agent_completion_times") or {}).items():
        rows.append((f"  {agent}", _seconds(t), "last delivery" if agent != "human" else "her own task done"))
    rows.append(
        (
            "human door openings",
            str(m.get("human_door_openings", 0)),
            "times the human walked to a door and opened it for the robots (her a1 actions; the paper's figure)",
        )
    )
    note = "openings per door: by the human, or for a robot (doors that open as a robot approaches)"
    for door, by in sorted((m.get("door_openings") or {}).items()):
        parts = [f"{n} by {who}" for who, n in sorted(by.items())]
        rows.append((f"  {door}", ", ".join(parts), note))
        note = ""
    fb = m.get("feedback") or {}
    rows.append(
        (
            "feedback",
            f"{fb.get('sent', 0)} sent",
            f"{fb.get('accepted', 0)} accepted, {fb.get('refused', 0)} refused, "
            f"{fb.get('unanswered', 0)} unanswered (the human's declarations)",
        )
    )
    for rid, r in sorted((m.get("robots") or {}).items()):
        rows.append(
            (
                f"robot {rid}",
                f"{len(r.get('delivered', []))} delivered",
                f"waited {float(r.get('wait_time', 0)):.1f} s at closed doors",
            )
        )
    rows.append(
        (
            "closed-door crossings",
            str(m.get("closed_door_crossings", 0)),
            "robots that entered a closed door's doorway (0 in a correct run)",
        )
    )
    if "robot_overlaps" in m:  # older runs' metrics have no such count
        rows.append(
            ("robot-robot contacts", str(m["robot_overlaps"]), "times two robots' discs began to intersect (0: none)")
        )
    rows.append(("world versions", str(m.get("world_versions", 0)), "changes the planner had to answer (replans)"))
    return rows


def recording_of(run: Path) -> Path:
    """A run folder's recording, or the recording itself."""
    return run if run.suffix == ".mcap" else run / RECORDING


def show(run: Path, out: TextIO | None = None, png: Path | None = None) -> int:
    out = out or sys.stdout  # looked up now, not at import: a caller may have redirected it
    recording = recording_of(run)
    folder = recording.parent
    print(f"run {folder}", file=out)
    info_file = folder / "run.json"
    if info_file.is_file():
        info = json.loads(info_file.read_text())
        print(
            f"  services {', '.join(info.get('services', []))}; stopped: {info.get('stop_reason')}; "
            f"exit {info.get('exit_code')}; {float(info.get('wall_seconds', 0)):.1f} wall s",
            file=out,
        )
    metrics_file = folder / "metrics.json"
    metrics = json.loads(metrics_file.read_text()) if metrics_file.is_file() else None
    if not recording.is_file():
        print(f"  no recording ({recording} is missing: the run was started with --no-record?)", file=out)
        if not metrics:
            log.error("%s: neither %s nor metrics.json: nothing to show", folder, RECORDING)
            return 1
        print("\nmetrics", file=out)
        _table(metrics_rows(metrics), out)
        return 0
    stats = channel_stats(recording)
    timeline = build_timeline(recording)
    metrics = metrics or timeline.metrics
    if metrics:
        print("\nmetrics", file=out)
        _table(metrics_rows(metrics), out)
    size = recording.stat().st_size
    total = sum(c.messages for c in stats)
    print(f"\nrecording {recording} ({size / 1e6:.2f} MB, {total} messages, {len(stats)} channels)", file=out)
    origin = int(metadata(recording).get(ORIGIN_KEY, 0))
    if origin:
        start = datetime.fromtimestamp(origin / 1e9).astimezone().isoformat(timespec="milliseconds")
        print(f"  site time 0 on the wall clock: {start} (log times are this plus site time)", file=out)
    rows = [("topic", "schema", "messages", "from (site s)", "to (site s)")]
    rows += [(c.topic, c.schema, str(c.messages), f"{c.first:.1f}", f"{c.last:.1f}") for c in stats]
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    for r in rows:
        print(
            f"  {r[0]:<{widths[0]}}  {r[1]:<{widths[1]}}  {r[2]:>{widths[2]}}  {r[3]:>{widths[3]}}  "
            f"{r[4]:>{widths[4]}}",
            file=out,
        )
    picture = draw_timeline(timeline, png or folder / "timeline.png", title=f"timeline of {folder.name}")
    print(f"\ntimeline {picture}", file=out)
    return 0


def show_main(args: argparse.Namespace) -> int:
    path = Path(args.run)
    if not path.exists():
        log.error("%s: no such run folder or recording", path)
        return 2
    try:
        return show(path, png=Path(args.png) if args.png else None)
    except RecordingError as exc:
        log.error("%s", exc)
        return 2


def add_runs_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="DIR", help="a run folder (runs/<time>/) or a recording (.mcap)")
    parser.add_argument("--png", metavar="FILE", help="where the timeline goes (default DIR/timeline.png)")
    parser.add_argument("--log-level", default=None, choices=("DEBUG", "INFO", "WARNING", "ERROR"))
