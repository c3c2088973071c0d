"""Which annotated frames the AR client keeps (``arroch ar --snapshots``): good ones, spread over the run."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import cv2
import numpy as np
import pytest

from protocol.messages import Overlay, Primitive
from services.ar_client.snapshots import OverlaySnapshots, least_needed, shows_world


def overlay(
    seq: int, *, ok: bool = True, layers: tuple[str, ...] = ("robot:r0", "intent:r0"), latency: float = 0.05
) -> Overlay:
    prims = [
        Primitive(kind="line", points=[[1.0, 1.0], [5.0, 5.0]], color=[255, 0, 0, 255], layer=layer) for layer in layers
    ]
    return Overlay(
        camera="tablet",
        frame_seq=seq,
        width=32,
        height=24,
        ok=ok,
        latency=latency,
        primitives=prims,
        position=[1.0, 2.0, 1.3] if ok else [],
        quaternion=[0.0, 0.0, 0.0, 1.0] if ok else [],
    )


IMAGE = np.full((24, 32, 3), 90, np.uint8)


def test_only_frames_with_a_pose_a_robot_an_intent_and_a_matching_drawing_are_kept(tmp_path: Path):
    assert shows_world(overlay(1)) and not shows_world(overlay(1, ok=False))
    assert not shows_world(overlay(1, layers=("robot:r0", "door"))) and not shows_world(
        overlay(1, layers=("intent:r1",))
    )
    keep = OverlaySnapshots(tmp_path / "overlays")
    assert keep.offer(overlay(1, layers=("robot:r0",)), IMAGE, 0.0) is None
    assert keep.offer(overlay(2, latency=2.0), IMAGE, 0.0) is None  # drawn 2 s of site time after its capture
    path = keep.offer(overlay(3), IMAGE, 1.5)
    assert path == tmp_path / "overlays" / "overlay-t00001.5-f3.png"
    assert cv2.imread(str(path)).shape == (24, 32, 3)
    record = json.loads(path.with_suffix(".json").read_text())
    assert (
        record["time"] == 1.5
        and record["frame_seq"] == 3
        and {p["layer"] for p in record["primitives"]} == {"robot:r0", "intent:r0"}
    )
    assert not keep.wanted(5.0) and keep.offer(overlay(4), IMAGE, 5.0) is None  # within the minimum gap


def test_the_kept_frames_stay_spread_from_the_first_to_the_newest(tmp_path: Path):
    keep = OverlaySnapshots(tmp_path, count=4, min_gap=10.0)
    # Good frames come in clusters (lockstep: site time jumps while nothing happens).
    for seq, t in enumerate([0.0, 12.0, 25.0, 290.0, 301.0, 330.0, 420.0, 640.0]):
        assert keep.offer(overlay(seq), IMAGE, t) is not None
    times = [t for t, _ in keep.kept]
    assert times[0] == 0.0 and times[-1] == 640.0 and len(times) == 4
    assert min(b - a for a, b in pairwise(times)) >= 100.0, times
    on_disk = sorted(p.name for p in tmp_path.iterdir())
    assert on_disk == sorted([p.name for p in keep.paths] + [p.with_suffix(".json").name for p in keep.paths])


def test_least_needed_drops_the_interior_frame_with_the_closest_neighbours():
    assert least_needed([0.0, 10.0, 12.0, 100.0]) == 1  # neighbours 0 and 12: the tightest
    assert least_needed([0.0, 50.0, 60.0, 61.0, 200.0]) == 2  # neighbours 50 and 61


def test_fewer_than_two_frames_is_refused():
    with pytest.raises(ValueError, match="--snapshot-count must be at least 2"):
        OverlaySnapshots("x", count=1)
