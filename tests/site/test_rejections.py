"""Every reason a site is refused has its own small file in bad_sites/, and the message names
the file, the entry and the problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocol.site import SiteError, load_site

BAD = Path(__file__).parent / "bad_sites"

# file stem -> (the entry the message must name, fragments of the problem it must state)
EXPECTED: dict[str, tuple[str, tuple[str, ...]]] = {
    "broken_toml": ("", ("not valid TOML", "line 10")),
    "wrong_type": ('doors[0] (id "d_ac")', ("width", "expected a number", '"wide"')),
    "bool_number": ('doors[0] (id "d_ac")', ("width", "expected a number", "true")),
    "not_finite": ('doors[0] (id "d_ac")', ("width", "finite")),
    "negative_width": ('doors[0] (id "d_ac")', ("width", "greater than 0", "-0.9")),
    "zero_room": ('rooms[1] (id "b")', ("rect", "zero or negative width")),
    "negative_param": ("params", ("robot_speed", "greater than 0")),
    "unknown_key": ('rooms[2] (id "c")', ("unknown key 'colour'",)),
    "unknown_table": ("furniture", ("unknown table 'furniture'",)),
    "unknown_param": ("params", ("unknown key 'robot_colour'",)),
    "missing_key": ('doors[0] (id "d_ac")', ("missing required key 'center'",)),
    "missing_human": ("human", ("missing required table [human]",)),
    "no_robots": ("robots", ("missing required [[robots]]",)),
    "rooms_not_array": ("rooms", ("expected an array of tables [[rooms]]",)),
    "bad_id": ('doors[0] (id "Door-AC")', ("not a valid lower-case ASP constant",)),
    "bad_site_name": ("site", ("name", "cannot be a key namespace")),
    "tag_not_36h11": ("landmarks[0] (tag 600)", ("not in family 36h11",)),
    "overlapping_rooms": ('rooms[1] (id "b")', ('overlaps rooms[0] (id "a")',)),
    "door_off_edge": (
        'doors[1] (id "d_b")',
        ('center (6, 3.3) is not on an edge shared by rooms "c" and "b"', "y = 3 for x in [4, 8]"),
    ),
    "door_rooms_apart": ('doors[1] (id "d_b")', ('not on an edge shared by rooms "a" and "e"', "share no wall")),
    "door_past_edge": (
        'doors[1] (id "d_b")',
        ("width 1 at center (7.7, 3) does not fit", "whole width must lie on it"),
    ),
    "door_at_corner": ('doors[1] (id "d_b")', ("must stay 0.05 m (half a wall) from the ends of the shared edge",)),
    "passage_off_edge": (
        'passages[0] (id "p_a_b")',
        ('not on an edge shared by rooms "a" and "b"', "x = 4 for y in [0, 3]"),
    ),
    "door_unknown_room": ('doors[1] (id "d_b")', ('unknown room "attic"',)),
    "door_too_narrow": ('doors[0] (id "d_ac")', ("width 0.45 is too narrow for a robot of radius 0.25",)),
    "openings_overlap": ('passages[1] (id "p_c_a")', ('overlaps or touches doors[0] (id "d_ac")',)),
    "leaf_does_not_fit": ('doors[2] (id "d_closet")', ('leaf (1 m) does not fit in room "closet"',)),
    "bad_swing_into": ('doors[0] (id "d_ac")', ('swing_into: "b" is not one of the door\'s rooms',)),
    "duplicate_id": ('robots[0] (id "a")', ('id "a" is already used by rooms[0] (id "a")',)),
    "duplicate_passage": ('passages[1] (id "p_a_b")', ('id "p_a_b" is already used by passages[0]',)),
    "duplicate_tag": ("landmarks[1] (tag 0)", ("tag id 0 is already used by landmarks[0] (tag 0)",)),
    "landmark_off_wall": ("landmarks[0] (tag 0)", ("is not on a wall", "0.55 m away")),
    "landmark_yaw": ("landmarks[0] (tag 0)", ("yaw 0.87 is not perpendicular to any wall",)),
    "landmark_faces_wall": ("landmarks[0] (tag 0)", ("faces into the wall at y = 0",)),
    "landmark_outside": ("landmarks[0] (tag 0)", ("faces no room",)),
    "landmark_over_opening": ("landmarks[0] (tag 0)", ('is over passages[0] (id "p_a_b")',)),
    "landmark_past_corner": ("landmarks[0] (tag 0)", ('extends past the corner of room "a"',)),
    "landmark_too_high": ("landmarks[0] (tag 0)", ("not within the wall (0 to 2.5 m)",)),
    "landmark_under_leaf": ("landmarks[0] (tag 0)", ('covered by door "d_ac"\'s leaf when it is open',)),
    "robot_outside": ('robots[0] (id "r0")', ("start (9, 4) is outside every room",)),
    "robot_in_wall": ('robots[0] (id "r0")', ("0.15 m from a wall", "robot radius")),
    "robots_overlap": ('robots[1] (id "r1")', ('overlaps robot "r0"',)),
    "robot_in_swing": ('robots[0] (id "r0")', ('where door "d_ac"\'s leaf swings',)),
    "object_outside": ('objects[0] (id "o0")', ("position (2, -1) is outside every room",)),
    "object_in_wall": ('objects[0] (id "o0")', ("position (4, 0.5) is inside a wall",)),
    "object_near_wall": ('objects[0] (id "o0")', ("0.1 m from a wall", "robot radius")),
    "object_bad_destination": ('objects[0] (id "o0")', ('deliver_to: unknown room "attic"',)),
    "object_bad_robot": ('objects[0] (id "o0")', ('robot: unknown robot "r9"',)),
    "human_outside": ("human", ('position (2, 1) is outside her room "b"',)),
    "human_unknown_room": ("human", ('room: unknown room "attic"',)),
    "unreachable_room": ('rooms[3] (id "vault")', ("is not reachable from the robots' rooms (c)",)),
}


def test_every_bad_file_has_an_expectation_and_every_expectation_a_file() -> None:
    assert sorted(p.stem for p in BAD.glob("*.toml")) == sorted(EXPECTED)


@pytest.mark.parametrize("stem", sorted(EXPECTED))
def test_bad_site_is_refused_naming_entry_and_problem(stem: str) -> None:
    entry, fragments = EXPECTED[stem]
    with pytest.raises(SiteError) as info:
        load_site(BAD / f"{stem}.toml")
    message = str(info.value)
    prefix = f"{stem}.toml: {entry}: " if entry else f"{stem}.toml: "
    assert message.startswith(prefix), message
    for fragment in fragments:
        assert fragment in message, message
    assert info.value.file == f"{stem}.toml" and info.value.entry == entry


def test_site_error_is_a_value_error_so_services_refuse_it_before_starting() -> None:
    assert issubclass(SiteError, ValueError)


def test_missing_file_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(SiteError, match=r"^nowhere\.toml: no such site file"):
        load_site(tmp_path / "nowhere.toml")


def test_the_tiny_site_the_bad_files_derive_from_is_valid() -> None:
    # Each bad file is this file with one thing broken, so this must load.
    load_site(Path(__file__).parent / "tiny.toml")


@pytest.mark.parametrize(
    "text,expected",
    [
        ("rooms = [1, 2]\n", "x.toml: rooms[0]: expected a table, got 1"),
        (
            '[site]\nname = "x"\n[[rooms]]\nid = 5\nrect = [0, 0, 1, 1]\n',
            "x.toml: rooms[0]: id: expected a string, got 5",
        ),
        (
            '[site]\nname = "x"\n[[rooms]]\nid = "a"\nrect = [0, 0, "1", 1]\n',
            'x.toml: rooms[0] (id "a"): rect[2]: expected a number, got "1"',
        ),
        (
            '[site]\nname = "x"\n[[rooms]]\nid = "a"\nrect = [0, 0, 1]\n',
            'x.toml: rooms[0] (id "a"): rect: expected an array of 4 numbers [xmin, ymin, xmax, ymax], got an array '
            "[0, 0, 1]",
        ),
        ("site = 3\n", "x.toml: site: expected a table, got 3"),
    ],
)
def test_odd_shapes_are_refused_by_entry(text: str, expected: str) -> None:
    from protocol.site import loads_site

    with pytest.raises(SiteError) as info:
        loads_site(text, "x.toml")
    assert str(info.value).startswith(expected), str(info.value)


def test_unreadable_files_are_refused_by_name(tmp_path: Path) -> None:
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(SiteError, match=r"^binary\.toml: cannot read"):
        load_site(binary)
    directory = tmp_path / "sub"
    directory.mkdir()
    with pytest.raises(SiteError, match=r"^sub: cannot read"):
        load_site(directory)
