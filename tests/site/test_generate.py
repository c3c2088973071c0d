"""The site generator: always valid, deterministic for a seed, scaled to the team."""

from __future__ import annotations

import tomllib

import pytest

from protocol.site import loads_site
from runtime.site.generate import generate_site


@pytest.mark.parametrize("robots", range(1, 21))
def test_generated_sites_are_valid_for_1_to_20_robots(robots: int) -> None:
    for seed in (0, 1, 7):
        text = generate_site(robots, 3, seed)
        site = loads_site(text, f"gen{robots}_{seed}.toml")
        assert list(site.robots) == [f"r{i}" for i in range(robots)]
        assert len(site.objects) == 3 * robots
        for i, rid in enumerate(site.robots):
            assert [o.id for o in site.objects.values() if o.robot == rid] == [f"o{3 * i + k}" for k in range(3)]
        assert all(o.deliver_to == "storage" and o.room not in ("storage", "corridor") for o in site.objects.values())
        assert site.human.room == "storage" and site.doors["d_storage"].human_operated
        assert [o for o, _ in site.neighbours("storage")] == ["d_storage"]
        assert len(site.rooms) == max(4, robots + 2) + 2  # + corridor + storage
        assert site.landmarks and all(lm.size == 0.16 for lm in site.landmarks)


def test_same_seed_same_text_other_seed_other_site() -> None:
    a, b = generate_site(5, 3, seed=11), generate_site(5, 3, seed=11)
    assert a == b
    c = generate_site(5, 3, seed=12)
    assert c != a
    assert tomllib.loads(a)["objects"] != tomllib.loads(c)["objects"]


def test_rooms_scale_with_the_team() -> None:
    small, large = loads_site(generate_site(2)), loads_site(generate_site(16))
    assert small.bounds[2] < large.bounds[2]
    assert len(large.rooms) > len(small.rooms)


def test_objects_per_robot_and_options() -> None:
    site = loads_site(generate_site(4, objects_per_robot=5, seed=3, robot_speed=0.8, load_time=4.0, name="bench_a"))
    assert len(site.objects) == 20 and site.name == "bench_a"
    assert site.params.robot_speed == 0.8 and site.params.load_time == 4.0
    empty = loads_site(generate_site(2, objects_per_robot=0))
    assert empty.objects == {}
    wide = loads_site(generate_site(3, room_width=5.0, passage_probability=1.0))
    assert all(o.kind == "passage" for o in wide.openings.values() if o.id != "d_storage" and "corridor" in o.rooms)


def test_bad_arguments_are_refused_by_name() -> None:
    with pytest.raises(ValueError, match="robots must be an integer >= 1"):
        generate_site(0)
    with pytest.raises(ValueError, match="objects_per_robot"):
        generate_site(2, objects_per_robot=-1)
    with pytest.raises(TypeError, match="unknown option 'colour'"):
        generate_site(2, colour="red")
