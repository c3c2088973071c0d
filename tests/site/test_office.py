"""The packaged default site: it loads, mirrors the paper's setup, and its landmarks serve the tablet."""

from __future__ import annotations

import dataclasses
import math

import pytest

from protocol.site import Site, default_site_path, load_site, loads_site
from tests.site.visibility import poses_seeing_fewer_than, visible_tags


@pytest.fixture(scope="module")
def office() -> Site:
    return load_site()


def test_default_site_loads_from_the_package_and_the_path(office: Site) -> None:
    assert office.name == "office" and office.source == "<packaged office>"
    path = default_site_path()
    assert path.name == "office.toml" and path.is_file()
    assert load_site(path).rooms == office.rooms


def test_office_mirrors_the_paper(office: Site) -> None:
    x0, y0, x1, y1 = office.bounds
    assert (x1 - x0, y1 - y0) == (20.0, 10.0)
    assert "corridor" in office.rooms and len(office.rooms) - 1 >= 5
    door = office.doors["d_storage"]
    assert door.human_operated and "storage" in door.rooms
    assert [o for o, _ in office.neighbours("storage")] == ["d_storage"]  # the human's door is the only way in
    assert office.human.room == "storage"
    assert office.door_leaves["d_storage"].swing_into == "storage"
    assert list(office.robots) == ["r0", "r1", "r2"]
    for rid in office.robots:
        mine = [o for o in office.objects.values() if o.robot == rid]
        assert len(mine) == 3 and all(o.deliver_to == "storage" for o in mine)
        assert len({o.room for o in mine}) == 3  # in different rooms
    assert any(not d.human_operated for d in office.doors.values()) and office.passages
    assert all(lm.size == 0.16 and 1.2 <= lm.position[2] <= 1.6 for lm in office.landmarks)


def test_office_landmarks_hang_just_in_front_of_the_wall_face(office: Site) -> None:
    half = office.params.wall_thickness / 2.0
    for lm in office.landmarks:
        nx, ny = round(math.cos(lm.yaw)), round(math.sin(lm.yaw))
        across = lm.position[0] if nx else lm.position[1]
        wall = round(across - (nx or ny) * half, 1)  # the centre line it hangs on
        assert abs(abs(across - wall) - half - 0.001) < 1e-9, lm


def test_tablet_anywhere_in_storage_facing_any_wall_sees_two_tags(office: Site) -> None:
    bad = poses_seeing_fewer_than(office, "storage", 2)
    assert not bad, f"{len(bad)} tablet poses see fewer than two tags, e.g. {bad[:3]}"


def test_the_visibility_check_notices_missing_tags(office: Site) -> None:
    # Take away the tags on the storage's east wall (facing west): facing it, the tablet sees none.
    east = [lm for lm in office.landmarks if abs(lm.yaw - math.pi) < 0.01]
    assert east
    fewer = dataclasses.replace(office, landmarks=[lm for lm in office.landmarks if lm not in east], _grids={})
    bad = poses_seeing_fewer_than(fewer, "storage", 2)
    assert bad and all(abs(yaw) < 0.01 for _, yaw, _ in bad)
    # Seen from the middle of the room, the east wall's tags are in view; from the corridor, none is.
    assert visible_tags(office, (8.5, 2.0, 1.3), 0.0)
    assert visible_tags(office, (8.5, 5.0, 1.3), -math.pi / 2) == []  # behind the wall


@pytest.mark.parametrize("robots,seed", [(3, 0), (12, 5)])
def test_generated_storage_serves_the_tablet_too(robots: int, seed: int) -> None:
    from runtime.site.generate import generate_site

    site = loads_site(generate_site(robots, seed=seed))
    assert not poses_seeing_fewer_than(site, "storage", 2)


@pytest.mark.parametrize("robots,seed", [(None, None), (8, 4)])
def test_every_room_robot_and_object_connects_on_the_inflated_grid(robots: int | None, seed: int | None) -> None:
    import cv2
    import numpy as np

    from runtime.site.generate import generate_site

    site = load_site() if robots is None else loads_site(generate_site(robots, seed=seed))
    grid = site.occupancy_grid(
        resolution=0.05, open_doors=tuple(site.door_leaves), inflate=site.params.robot_radius + 0.05
    )
    _, labels = cv2.connectedComponents((~grid.occupied).astype(np.uint8), connectivity=8)
    points = (
        [r.center for r in site.rooms.values()]
        + [r.start[:2] for r in site.robots.values()]
        + [o.position for o in site.objects.values()]
    )
    found = {labels[grid.world_to_cell(x, y)] for x, y in points}
    assert 0 not in found, "a room centre, robot or object sits on an occupied cell"
    assert len(found) == 1, "the free space is split: some place cannot be reached"
