"""Shared pieces of the AR client tests: the test sites, synthetic frames, pose errors."""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

import numpy as np

from protocol.site import load_site
from runtime.frames import CameraPose, look_at, rotation_angle
from services.ar_client.project import Intrinsics

SITES = Path(__file__).parent / "sites"
HALL_FILE = SITES / "hall.toml"
VGA = Intrinsics.from_fov(640, 480, 50.0)
HD = Intrinsics.from_fov(1280, 720, 50.0)

#: The east-wall tag of the hall site, alone on its wall (single-tag cases).
SINGLE_TAG = 10
SINGLE_CENTRE = np.array([13.949, 4.0, 1.4])
#: Middle of the hall's west-wall cluster of six tags.
CLUSTER_CENTRE = np.array([0.051, 5.0, 1.35])


@cache
def site(name: str):  # noqa: ANN201
    return load_site(SITES / f"{name}.toml")


@cache
def only_tags(name: str, tags: tuple[int, ...]):  # noqa: ANN201
    """The site with only ``tags`` on its walls (to render frames in which only those can be seen)."""
    full = site(name)
    return dataclasses.replace(full, landmarks=[lm for lm in full.landmarks if lm.tag in tags])


def view_of(
    target: np.ndarray, facing_yaw: float, distance: float, obliquity_deg: float, height: float = 1.2
) -> CameraPose:
    """A camera ``distance`` m from ``target`` (horizontally), ``obliquity_deg`` off the wall normal
    ``facing_yaw``, aimed at it."""
    a = facing_yaw + np.radians(obliquity_deg)
    xy = target[:2] + distance * np.array([np.cos(a), np.sin(a)])
    return look_at([xy[0], xy[1], height], target)


def errors(estimate: CameraPose, truth: CameraPose) -> tuple[float, float]:
    """Position error (m) and rotation error (degrees)."""
    return float(np.linalg.norm(estimate.position - truth.position)), float(
        np.degrees(rotation_angle(estimate.R_wc, truth.R_wc))
    )
