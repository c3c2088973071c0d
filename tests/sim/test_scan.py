"""The simulated laser scanner (services/sim/scan.py) sees what the kinematic world holds: walls at
their exact distance, a door's leaf where it stands (not through a closed door, through an open
one), other robots and the human as discs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from protocol.site import load_site
from services.sim.doors import DoorConfig, Doors
from services.sim.scan import Scanner, ScannerConfig

SITE = load_site()
R1 = SITE.robots["r1"].start  # (12.5, 8.0) facing -y, in the lab, 2 m from d_lab (on the wall y = 6)


def beam(scanner: Scanner, bearing: float) -> int:
    """The beam pointing ``bearing`` rad from the robot's heading."""
    return int(round((bearing - scanner.angle_min) / scanner.angle_increment)) % scanner.config.beams


def doors(fraction: float) -> Doors:
    d = Doors(SITE.doors.values(), DoorConfig(), SITE.params.robot_radius, SITE.door_leaves)
    d["d_lab"].fraction = fraction
    return d


def test_walls_at_their_distance():
    scanner = Scanner(SITE)
    ranges = scanner.ranges(R1, [])
    wall_half = (SITE.walls[0].box[3] - SITE.walls[0].box[1]) / 2  # walls are boxes around their centre line
    # Through d_lab's gap (no leaves given) to the corridor's far wall at y = 4.
    assert ranges[beam(scanner, 0.0)] == pytest.approx(8.0 - 4.0 - wall_half, abs=1e-9)
    assert ranges.min() > SITE.params.robot_radius  # the robot stands clear of every wall


def test_a_closed_leaf_is_seen_an_open_one_lets_the_beam_through():
    scanner = Scanner(SITE)
    ahead = beam(scanner, 0.0)
    closed = scanner.ranges(R1, [], doors(0.0))[ahead]
    opened = scanner.ranges(R1, [], doors(1.0))[ahead]
    assert closed == pytest.approx(2.0, abs=0.01) and opened > 3.5


def test_robots_and_the_human_are_discs():
    scanner = Scanner(SITE, ScannerConfig(beams=360))
    x, y, th = R1
    person = (x + math.cos(th) * 1.0, y + math.sin(th) * 1.0, 0.18)
    robot = (x + 0.8, y, 0.25)  # to the robot's right (heading -y): bearing +90°
    ranges = scanner.ranges(R1, [person, robot])
    assert ranges[beam(scanner, 0.0)] == pytest.approx(0.82, abs=1e-9)
    assert ranges[beam(scanner, math.pi / 2)] == pytest.approx(0.55, abs=1e-9)
    assert scanner.ranges(R1, [(x, y, 0.25)]).max() == 0.0  # inside a disc: touching everywhere


def test_beyond_range_is_no_return():
    scanner = Scanner(SITE, ScannerConfig(range_max=1.0))
    assert np.isinf(scanner.ranges(R1, [])).all()
