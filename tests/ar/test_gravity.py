"""Gravity in the localiser: the 4-DoF scan, the prior, and a single small tag's planar ambiguity."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from runtime.frames import gravity_in_camera, look_at
from services.ar_client.detect import TagDetector
from services.ar_client.gravity import GravityPrior, gravity_error, parse_gravity, refine, yaw_scan
from services.ar_client.localize import Localizer
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, SINGLE_CENTRE, SINGLE_TAG, VGA, errors, only_tags, site, view_of


@pytest.fixture(scope="module")
def detector() -> TagDetector:
    return TagDetector("opencv", known_ids=[lm.tag for lm in site("hall").landmarks])


def single_tag_view(obliquity_deg: float, distance: float = 4.5, height: float = 1.0):  # noqa: ANN201
    """A camera ``distance`` m from the hall's lone tag, ``obliquity_deg`` off its normal, aimed a little beside it."""
    a = np.pi + np.radians(obliquity_deg)
    xy = SINGLE_CENTRE[:2] + distance * np.array([np.cos(a), np.sin(a)])
    return look_at([xy[0], xy[1], height], SINGLE_CENTRE + [0.0, 0.2, 0.1])


def test_yaw_scan_finds_the_true_pose_among_its_minima():
    hall = site("hall")
    truth = single_tag_view(-30.0)
    obj = np.asarray(next(lm for lm in hall.landmarks if lm.tag == SINGLE_TAG).corners(), np.float64)
    rvec, tvec = truth.rvec_tvec()
    img, _ = cv2.projectPoints(obj, rvec, tvec, VGA.K, None)
    prior = GravityPrior.from_vector(gravity_in_camera(truth.R_wc))
    seeds = yaw_scan(obj, img.reshape(-1, 2), VGA.K, VGA.dist, prior)
    assert 1 <= len(seeds) <= 4
    # Every seed agrees with gravity exactly (the scan only turns about the vertical) ...
    from runtime.frames import CameraPose

    for r, t in seeds:
        assert np.degrees(gravity_error(CameraPose.from_rvec_tvec(r, t).R_wc, prior)) < 1e-6
    # ... and refining the best one lands on the truth.
    r, t = refine(obj, img.reshape(-1, 2), VGA.K, VGA.dist, *seeds[0], prior, sigma_px=0.1)
    pe, re = errors(CameraPose.from_rvec_tvec(r, t), truth)
    assert pe < 1e-3 and re < 0.01


@pytest.mark.parametrize("obliquity", [-30.0, -15.0])
def test_gravity_picks_a_small_single_tags_right_solution(detector, obliquity):
    """VGA, 4.5 m, one 17-px tag: the two planar solutions fit the pixels equally well, and without
    gravity the wrong one wins (~50-100 % of the distance off) but is flagged; gravity (1 deg noise)
    picks the right one."""
    lone, hall = only_tags("hall", (SINGLE_TAG,)), site("hall")
    truth = single_tag_view(obliquity)
    frame = render(lone, truth, VGA, seed=int(450 + obliquity + 10))
    dets = detector.detect(frame.image)
    assert [d.tag_id for d in dets] == [SINGLE_TAG]
    blind = Localizer(hall).localize(dets, VGA, 0.0)
    assert blind.ok and blind.ambiguous
    assert errors(blind.pose, truth)[0] > 0.2 * 4.5
    g = gravity_in_camera(truth.R_wc, 1.0, np.random.default_rng(7))
    seen = Localizer(hall).localize(dets, VGA, 0.0, gravity=g)
    assert seen.ok
    pe, re = errors(seen.pose, truth)
    assert pe < 0.03 * 4.5 and re < 2.0, (pe, re)
    assert seen.gravity_error_deg is not None and seen.gravity_error_deg < 3.0
    assert "gravity_error_deg" in seen.to_json() and "gravity_error_deg" not in blind.to_json()


def test_noisy_gravity_does_not_pull_a_well_seen_pose(detector):
    """Several tags at 2 m: the pixels pin the rotation far better than a 1-deg accelerometer."""
    hall = site("hall")
    worst = []
    for k, ob in enumerate((-40.0, 0.0, 35.0)):
        truth = view_of(CLUSTER_CENTRE, 0.0, 2.0, ob, height=1.3)
        dets = detector.detect(render(hall, truth, VGA, seed=k).image)
        blind = Localizer(hall).localize(dets, VGA, 0.0)
        g = gravity_in_camera(truth.R_wc, 1.0, np.random.default_rng(k))
        seen = Localizer(hall).localize(dets, VGA, 0.0, gravity=g)
        worst.append((errors(blind.pose, truth)[0], errors(seen.pose, truth)[0]))
    blind_err, seen_err = np.array(worst).T
    assert seen_err.max() <= max(2.0 * blind_err.max(), 0.01), worst


def test_gravity_far_from_every_solution_is_refused(detector):
    """Gravity 30 deg off what the tags say: no pose rather than one that contradicts the sensor."""
    hall = site("hall")
    truth = view_of(CLUSTER_CENTRE, 0.0, 2.0, 10.0, height=1.3)
    dets = detector.detect(render(hall, truth, VGA, seed=3).image)
    tilted = cv2.Rodrigues(np.array([np.radians(30.0), 0.0, 0.0]))[0] @ gravity_in_camera(truth.R_wc)
    loc = Localizer(hall).localize(dets, VGA, 0.0, gravity=tilted)
    assert not loc.ok and "gravity" in loc.reason


def test_no_or_unusable_gravity_behaves_as_without():
    assert GravityPrior.from_vector(None) is None
    assert GravityPrior.from_vector([]) is None
    assert GravityPrior.from_vector([0.0, 0.0, 0.0]) is None
    assert GravityPrior.from_vector([np.nan, 9.8, 0.0]) is None
    assert np.allclose(GravityPrior.from_vector([0.0, 9.8, 0.0]).direction, [0.0, 1.0, 0.0])


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "0,0,0", "1,2,nan"])
def test_bad_gravity_text_is_named(text):
    with pytest.raises(ValueError, match="gravity"):
        parse_gravity(text)
