"""Lens distortion in the corner refinement: a tag's edges are straight only once undistorted."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from runtime.frames import look_at
from services.ar_client.detect import TagDetector
from services.ar_client.localize import Localizer
from services.ar_client.refine import Lens
from services.ar_client.synth import render
from tests.ar.helpers import CLUSTER_CENTRE, VGA, errors, site

#: A wide-angle lens with strong barrel distortion (about 9 px at the image corners of 640x480).
DISTORTION = (-0.28, 0.09, 0.0, 0.0, 0.0)


def distorted(image: np.ndarray, lens: Lens) -> np.ndarray:
    """The picture an ideal-pinhole ``image`` becomes through the lens: each output pixel reads the
    ideal image where its ray lands undistorted."""
    h, w = image.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    ideal = lens.undistort(np.stack([u, v], axis=-1))
    return cv2.remap(
        image, ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32), cv2.INTER_LINEAR, borderValue=120
    )


def test_lens_round_trip():
    lens = Lens(VGA.K, np.array(DISTORTION))
    points = np.array([[5.0, 5.0], [634.0, 470.0], [320.0, 240.0], [100.0, 400.0]])
    assert np.abs(lens.distort(lens.undistort(points)) - points).max() < 1e-6


def test_corners_and_pose_account_for_the_distortion():
    hall = site("hall")
    K = dataclasses.replace(VGA, distortion=DISTORTION)
    lens = Lens(K.K, K.dist)
    # Close to the cluster and looking a little past it and down: the tags spread to where the lens bends most.
    truth = look_at([1.5, 5.0, 1.35], CLUSTER_CENTRE + [0.0, -1.0, 0.2])
    frame = render(hall, truth, VGA, seed=2, noise_sigma=1.0, blur_sigma=0.5)
    image = distorted(frame.image, lens)
    detector = TagDetector("opencv", known_ids=[lm.tag for lm in hall.landmarks])
    aware, blind = detector.detect(image, lens), detector.detect(image)
    ids = {d.tag_id for d in aware} & {d.tag_id for d in blind}
    assert len(ids) >= 3
    true = {t: lens.distort(frame.corners[t]) for t in ids}
    err_aware = np.sqrt(np.mean([np.sum((d.corners - true[d.tag_id]) ** 2, axis=1) for d in aware if d.tag_id in ids]))
    err_blind = np.sqrt(np.mean([np.sum((d.corners - true[d.tag_id]) ** 2, axis=1) for d in blind if d.tag_id in ids]))
    # Over one tag the distortion is nearly affine, so the blind fit is not far off; it is still 2-4x worse.
    assert err_aware < 0.1 and err_aware < 0.6 * err_blind, (err_aware, err_blind)
    loc = Localizer(hall).localize(aware, K, 0.0)
    pe, re = errors(loc.pose, truth)
    assert loc.ok and pe < 0.02 and re < 0.5, (pe, re)
