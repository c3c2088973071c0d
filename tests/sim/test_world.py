"""The pybullet world matches the site it is built from, and answers the engine's questions.

Real pybullet (DIRECT): body extents and poses are read back from pybullet itself, openings are
probed with ray tests, overlaps with pybullet's closest-point queries.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator

import numpy as np
import pytest

from protocol.site import default_site_path, load_site, loads_site
from protocol.site.model import Site
from runtime.apriltag import quad_edge
from runtime.palette import robot_colors
from services.ar_client.overlay import robot_colours as overlay_colours
from services.sim.camera import CameraSpec
from services.sim.objects import CARRY_HEIGHT, FLOOR_HEIGHT
from services.sim.world import LEAF_HEIGHT, ROBOT_HEIGHT, TAG_QUIET_MODULES, World

RAY_Z = 1.0  # m: rays at a height where only walls and leaves stand


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site(None)


@pytest.fixture
def world(site: Site) -> Iterator[World]:
    with World(site) as w:
        yield w


def _extent(world: World, name: str) -> np.ndarray:
    """(xmin, ymin, zmin, xmax, ymax, zmax) of a body's collision shape, from pybullet."""
    lo, hi = world.aabb(name)
    return np.array([*lo, *hi])


def _across(site: Site, opening_id: str, offset: float, reach: float = 0.6) -> tuple[list[float], list[float]]:
    """A ray through the wall at an opening, ``offset`` along the wall from its centre, room to room."""
    o = site.openings[opening_id]
    a, b = o.rooms
    ax, ay = o.beside(a, reach)
    bx, by = o.beside(b, reach)
    dx, dy = (offset, 0.0) if o.axis == "x" else (0.0, offset)
    return [ax + dx, ay + dy, RAY_Z], [bx + dx, by + dy, RAY_Z]


# ---------------------------------------------------------------------- static geometry


def test_every_wall_is_the_site_wall_box(world: World, site: Site) -> None:
    assert len(world.wall_names) == len(site.walls)
    for name, wall in zip(world.wall_names, site.walls, strict=True):
        x0, y0, x1, y1 = wall.box
        np.testing.assert_allclose(_extent(world, name), [x0, y0, 0.0, x1, y1, wall.height], atol=1e-6, err_msg=name)


def test_openings_are_cut_to_their_width(world: World, site: Site) -> None:
    """Through every opening (doors open) a ray passes anywhere across the gap; just beside it, a wall stops it."""
    for did in site.doors:
        world.set_door_opening(did, 1.0)
    for oid, opening in site.openings.items():
        half = opening.width / 2
        # 5 cm clear of the jambs: an open leaf stands at the hinge jamb, 2 cm thick each side.
        for offset in (-half + 0.05, 0.0, half - 0.05):
            assert world.ray(*_across(site, oid, offset)) is None, f"{oid} blocked at {offset:+.2f} m"
        for offset in (-half - 0.03, half + 0.03):
            hit = world.ray(*_across(site, oid, offset))
            assert hit is not None and hit.startswith("wall:"), (
                f"{oid}: nothing beside the gap at {offset:+.2f} m ({hit})"
            )


def test_a_closed_leaf_fills_its_doorway_and_an_open_one_clears_it(world: World, site: Site) -> None:
    for did, leaf in site.door_leaves.items():
        world.set_door_opening(did, 0.0)
        assert world.ray(*_across(site, did, 0.0)) == did
        x0, y0, x1, y1 = leaf.box(open=False)
        np.testing.assert_allclose(_extent(world, did)[[0, 1, 3, 4]], [x0, y0, x1, y1], atol=1e-6)
        world.set_door_opening(did, 1.0)
        assert world.ray(*_across(site, did, 0.0)) is None
        x0, y0, x1, y1 = leaf.box(open=True)
        np.testing.assert_allclose(_extent(world, did)[[0, 1, 3, 4]], [x0, y0, x1, y1], atol=1e-6)
        assert _extent(world, did)[5] - _extent(world, did)[2] == pytest.approx(LEAF_HEIGHT)


def test_a_half_open_leaf_turns_about_its_hinge(world: World, site: Site) -> None:
    leaf = site.door_leaves["d_storage"]
    world.set_door_opening("d_storage", 0.5)
    (cx, cy, _), orn = world.pose_of("d_storage")
    yaw = 2.0 * math.atan2(orn[2], orn[3])
    mid = leaf.closed_yaw + 0.5 * math.atan2(
        math.sin(leaf.open_yaw - leaf.closed_yaw), math.cos(leaf.open_yaw - leaf.closed_yaw)
    )
    assert math.cos(yaw - mid) == pytest.approx(1.0, abs=1e-9)
    # The leaf's near end is still at the hinge.
    assert cx - leaf.length / 2 * math.cos(yaw) == pytest.approx(leaf.hinge[0], abs=1e-9)
    assert cy - leaf.length / 2 * math.sin(yaw) == pytest.approx(leaf.hinge[1], abs=1e-9)
    assert world.door_opening("d_storage") == 0.5
    world.set_door_opening("d_storage", 7.0)  # clamped
    assert world.door_opening("d_storage") == 1.0


def test_landmark_quads_sit_on_the_site_corners(world: World, site: Site) -> None:
    assert sorted(world.landmark_ids) == sorted(lm.tag for lm in site.landmarks)
    for lm in site.landmarks:
        np.testing.assert_allclose(world.landmark_corners(lm.tag), lm.corners(), atol=1e-9, err_msg=f"tag {lm.tag}")
        quad = world.landmark_quad(lm.tag)
        assert np.linalg.norm(quad[1] - quad[0]) == pytest.approx(quad_edge(lm.size, TAG_QUIET_MODULES))
        # The quad lies in the tag's plane, in front of the wall face it hangs on.
        assert np.allclose((quad - np.asarray(lm.position)) @ np.asarray(lm.normal), 0.0, atol=1e-9)


def test_a_landmark_buried_in_a_wall_is_reported(caplog: pytest.LogCaptureFixture) -> None:
    text = (
        default_site_path()
        .read_text(encoding="utf-8")
        .replace("position = [6.44, 0.051, 1.25]", "position = [6.44, 0.03, 1.25]")
    )
    buried = loads_site(text)
    with caplog.at_level(logging.WARNING, logger="services.sim.world"):
        World(buried).close()
    assert any("tag 0 " in r.getMessage() and "inside wall" in r.getMessage() for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="services.sim.world"):
        World(load_site(None)).close()
    assert not [r for r in caplog.records if "inside wall" in r.getMessage()]


# ---------------------------------------------------------------------- moving things


def test_robots_start_where_the_site_puts_them(world: World, site: Site) -> None:
    assert sorted(world.robot_ids) == sorted(site.robots)
    for rid, spec in site.robots.items():
        (x, y, z), orn = world.pose_of(rid)
        assert (x, y, z) == pytest.approx((spec.start[0], spec.start[1], 0.0))
        yaw = 2.0 * math.atan2(orn[2], orn[3])
        assert math.cos(yaw - spec.start[2]) == pytest.approx(1.0, abs=1e-9)
        lo, hi = world.aabb(rid)
        assert hi[0] - lo[0] == pytest.approx(2 * site.params.robot_radius, abs=1e-3)
        assert hi[2] - lo[2] == pytest.approx(ROBOT_HEIGHT, abs=1e-3)


def test_robots_wear_the_shared_palette(world: World, site: Site) -> None:
    """Seen from straight above, a robot's top (behind its heading bar) is its palette colour, the
    colour the AR overlay draws it in."""
    palette = robot_colors(site.robots)
    assert {rid: list(rgb) for rid, rgb in palette.items()} == {
        rid: c[:3] for rid, c in overlay_colours(site.robots).items()
    }
    for rid, rgb in palette.items():
        world.set_robot_pose(rid, 8.5, 2.0, 0.0)
        image = world.render(CameraSpec((8.4, 2.0, 2.0), 0.0, math.radians(-89.0), 48, 48))
        pixel = image[24, 24].astype(float)
        np.testing.assert_allclose(pixel / pixel.max(), np.array(rgb) / max(rgb), atol=0.06, err_msg=rid)
        world.set_robot_pose(rid, *site.robots[rid].start)


def test_a_carried_object_rides_on_its_robot(world: World) -> None:
    world.attach_object("o0", "r0")
    world.set_robot_pose("r0", 3.0, 5.0, 1.0)
    (x, y, z), _ = world.pose_of("o0")
    assert (x, y, z) == pytest.approx((3.0, 5.0, CARRY_HEIGHT))
    assert world.carrier("o0") == "r0"
    world.attach_object("o0", None)
    world.set_robot_pose("r0", 4.0, 5.0, 0.0)  # no longer follows
    assert world.pose_of("o0")[0] == pytest.approx((3.0, 5.0, CARRY_HEIGHT))
    world.set_object_pose("o0", 7.0, 2.0, FLOOR_HEIGHT)
    assert world.pose_of("o0")[0] == pytest.approx((7.0, 2.0, FLOOR_HEIGHT))


def test_unknown_ids_are_named(world: World) -> None:
    with pytest.raises(KeyError, match="r9"):
        world.set_robot_pose("r9", 0, 0, 0)
    with pytest.raises(KeyError, match="d_nowhere"):
        world.set_door_opening("d_nowhere", 1.0)
    with pytest.raises(KeyError, match="o99"):
        world.attach_object("o99", "r0")
    with pytest.raises(KeyError, match="r9"):
        world.attach_object("o0", "r9")


# ---------------------------------------------------------------------- overlaps


def test_robot_blocked_by_a_closed_leaf_not_an_open_one(world: World, site: Site) -> None:
    door = site.doors["d_storage"]
    world.set_robot_pose("r0", *door.center, 0.0)
    world.set_door_opening("d_storage", 0.0)
    assert world.robot_blocked("r0") == "d_storage"
    world.set_door_opening("d_storage", 1.0)
    assert world.robot_blocked("r0") is None
    # Half-way through its swing the leaf sweeps the storage side of the doorway.
    world.set_robot_pose("r0", *door.beside("storage", 0.3), 0.0)
    assert world.robot_blocked("r0") is None
    world.set_door_opening("d_storage", 0.5)
    assert world.robot_blocked("r0") == "d_storage"


def test_robot_blocked_by_walls_exactly_at_its_radius(world: World, site: Site) -> None:
    r = site.params.robot_radius
    face = site.params.wall_thickness / 2  # storage's south wall face at y = +0.05
    world.set_robot_pose("r1", 8.5, face + r + 0.002, 0.0)  # 2 mm clear
    assert world.robot_blocked("r1") is None
    world.set_robot_pose("r1", 8.5, face + r - 0.01, 0.0)  # 1 cm into the wall
    blocked = world.robot_blocked("r1")
    assert blocked is not None and blocked.startswith("wall:")
    x0, y0, x1, y1 = site.walls[int(blocked.split(":")[1])].box
    assert x0 <= 8.5 <= x1 and y0 <= 0.0 <= y1
    world.set_robot_pose("r1", *site.rooms["storage"].center, 0.0)
    assert world.robot_blocked("r1") is None


# ---------------------------------------------------------------------- clients, rendering


def test_worlds_are_independent_clients(site: Site) -> None:
    with World(site) as a, World(site) as b:
        assert a.client != b.client
        a.set_door_opening("d_storage", 1.0)
        assert a.ray(*_across(site, "d_storage", 0.0)) is None
        assert b.ray(*_across(site, "d_storage", 0.0)) == "d_storage"
        a.close()
        image = b.render(CameraSpec((8.5, 2.5, 1.3), -math.pi / 2, 0.0, 64, 48))
        assert image.shape == (48, 64, 3) and image.dtype == np.uint8
    with pytest.raises(RuntimeError, match="closed"):
        a.render(CameraSpec((8.5, 2.5, 1.3), 0.0, 0.0, 64, 48))


def test_the_human_is_seen_but_not_by_her_own_tablet(world: World, site: Site) -> None:
    hx, hy = site.human.position
    own = CameraSpec((hx, hy, 1.3), math.pi, -0.2, 160, 120)  # her tablet, at her position
    other = CameraSpec((hx - 2.0, hy, 1.3), 0.0, 0.0, 160, 120)  # someone 2 m west, looking at her
    world.set_human_pose(hx + 30.0, hy, math.pi)  # out of the building: the frames without her
    without = {"own": world.render(own), "other": world.render(other)}
    world.set_human_pose(hx, hy, math.pi)
    # Her own tablet sees exactly what it would see without her (her arms and tablet left out) ...
    assert np.array_equal(world.render(own), without["own"])
    # ... anyone else sees her, and she is back in place after her own tablet's frame.
    assert (world.render(other) != without["other"]).any(axis=2).sum() > 1000
