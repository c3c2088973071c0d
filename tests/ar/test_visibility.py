"""X-ray classification against hand-checked cases on the xray site (see its drawing):

y=6 +-----------------------------------------+
    |                  hall                   |
y=4 +--[d_a: x 1.5-2.5]--+--[passage: x 5.4-6.6]--+
    |         a          |          b             |
y=0 +--------------------+------------------------+
    x=0                 x=4                      x=8
"""

from __future__ import annotations

import numpy as np
import pytest

from services.ar_client.visibility import Occluders, resample, split_runs
from tests.ar.helpers import site

EYE_DOOR = np.array([2.0, 5.5])  # in the hall, in line with the door
EYE_PASSAGE = np.array([6.0, 5.5])  # in the hall, in line with the passage


@pytest.mark.parametrize(
    "eye,point,door_open,hidden,why",
    [
        (EYE_DOOR, (2.0, 2.0), False, True, "straight through the closed door d_a: its leaf hides"),
        (EYE_DOOR, (2.0, 2.0), True, False, "straight through the open door d_a"),
        (EYE_DOOR, (0.5, 2.0), True, True, "crosses y=4 at x=1.36, on the wall left of the doorway"),
        (EYE_DOOR, (4.0, 5.0), False, False, "inside the hall"),
        (EYE_PASSAGE, (6.0, 2.0), False, False, "through the passage, which never occludes"),
        (EYE_PASSAGE, (7.5, 1.0), False, False, "crosses y=4 at x=6.5, inside the passage"),
        (EYE_PASSAGE, (3.0, 1.0), True, True, "crosses y=4 at x=5.0 (wall) and then the a|b wall"),
        (EYE_PASSAGE, (2.0, 2.0), True, True, "crosses y=4 at x=4.2, on the wall between doorway and passage"),
        (np.array([7.0, 2.0]), (1.0, 2.0), True, True, "from room b into room a through the wall x=4"),
        (np.array([7.0, 2.0]), (5.0, 1.0), True, False, "inside room b"),
    ],
)
def test_hand_checked_cases(eye, point, door_open, hidden, why):
    occ = Occluders.from_site(site("xray"), ["d_a"] if door_open else [])
    assert occ.blocked(eye, point) is hidden, why


def test_a_camera_above_the_walls_sees_everything():
    occ = Occluders.from_site(site("xray"), [])
    assert occ.blocked(EYE_DOOR, (0.5, 2.0))
    assert not occ.blocked(EYE_DOOR, (0.5, 2.0), eye_z=3.0)


def test_a_path_through_a_door_splits_where_the_jamb_cuts_the_view():
    """From (6, 5.5) a path down x=2 through the doorway: hall points are visible; in room a, the
    view passes the doorway only while y >= 3.786 (line to the jamb at x=2.5), when the door is open;
    a closed leaf hides everything past y=4."""
    path = np.array([[2.0, 5.0], [2.0, 1.0]])
    pts, _frac = resample(path)
    assert np.max(np.linalg.norm(np.diff(pts, axis=0), axis=1)) <= 0.05 + 1e-9
    for door_open, boundary in ((True, 3.786), (False, 4.0)):
        occ = Occluders.from_site(site("xray"), ["d_a"] if door_open else [])
        hidden = occ.blocked_many(EYE_PASSAGE, pts)
        runs = split_runs(pts, hidden)
        assert [h for h, _ in runs] == [False, True], door_open
        visible_end = runs[0][1][-1]  # shared with the hidden run's start
        assert visible_end[1] == pytest.approx(boundary, abs=0.06), (door_open, visible_end)


def test_resample_keeps_the_original_rows_and_interpolates_times():
    rows = np.array([[0.0, 0.0, 0.0], [10.0, 1.0, 0.0], [20.0, 1.0, 0.5]])  # t, x, y
    pts, frac = resample(rows[:, 1:])
    assert np.allclose(pts[0], rows[0, 1:]) and np.allclose(pts[-1], rows[-1, 1:])
    times = np.interp(frac, np.arange(len(rows)), rows[:, 0])
    halfway = np.argmin(np.abs(pts[:, 0] - 0.5))
    assert times[halfway] == pytest.approx(5.0, abs=0.3)
