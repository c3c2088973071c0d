"""The pose stream drawn: one wrong frame does not throw the overlay, jitter is smoothed, a real
move is followed."""

from __future__ import annotations

import numpy as np

from runtime.frames import CameraPose, gravity_in_camera, look_at, rotation_angle
from services.ar_client.gravity import GravityPrior
from services.ar_client.pipeline import Pipeline
from services.ar_client.posefilter import PoseFilter
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, VGA, site

FPS = 15.0


def pan(k: int) -> CameraPose:
    """A tablet walking slowly (0.3 m/s) past the hall's west-wall cluster, 2.5 m from it, turning to
    keep it in view."""
    t = k / FPS
    position = [2.5, 3.8 + 0.3 * t, 1.35]
    return look_at(position, CLUSTER_CENTRE + [0.0, 0.2 * t, 0.0])


def test_one_wrong_frame_does_not_move_the_drawn_pose():
    hall = site("hall")
    pipeline = Pipeline(hall)
    wrong_at = 12
    wrong_pose = look_at([3.6, 6.2, 1.5], CLUSTER_CENTRE + [0.0, -0.6, 0.0])  # 1.1 m away, looking elsewhere
    drawn, measured, truths = [], [], []
    for k in range(24):
        truth = pan(k)
        seen = wrong_pose if k == wrong_at else truth
        frame = render(hall, seen, VGA, seed=k)
        overlay, _ = pipeline.process(frame.image, VGA, k / FPS, annotate=False)
        assert overlay.ok, k
        drawn.append(np.array(overlay.position))
        measured.append(pipeline.last_localization.pose.position)
        truths.append(truth.position)
        if k == wrong_at:
            assert not pipeline.last_filtered.accepted and "jumped" in pipeline.last_filtered.reason
    drawn, measured, truths = map(np.array, (drawn, measured, truths))
    # The localiser really measured the wrong place at that frame ...
    assert np.linalg.norm(measured[wrong_at] - truths[wrong_at]) > 0.8
    assert pipeline.pose_filter.rejected == 1
    # ... but what is drawn follows the walk: no step bigger than a few of its 2 cm steps, near the truth.
    steps = np.linalg.norm(np.diff(drawn, axis=0), axis=1)
    assert steps.max() < 0.06, steps
    assert np.linalg.norm(drawn - truths, axis=1).max() < 0.05


def _pose(x: float, yaw_deg: float = 0.0) -> CameraPose:
    return look_at([x, 0.0, 1.4], [x + np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg)), 1.4])


def test_jitter_is_smoothed_and_a_steady_motion_followed():
    rng = np.random.default_rng(1)
    f = PoseFilter()
    raw, out = [], []
    for k in range(90):
        truth = 0.01 * k  # 0.3 m/s at 30 Hz
        noisy = _pose(truth + rng.normal(0.0, 0.01))
        drawn = f.update(noisy, k / 30.0)
        assert drawn.accepted
        if k >= 30:  # once the velocity has settled
            raw.append(noisy.position[0] - truth)
            out.append(drawn.pose.position[0] - truth)
    assert np.std(out) < 0.8 * np.std(raw)
    assert abs(np.mean(out)) < 0.005  # no lag behind a constant velocity


def test_a_real_move_restarts_the_filter_after_a_few_consistent_frames():
    f = PoseFilter()
    for k in range(10):
        f.update(_pose(0.0), k / 15.0)
    results = [f.update(_pose(2.0, 40.0), (10 + k) / 15.0) for k in range(4)]
    assert [r.accepted for r in results[:2]] == [False, False]
    assert results[2].accepted and results[2].reason == "restarted"
    assert np.linalg.norm(results[3].pose.position - _pose(2.0, 40.0).position) < 0.01
    assert f.rejected == 3


def test_a_pose_tilted_against_gravity_is_rejected():
    f = PoseFilter()
    level = _pose(0.0)
    gravity = GravityPrior.from_vector(gravity_in_camera(level.R_wc))
    for k in range(5):
        assert f.update(level, k / 15.0, gravity).accepted
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.15), -np.sin(0.15)], [0.0, np.sin(0.15), np.cos(0.15)]])
    tilted = CameraPose(
        R_wc=level.R_wc @ tilt, position=level.position + [0.02, 0.0, 0.0]
    )  # 8.6 deg pitch, a small step
    r = f.update(tilted, 5 / 15.0, gravity)
    assert not r.accepted and "gravity" in r.reason
    assert np.degrees(rotation_angle(r.pose.R_wc, level.R_wc)) < 0.5


def test_a_gap_starts_afresh():
    f = PoseFilter()
    f.update(_pose(0.0), 0.0)
    far = f.update(_pose(3.0, 90.0), 2.0)  # 2 s later: the old state is stale
    assert far.accepted and np.linalg.norm(far.pose.position - _pose(3.0, 90.0).position) < 1e-9
