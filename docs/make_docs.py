"""``make docs``: every figure the docs quote from a demo run, measured on a fresh one.

Runs ``arroch demo`` as ``make demo`` does (lockstep, paced; ``--no-linger``) in a scratch folder, then
writes

- ``docs/figures.json``: each figure's value and the text the docs quote (``{"key": {"value", "text"}}``);
- ``docs/demo-timeline.png``: the run's timeline, as ``arroch runs show RUN --png`` draws it;

and rewrites every quoted figure in README.md, docs/*.md and docs/services/*.md: a figure is quoted as
``<!--figure:KEY-->TEXT<!--/figure-->`` (the comments do not show in rendered Markdown), and TEXT is
replaced by the figure's text. ``tests/test_docs_figures.py`` checks that every quote matches
``figures.json``, so the docs cannot drift from what was measured.

Usage: ``python docs/make_docs.py [--keep DIR]`` (``--keep``: run in DIR and leave the run there).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIGURES = ROOT / "docs" / "figures.json"
TIMELINE = ROOT / "docs" / "demo-timeline.png"
QUOTE = re.compile(r"<!--figure:([a-z0-9_.]+)-->(.*?)<!--/figure-->", re.DOTALL)
DEMO_TIMEOUT = 900.0  # wall s for the whole demo on a busy machine


@dataclass(frozen=True)
class Figure:
    value: float | int
    text: str


def quoted_files() -> list[Path]:
    return [
        ROOT / "README.md",
        *sorted((ROOT / "docs").glob("*.md")),
        *sorted((ROOT / "docs" / "services").glob("*.md")),
    ]


def run_demo(folder: Path) -> tuple[Path, float]:
    """A fresh ``arroch demo`` run in ``folder``: its run folder and its wall time (s)."""
    runs = folder / "runs"
    started = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-m", "services.cli", "demo", "--no-linger", "--run-dir", str(runs)],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        timeout=DEMO_TIMEOUT,
        check=False,
    )
    wall = time.monotonic() - started
    if result.returncode != 0:
        raise SystemExit(f"make docs: the demo failed (exit {result.returncode}); no figure written")
    (run,) = [p for p in runs.iterdir() if p.is_dir()]
    return run, wall


def measure(run: Path, wall: float) -> dict[str, Figure]:
    """The figures of one demo run (its folder and the demo's wall time)."""
    sys.path.insert(0, str(ROOT))
    from services.recorder.reading import channel_stats

    metrics = json.loads((run / "metrics.json").read_text())
    recording = run / "run.mcap"
    channels = channel_stats(recording)
    by_topic = {c.topic: c for c in channels}
    messages = sum(c.messages for c in channels)
    span = max(c.last for c in channels) - min(max(c.first, 0.0) for c in channels)
    pose = by_topic["/arroch/robot/r0/pose"]
    image = by_topic["/camera/tablet/image"]

    def rate(c: object) -> float:
        return c.messages / max(c.last - c.first, 1e-9)  # type: ignore[attr-defined]

    size_mb = recording.stat().st_size / 1e6
    figures = {
        "demo.wall_s": Figure(round(wall, 1), f"{wall:.0f} s"),
        "demo.team_time_s": Figure(metrics["team_completion_time"], f"{metrics['team_completion_time']:.1f} s"),
        "recording.size_mb": Figure(round(size_mb, 2), f"{size_mb:.1f} MB"),
        "recording.messages": Figure(messages, f"{messages:,}"),
        "recording.channels": Figure(len(channels), str(len(channels))),
        "recording.site_span_s": Figure(round(span, 1), f"{span:.0f} s"),
        "recording.pose_hz": Figure(round(rate(pose), 2), f"{rate(pose):.0f} Hz"),
        "recording.camera_frames": Figure(image.messages, str(image.messages)),
        "recording.camera_hz": Figure(round(rate(image), 3), f"{rate(image):.2f} Hz"),
    }
    return figures


def draw_timeline(run: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "services.cli", "runs", "show", str(run), "--png", str(TIMELINE)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        check=True,
        timeout=300,
    )


def requote(text: str, figures: dict[str, Figure], where: str) -> str:
    """``text`` with every quoted figure's text replaced; an unknown key is an error naming the file."""

    def replace(match: re.Match[str]) -> str:
        key = match.group(1)
        if key not in figures:
            raise SystemExit(f"make docs: {where} quotes figure {key!r}, which {FIGURES.name} does not have")
        return f"<!--figure:{key}-->{figures[key].text}<!--/figure-->"

    return QUOTE.sub(replace, text)


def write(figures: dict[str, Figure], rewrite: Callable[[Path, str], None]) -> None:
    FIGURES.write_text(
        json.dumps({k: {"value": f.value, "text": f.text} for k, f in figures.items()}, indent=2, sort_keys=True)
        + "\n",
        encoding="utf-8",
    )
    for path in quoted_files():
        before = path.read_text(encoding="utf-8")
        after = requote(before, figures, path.name)
        if after != before:
            rewrite(path, after)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", metavar="DIR", help="run the demo in DIR and leave the run there")
    args = parser.parse_args(argv)
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="arroch-docs-"))
    try:
        run, wall = run_demo(folder)
        figures = measure(run, wall)
        draw_timeline(run)
        write(figures, lambda path, text: path.write_text(text, encoding="utf-8"))
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
    for key, figure in figures.items():
        print(f"{key:28} {figure.text}")
    print(f"wrote {FIGURES.relative_to(ROOT)}, {TIMELINE.relative_to(ROOT)} and the quotes in the docs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
