"""Derived geometry of the tiny site against values computed by hand (see tiny.toml)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from protocol.site import Site, load_site

TINY = Path(__file__).parent / "tiny.toml"


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site(TINY)


def test_rooms_and_lookup(site: Site) -> None:
    assert list(site.rooms) == ["a", "b", "c"]
    assert site.rooms["c"].center == (4.0, 4.0)
    assert site.room_at(6.0, 1.0).id == "b"
    assert site.room_at(1.0, 4.5).id == "c"
    assert site.room_at(9.0, 1.0) is None
    assert site.rooms["a"].contains(0.2, 0.2) and not site.rooms["a"].contains(0.2, 0.2, margin=0.25)
    assert site.bounds == (0.0, 0.0, 8.0, 5.0)


def test_walls_merge_shared_edges_and_cut_openings(site: Site) -> None:
    got = sorted((w.a, w.b, w.box) for w in site.walls)
    h = 0.05
    expected = sorted(
        [
            ((0.0, 0.0), (8.0, 0.0), (-h, -h, 8.0 + h, h)),  # a's and b's south edges, one wall
            ((0.0, 3.0), (1.55, 3.0), (-h, 3.0 - h, 1.55, 3.0 + h)),  # up to d_ac's jamb (no extension into the gap)
            ((2.45, 3.0), (5.5, 3.0), (2.45, 3.0 - h, 5.5, 3.0 + h)),  # between d_ac and d_b
            ((6.5, 3.0), (8.0, 3.0), (6.5, 3.0 - h, 8.0 + h, 3.0 + h)),
            ((0.0, 5.0), (8.0, 5.0), (-h, 5.0 - h, 8.0 + h, 5.0 + h)),
            ((0.0, 0.0), (0.0, 5.0), (-h, -h, h, 5.0 + h)),  # a's and c's west edges, merged
            ((4.0, 0.0), (4.0, 1.0), (4.0 - h, -h, 4.0 + h, 1.0)),  # a|b wall, below the passage
            ((4.0, 2.0), (4.0, 3.0), (4.0 - h, 2.0, 4.0 + h, 3.0 + h)),  # above it
            ((8.0, 0.0), (8.0, 5.0), (8.0 - h, -h, 8.0 + h, 5.0 + h)),
        ]
    )
    assert len(got) == len(expected)
    for (ga, gb, gbox), (ea, eb, ebox) in zip(got, expected, strict=True):
        assert ga == pytest.approx(ea) and gb == pytest.approx(eb) and gbox == pytest.approx(ebox)
    assert all(w.thickness == 0.1 and w.height == 2.5 for w in site.walls)
    assert {w.axis for w in site.walls if w.a[0] == 4.0} == {"y"}


def test_openings(site: Site) -> None:
    d = site.opening("d_ac")
    assert (d.kind, d.axis, d.rooms, d.human_operated) == ("door", "x", ("c", "a"), False)
    assert d.endpoints == ((1.55, 3.0), (2.45, 3.0))
    assert d.normal_into("a") == (0.0, -1.0) and d.normal_into("c") == (0.0, 1.0)
    assert d.beside("c", 0.5) == (2.0, 3.5) and d.beside("a", 0.6) == pytest.approx((2.0, 2.4))
    p = site.opening("p_a_b")
    assert (p.kind, p.axis, p.width) == ("passage", "y", 1.0)
    assert p.endpoints == ((4.0, 1.0), (4.0, 2.0))
    assert p.normal_into("b") == (1.0, 0.0)
    assert site.opening("p_b_a") is p  # default passage ids work in either order
    assert site.doors.keys() == {"d_ac", "d_b"} and site.passages.keys() == {"p_a_b"}
    assert site.opening("d_b").human_operated
    with pytest.raises(ValueError, match="does not connect room 'b'"):
        d.normal_into("b")
    with pytest.raises(KeyError, match="no door or passage 'p_a_c'"):
        site.opening("p_a_c")


def test_adjacency(site: Site) -> None:
    assert site.neighbours("a") == [("d_ac", "c"), ("p_a_b", "b")]
    assert site.neighbours("c") == [("d_ac", "a"), ("d_b", "b")]
    assert site.neighbours("b") == [("d_b", "c"), ("p_a_b", "a")]


def test_door_leaves(site: Site) -> None:
    ac = site.door_leaves["d_ac"]
    # Hinge at the gap's west end; an ordinary door swings into its second room (a, south).
    assert (ac.hinge, ac.length, ac.swing_into) == ((1.55, 3.0), 0.9, "a")
    assert ac.closed_yaw == 0.0 and ac.open_yaw == pytest.approx(-math.pi / 2)
    assert ac.tip(open=False) == pytest.approx((2.45, 3.0))
    assert ac.tip(open=True) == pytest.approx((1.55, 2.1))
    assert ac.box(open=False) == pytest.approx((1.55, 2.98, 2.45, 3.02))
    assert ac.box(open=True) == pytest.approx((1.53, 2.1, 1.57, 3.0))
    b = site.door_leaves["d_b"]
    # The human-operated door swings into the human's room (b).
    assert (b.hinge, b.swing_into) == ((5.5, 3.0), "b")
    assert set(site.door_leaves) == {"d_ac", "d_b"}


def test_landmark_corners_tl_tr_br_bl_seen_from_the_front(site: Site) -> None:
    (lm,) = site.landmarks
    # On a's south wall, facing north: a viewer looking south has east (+x) on her left.
    expected = np.array(
        [
            [1.08, 0.051, 1.38],  # TL
            [0.92, 0.051, 1.38],  # TR
            [0.92, 0.051, 1.22],  # BR
            [1.08, 0.051, 1.22],  # BL
        ]
    )
    np.testing.assert_allclose(lm.corners(), expected, atol=1e-12)
    np.testing.assert_allclose(lm.corners(printed=True)[0], [1.1, 0.051, 1.4], atol=1e-12)
    # The corner order is clockwise as seen from the front: (TR - TL) x (BL - TL) points at the viewer.
    c = lm.corners()
    assert np.dot(np.cross(c[1] - c[0], c[3] - c[0]), lm.normal) < 0


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, math.pi, -math.pi / 2])
def test_corners_for_every_facing(yaw: float) -> None:
    from protocol.site import Landmark

    lm = Landmark(tag=1, size=0.2, position=(0.0, 0.0, 1.0), yaw=yaw)
    tl, tr, br, bl = lm.corners()
    n = np.array(lm.normal)
    right = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    assert np.allclose(tr - tl, 0.2 * right) and np.allclose(tl - bl, [0, 0, 0.2]) and np.allclose(br - bl, 0.2 * right)
    # A viewer in front (at p + n) looking at -n sees TR to the right of TL: right = (-n) x up.
    assert np.allclose(np.cross(-n, [0, 0, 1]), right)


def test_objects_robots_human(site: Site) -> None:
    assert site.robots["r0"].room == "c" and site.robots["r0"].start == (1.0, 4.0, 0.0)
    o = site.objects["o0"]
    assert (o.room, o.deliver_to, o.robot, o.position) == ("a", "b", "r0", (2.0, 1.5))
    assert (site.human.room, site.human.position) == ("b", (7.0, 1.0))
    assert site.params.robot_radius == 0.25 and site.params.wall_height == 2.5


def test_occupancy_grid_cells_and_obstacles(site: Site) -> None:
    g = site.occupancy_grid(resolution=0.1)
    # Margin half a wall plus a cell around the 8 x 5 m building.
    assert g.origin == pytest.approx((-0.15, -0.15)) and g.shape == (53, 83)
    assert g.world_to_cell(0.0, 0.0) == (1, 1) and g.cell_to_world(1, 1) == pytest.approx((0.0, 0.0))
    assert g.world_to_cell(*g.cell_to_world(20, 30)) == (20, 30)
    assert g.is_free(1.0, 1.0) and g.is_free(6.0, 4.0)
    assert not g.is_free(4.0, 0.5)  # the a|b wall
    assert not g.is_free(8.04, 2.0) and not g.is_free(-0.12, 1.0) and not g.is_free(100.0, 1.0)
    assert g.is_free(4.0, 1.5)  # in the passage
    assert not g.is_free(2.0, 3.0)  # d_ac closed
    assert g.occupied.dtype == bool and not g.occupied.flags.writeable


def test_open_doors_free_the_gap_and_place_the_leaf(site: Site) -> None:
    closed = site.occupancy_grid(resolution=0.05)
    opened = site.occupancy_grid(resolution=0.05, open_doors=["d_ac"])
    assert not closed.is_free(2.0, 3.0) and opened.is_free(2.0, 3.0)
    assert closed.is_free(1.55, 2.5) and not opened.is_free(1.55, 2.5)  # the open leaf stands there
    assert not opened.is_free(6.0, 3.0)  # d_b still closed
    assert site.occupancy_grid(resolution=0.05) is closed  # cached
    with pytest.raises(ValueError, match="unknown door.*d_zz"):
        site.occupancy_grid(open_doors=["d_zz"])
    with pytest.raises(ValueError, match="resolution"):
        site.occupancy_grid(resolution=0.0)


def test_inflation_keeps_a_robot_centre_off_the_walls(site: Site) -> None:
    g = site.occupancy_grid(resolution=0.05, inflate=0.25)
    assert g.inflation == 0.25
    assert g.is_free(4.0, 1.5)  # middle of the 1 m passage: 0.5 m from each jamb
    assert not g.is_free(4.0, 1.2)  # 0.2 m from the jamb at y = 1
    assert not g.is_free(1.0, 0.25)  # 0.2 m from the south wall face
    assert g.is_free(1.0, 0.4)  # 0.35 m from it
    # Every free cell's centre is at least the radius from every wall box.
    from protocol.site.geometry import box_distance

    rows, cols = np.nonzero(~g.occupied)
    for r, c in list(zip(rows, cols, strict=True))[::37]:
        x, y = g.cell_to_world(int(r), int(c))
        assert min(box_distance(w.box, x, y) for w in site.walls) >= 0.25 - 1e-9
    # The passage stays passable: a free path of cells across x = 4.
    col = g.world_to_cell(4.0, 1.5)[1]
    assert (~g.occupied[:, col]).sum() >= 3
