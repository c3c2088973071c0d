"""A few overlay frames kept as pictures: what the AR client drew, spread over a run.

``arroch ar --snapshots DIR`` keeps at most ``count`` annotated frames in DIR, each as
``overlay-t<site time>-f<frame seq>.png`` with the Overlay it published beside it (``.json``: time,
pose, tags, latency, every primitive).

Which frames: only those that show what the AR view is for — a pose was found, at least one robot
and one intent are drawn — and whose drawing is the world the image shows: no more than
``max_latency`` site seconds between the frame's capture and its drawing. The AR client does not
know how long the run will be, so the set is kept spread as it goes: the first good frame, then any
good frame at least ``min_gap`` site seconds after the last one kept; past ``count``, the kept frame
(neither the first nor the newest) whose neighbours are closest in time is deleted. At the end the
run's first and last good frames are there, and the others fill the largest gaps between them.

Lockstep: site time advances only while the sim is not waiting for the planner, and then many times
faster than wall time, so a frame taken at a wall instant would be drawn over robots seconds further
on. The sim therefore takes its frames on the site clock instead: one every ``--camera-hold`` site
seconds (30), once the plan answering that instant is in, with time held still until this client's
Overlay of it comes back (:class:`services.sim.camfeed.FrameHold`). Every frame is then drawn at its
capture instant and passes the latency check, whatever the machine's load; which frames show the
world depends only on the mission, and so does the kept set: two runs of the same mission keep
frames at the same site times. (Two demo runs do not always give the same mission: the planner's
answers can differ from run to run, and then so do the robots the tablet sees.)
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from protocol.messages import Overlay
from protocol.schema import record_to_wire

DEFAULT_COUNT = 5
MIN_GAP = 10.0  # site seconds between two kept frames
MAX_LATENCY = 0.5  # site seconds from capture to drawing beyond which the drawing is not the image's


def shows_world(overlay: Overlay) -> bool:
    """A pose, at least one robot avatar and at least one intent path are drawn."""
    layers = {p.layer for p in overlay.primitives}
    return (
        overlay.ok
        and any(layer.startswith("robot:") for layer in layers)
        and any(layer.startswith("intent:") for layer in layers)
    )


def least_needed(times: list[float]) -> int:
    """Index of the interior time whose neighbours are closest: dropping it loses the least spread."""
    return min(range(1, len(times) - 1), key=lambda i: (times[i + 1] - times[i - 1], i))


class OverlaySnapshots:
    """Decides which annotated frames to keep and keeps them on disk (PNG + the Overlay as JSON)."""

    def __init__(
        self,
        directory: str | Path,
        count: int = DEFAULT_COUNT,
        min_gap: float = MIN_GAP,
        max_latency: float = MAX_LATENCY,
    ) -> None:
        if count < 2:
            raise ValueError(f"--snapshot-count must be at least 2 (the first and the last), got {count}")
        self.directory = Path(directory)
        self.count = count
        self.min_gap = min_gap
        self.max_latency = max_latency
        self.kept: list[tuple[float, Path]] = []  # (site time, PNG), in time order

    @property
    def paths(self) -> list[Path]:
        return [path for _, path in self.kept]

    def wanted(self, now: float) -> bool:
        """Whether a frame drawn at site time ``now`` could be kept (so is worth annotating)."""
        return not self.kept or now >= self.kept[-1][0] + self.min_gap

    def offer(self, overlay: Overlay, image: np.ndarray, now: float) -> Path | None:
        """Keep this annotated frame if it qualifies; returns the PNG written, or None."""
        if not self.wanted(now) or not shows_world(overlay) or overlay.latency > self.max_latency:
            return None
        self.directory.mkdir(parents=True, exist_ok=True)
        path = self.directory / f"overlay-t{now:07.1f}-f{overlay.frame_seq}.png"
        if not cv2.imwrite(str(path), image):
            raise OSError(f"cannot write {path}")
        path.with_suffix(".json").write_text(json.dumps({"time": now, **record_to_wire(overlay)}, indent=1) + "\n")
        self.kept.append((now, path))
        if len(self.kept) > self.count:
            _, dropped = self.kept.pop(least_needed([t for t, _ in self.kept]))
            dropped.unlink(missing_ok=True)
            dropped.with_suffix(".json").unlink(missing_ok=True)
        return path
