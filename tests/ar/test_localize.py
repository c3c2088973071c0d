"""Tablet pose from wall tags on real (synthetic, anti-aliased, noisy) pixels.

Frames are rendered by ``services.ar_client.synth`` at known poses; the stated bounds are what the
tests hold the pipeline to. Bounds (default detector: OpenCV ArUco + edge-fit corners):

* several tags on a wall (the hall's west wall: six 0.16 m tags over 3 m), 1-4 m, 0-60 deg:
  position within 0.5 % of the distance and rotation within 0.3 deg at 1280x720;
  within 1 % and 0.6 deg at 640x480;
* one tag, 1-4 m, 30-60 deg off its normal, 1280x720: within 1 % and 0.5 deg; near-frontal
  (0-15 deg) a single small tag is genuinely ambiguous (its two planar solutions fit the pixels
  equally well): within 4 % and 2.5 deg, and flagged ``ambiguous`` whenever worse than 1 %;
* exact 180 deg (a level camera squarely facing the tag): within 2 % and 1.5 deg.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from runtime.frames import CameraPose, camera_from_yaw_pitch
from services.ar_client.detect import TagDetector
from services.ar_client.localize import Localizer
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, HD, SINGLE_CENTRE, SINGLE_TAG, VGA, errors, only_tags, site, view_of


@pytest.fixture(scope="module")
def detector() -> TagDetector:
    return TagDetector("opencv", known_ids=[lm.tag for lm in site("hall").landmarks])


@pytest.mark.parametrize("K,pos_frac,rot_deg", [(HD, 0.005, 0.3), (VGA, 0.01, 0.6)], ids=["1280x720", "640x480"])
def test_several_tags_1_to_4_m_up_to_60_degrees(detector, K, pos_frac, rot_deg):
    hall = site("hall")
    worst = (0.0, 0.0)
    for d in (1.0, 2.0, 3.0, 4.0):
        for ob in (0.0, 30.0, 45.0, 60.0):
            for side in (1, -1):
                truth = view_of(CLUSTER_CENTRE, 0.0, d, side * ob)
                frame = render(hall, truth, K, seed=int(d * 100 + ob))
                loc = Localizer(hall).localize(detector.detect(frame.image), K, 0.0)
                assert loc.ok, (d, ob, loc.reason)
                assert len(loc.tags) >= 2, (d, ob, loc.tags)
                pe, re = errors(loc.pose, truth)
                assert pe <= pos_frac * d and re <= rot_deg, (d, ob, side, pe, re)
                assert loc.rmse_px < 0.5
                worst = max(worst, (pe / d, re))
    assert worst[0] > 0.0  # the errors were measured, not trivially zero


@pytest.mark.parametrize("d", [1.0, 2.0, 3.0, 4.0])
def test_single_tag_oblique_and_frontal(detector, d):
    lone = only_tags("hall", (SINGLE_TAG,))
    hall = site("hall")
    for ob in (0.0, 15.0, 30.0, 45.0, 60.0):
        for side in (1, -1):
            truth = view_of(SINGLE_CENTRE, np.pi, d, side * ob)
            frame = render(lone, truth, HD, seed=int(d * 10 + ob))
            loc = Localizer(hall).localize(detector.detect(frame.image), HD, 0.0)
            assert loc.ok and loc.tags == [SINGLE_TAG], (d, ob, loc.reason)
            pe, re = errors(loc.pose, truth)
            if ob >= 30.0:
                assert pe <= 0.01 * d and re <= 0.55, (d, ob, pe, re)
            else:
                assert pe <= 0.04 * d and re <= 2.5, (d, ob, pe, re)
                if pe > 0.01 * d:
                    assert loc.ambiguous, (d, ob, pe, re)


@pytest.mark.parametrize("d", [1.0, 2.0, 3.0])
def test_single_tag_exactly_180_degrees_level_camera(detector, d):
    """A level camera squarely facing the tag: the tag-to-camera rotation is exactly 180 deg about
    the vertical, where OpenCV's IPPE returns wrong poses (NOTES). SQPnP among the candidates and
    the reprojection check keep the result right."""
    lone = only_tags("hall", (SINGLE_TAG,))
    hall = site("hall")
    truth = camera_from_yaw_pitch(SINGLE_CENTRE - [d, 0.0, 0.0], yaw=0.0, pitch=0.0)
    frame = render(lone, truth, HD, seed=3)
    dets = detector.detect(frame.image)
    loc = Localizer(hall).localize(dets, HD, 0.0)
    assert loc.ok
    pe, re = errors(loc.pose, truth)
    assert pe <= 0.02 * d and re <= 1.5, (pe, re)
    # The configuration is the degenerate one: IPPE alone is far off here. (Should a future OpenCV
    # fix this, the check says the test no longer exercises the failure.)
    lm = next(lm for lm in hall.landmarks if lm.tag == SINGLE_TAG)
    _ok, rvec, tvec = cv2.solvePnP(lm.corners(), dets[0].corners, HD.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    ippe_error, _ = errors(CameraPose.from_rvec_tvec(rvec, tvec), truth)
    assert ippe_error > 0.5


@pytest.mark.parametrize("height", [1.0])
def test_tracking_keeps_the_right_solution_of_an_ambiguous_tag(detector, height):
    """One small tag (about 20 px across at 640x480), 3.6-3.8 m away, 25 to 12 deg off its normal,
    the camera moving a little each frame. Frame by frame, the mirror solution often fits the pixels
    better (rotation errors of 20-30 deg); with the previous pose as a guide every frame stays on
    the right branch."""
    lone = only_tags("hall", (SINGLE_TAG,))
    hall = site("hall")
    tracked = Localizer(hall)
    frames = 30
    flips_alone = 0
    for k in range(frames):
        s = k / (frames - 1)
        truth = view_of(SINGLE_CENTRE, np.pi, 3.6 + 0.2 * s, -25.0 + 13.0 * s, height=height)
        dets = detector.detect(render(lone, truth, VGA, seed=k).image)
        loc = tracked.localize(dets, VGA, stamp=0.05 * k)  # 20 frames/s
        assert loc.ok, (k, loc.reason)
        assert errors(loc.pose, truth)[1] <= 4.0, (k, errors(loc.pose, truth))
        alone = Localizer(hall).localize(dets, VGA, 0.0)
        flips_alone += alone.ok and errors(alone.pose, truth)[1] > 10.0
    assert flips_alone >= 3  # without tracking the sequence really does flip


def test_a_misplaced_tag_is_rejected_as_an_outlier(detector):
    """The site file puts tag 2 where it is not (0.3 m off): its corners disagree with the others'
    pose, it is dropped, and the pose from the remaining tags stays accurate."""
    import dataclasses

    hall = site("hall")
    wrong = dataclasses.replace(
        hall,
        landmarks=[
            dataclasses.replace(lm, position=(lm.position[0], lm.position[1] + 0.3, lm.position[2]))
            if lm.tag == 2
            else lm
            for lm in hall.landmarks
        ],
    )
    truth = view_of(CLUSTER_CENTRE, 0.0, 2.5, 20.0)
    frame = render(hall, truth, HD, seed=5)  # the real wall
    loc = Localizer(wrong).localize(detector.detect(frame.image), HD, 0.0)
    assert loc.ok and loc.rejected == [2] and 2 not in loc.tags
    pe, re = errors(loc.pose, truth)
    assert pe <= 0.01 and re <= 0.3


def test_lost_without_tags_reports_the_age_of_the_last_pose_and_no_pose(detector):
    hall = site("hall")
    localizer = Localizer(hall)
    blank = np.full((HD.height, HD.width), 128, np.uint8)
    first = localizer.localize(detector.detect(blank), HD, 10.0)
    assert not first.ok and first.pose is None and first.lost_age is None and "no landmark" in first.reason
    truth = view_of(CLUSTER_CENTRE, 0.0, 2.0, 10.0)
    good = localizer.localize(detector.detect(render(hall, truth, HD).image), HD, 11.0)
    assert good.ok
    lost = localizer.localize(detector.detect(blank), HD, 13.5)
    assert not lost.ok and lost.pose is None and lost.lost_age == pytest.approx(2.5)
    assert lost.to_json()["ok"] is False and "position" not in lost.to_json()


def test_tags_the_site_does_not_know_give_no_pose():
    """A tag that is not a landmark of the site (here: the hall's tags against the xray site) is
    never used; the answer is lost, naming the ids."""
    hall = site("hall")
    xray = site("xray")
    truth = view_of(CLUSTER_CENTRE, 0.0, 2.0, 10.0)
    frame = render(hall, truth, HD)
    loc = Localizer(xray).localize(TagDetector("opencv").detect(frame.image), HD, 0.0)
    assert not loc.ok and "not in the site" in loc.reason


def test_implausible_poses_are_refused():
    """A pose below the floor, outside the building, or upside down is not a hand-held tablet."""
    hall = site("hall")
    localizer = Localizer(hall)
    good = view_of(CLUSTER_CENTRE, 0.0, 2.0, 10.0)
    assert localizer.plausibility(good, [0, 1]) == ""
    low = CameraPose(R_wc=good.R_wc, position=good.position * [1, 1, 0] + [0, 0, 0.1])
    assert "height" in localizer.plausibility(low, [0])
    outside = CameraPose(R_wc=good.R_wc, position=np.array([-3.0, 5.0, 1.2]))
    assert "behind tag" in localizer.plausibility(outside, [0]) or "outside" in localizer.plausibility(outside, [0])
    flipped = CameraPose(R_wc=good.R_wc @ np.diag([-1.0, -1.0, 1.0]), position=good.position)
    assert "upright" in localizer.plausibility(flipped, [0])
    behind = CameraPose(R_wc=good.R_wc, position=np.array([15.0, 5.0, 1.2]))  # in the annex, east of the east wall
    assert "behind tag 10" in localizer.plausibility(behind, [10])


def test_a_pose_outside_plausible_heights_is_lost_with_the_reason(detector):
    """A camera 2.6 m up (on a ladder, not a hand-held tablet): the pose fits the pixels but is
    refused, and the reason says which check failed."""
    hall = site("hall")
    truth = view_of(CLUSTER_CENTRE, 0.0, 2.5, 20.0, height=2.6)
    loc = Localizer(hall).localize(detector.detect(render(hall, truth, HD).image), HD, 0.0)
    assert not loc.ok and loc.pose is None
    assert "height 2.6" in loc.reason
    relaxed = Localizer(hall, height_range=(0.3, 3.0)).localize(detector.detect(render(hall, truth, HD).image), HD, 0.0)
    assert relaxed.ok and errors(relaxed.pose, truth)[0] < 0.01
