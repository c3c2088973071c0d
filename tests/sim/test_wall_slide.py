"""A robot whose pursuit would cut a jamb's corner goes along the jamb instead (runtime/executor/wall_slide.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from runtime.executor.wall_slide import CLEAR, WallSlide
from runtime.executor.walls import TOUCH, WallDepth
from runtime.pursuit import ControllerConfig, Step
from tests.sim.helpers import small_site

RADIUS = 0.25
DT = 0.05
CORNER = (6.45, 3.95)  # the storage doorway's east jamb, corridor side of the wall at y = 4 (small_site)


@pytest.fixture
def walls() -> WallDepth:
    return WallDepth(small_site(), RADIUS)


def robot(x: float, y: float, theta: float) -> SimpleNamespace:
    return SimpleNamespace(id="r0", x=x, y=y, theta=theta)


def forward(r: SimpleNamespace, distance: float = 0.5 * DT) -> Step:
    """The pursuit's step straight ahead, at the robots' speed."""
    return Step(r.x + distance * math.cos(r.theta), r.y + distance * math.sin(r.theta), r.theta, distance / DT, 0.0)


def test_the_way_out_of_a_jambs_corner_points_from_the_corner(walls: WallDepth) -> None:
    x, y = 6.2, 3.9  # inside the storage room, 5 mm from the corner
    away = walls.away(x, y)
    expected = (x - CORNER[0], y - CORNER[1])
    norm = math.hypot(*expected)
    assert away == pytest.approx((expected[0] / norm, expected[1] / norm))
    assert walls.depth(x, y) == pytest.approx(RADIUS - norm)


def test_a_step_across_the_corner_becomes_a_turn_then_a_drive_along_the_jamb_that_never_enters_it(
    walls: WallDepth,
) -> None:
    slide = WallSlide(walls, TOUCH, ControllerConfig())
    r = robot(6.2, 3.9, -math.pi / 4)  # heading south-east, across the corner
    wanted = forward(r)
    assert slide.into_wall(r.x, r.y, wanted.x, wanted.y)  # the guard would refuse the pursuit's step
    turns = drives = 0
    for _ in range(200):
        step = slide.step(r, forward(r), DT)
        if (step.x, step.y) == (r.x, r.y):
            turns += 1
            assert step.v == 0.0 and step.omega != 0.0  # on the spot, as a differential drive must
        else:
            drives += 1
            assert not slide.into_wall(r.x, r.y, step.x, step.y)
            # along the jamb: away from the corner, and still on the wanted side (south-east)
            assert math.dist((step.x, step.y), CORNER) >= math.dist((r.x, r.y), CORNER) - 1e-9
            assert step.y < r.y
        r.x, r.y, r.theta = step.x, step.y, step.theta
        assert walls.depth(r.x, r.y) <= TOUCH
        if walls.depth(r.x, r.y) <= -CLEAR:
            break
    assert turns > 0 and drives > 0
    assert walls.depth(r.x, r.y) <= -CLEAR  # it got clear of the jamb
    r.theta = -math.pi / 4
    free = forward(r)
    assert slide.step(r, free, DT) is free  # clear: the pursuit steers again


def test_a_step_straight_at_a_wall_is_left_to_the_guard(walls: WallDepth) -> None:
    slide = WallSlide(walls, TOUCH, ControllerConfig())
    r = robot(3.0, 4.05 + RADIUS, -math.pi / 2)  # in the corridor, touching the wall, facing it
    step = forward(r)
    assert slide.into_wall(r.x, r.y, step.x, step.y)
    assert slide.step(r, step, DT) is step  # nothing along the wall: the guard refuses it, the grid plans


def test_a_step_clear_of_every_wall_is_the_pursuits(walls: WallDepth) -> None:
    slide = WallSlide(walls, TOUCH, ControllerConfig())
    r = robot(3.0, 5.0, 0.3)
    step = forward(r)
    assert slide.step(r, step, DT) is step
