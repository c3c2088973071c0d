"""The constraint library file: the packaged one, a site-specific one, and every way a file can be wrong."""

from __future__ import annotations

import json
import subprocess
from typing import Any

import pytest

from protocol.constraint_library import entries_to_wire
from protocol.site import loads_site
from services.restrictor.library import (
    CONSTRAINT,
    LibraryError,
    library_for_site,
    load_library,
    parse_library,
)
from tests.procs import ROOT, arroch
from tests.restrictor.conftest import HERE, LAB

# ---------------------------------------------------------------------------- building test files


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, str)):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(value)


DOOR = {"name": "door", "type": "door", "label": "Door"}
MINUTES = {"name": "minutes", "type": "int", "label": "Minutes", "min": 1, "max": 60}
BUSY = {
    "id": "busy",
    "label": "Busy",
    "help": "Not now.",
    "window_param": "minutes",
    "asp": ":- human_opens(${door}, T), T >= ${t0}, T < ${t1}.",
    "params": [DOOR, MINUTES],
}
WITHDRAW = {
    "id": "withdraw",
    "label": "Withdraw",
    "help": "Undo.",
    "effect": "cancel",
    "params": [{"name": "which", "type": "constraint", "label": "Which"}],
}


def library_text(*entries: dict, top: str = "") -> str:
    blocks = [top]
    for entry in entries:
        blocks.append("[[entry]]\n" + "\n".join(f"{k} = {toml_value(v)}" for k, v in entry.items() if v is not None))
    return "\n\n".join(blocks)


def with_(base: dict, **changes: Any) -> dict:
    out = dict(base)
    out.update(changes)
    return out


def param(base: dict, **changes: Any) -> dict:
    return {k: v for k, v in with_(base, **changes).items() if v is not None}


# ---------------------------------------------------------------------------- the packaged library


def test_the_packaged_library_has_the_required_entries(library) -> None:
    assert {"door_unavailable", "forbid_room", "door_available_now", "cancel"} <= set(library.entries)
    door_unavailable = library.get("door_unavailable")
    assert door_unavailable.param_names == ("door", "minutes") and door_unavailable.window_param == "minutes"
    assert library.get("forbid_room").param_names == ("room", "minutes")
    assert library.get("door_available_now").param_names == ("door",)
    assert [c.kind for c in library.get("door_available_now").cancels] == ["door_unavailable"]
    assert "cancels" in library.get("door_available_now").help.lower()  # the tablet tells the human
    assert library.get("cancel").params[0].type == CONSTRAINT
    for entry in library.entries.values():
        assert entry.label and entry.help and len(entry.help) <= 300


def test_a_valid_minimal_library_parses() -> None:
    lib = parse_library(library_text(BUSY, WITHDRAW, top="version = 1"), "mine.toml")
    assert list(lib.entries) == ["busy", "withdraw"] and lib.source == "mine.toml"


def test_a_site_specific_library_loads_from_its_path(lab_site) -> None:
    lib = load_library(HERE / "lab_library.toml")
    assert lib.source.endswith("lab_library.toml")
    shown = {e["id"]: e for e in entries_to_wire(library_for_site(lab_site, lib))}
    assert shown["avoid_opening"]["params"][0]["choices"] == ["d_lab", "d_storage", "p_corridor_room_a"]
    # human_operated = false: automatic doors are offered too
    assert shown["door_unavailable"]["params"][0]["choices"] == ["d_lab", "d_storage"]


# ---------------------------------------------------------------------------- library file errors

ERRORS = [
    ("[[entry]\nid = 1", "mine.toml: not valid TOML"),
    ("version = 1", "mine.toml: needs at least one [[entry]]"),
    (library_text(BUSY, top='colour = "red"'), "mine.toml: unknown field(s) colour"),
    (library_text(BUSY, top="version = 2"), "mine.toml: version 2 is not supported"),
    (
        library_text(with_(BUSY, id="Busy-Door")),
        "mine.toml: entry[0] (id 'Busy-Door'): id: 'Busy-Door' is not an identifier",
    ),
    (library_text(BUSY, BUSY), "mine.toml: entry[1] (id 'busy'): duplicate id 'busy'"),
    (library_text(with_(BUSY, label=None)), "entry[0] (id 'busy'): label: required"),
    (library_text(with_(BUSY, label="")), "entry[0] (id 'busy'): label: must not be empty"),
    (library_text(with_(BUSY, label="x" * 81)), "entry[0] (id 'busy'): label: 81 characters, more than 80"),
    (library_text(with_(BUSY, help=3)), "entry[0] (id 'busy'): help: expected a string, got int"),
    (library_text(with_(BUSY, colour="red")), "entry[0] (id 'busy'): unknown field(s) colour"),
    (library_text(with_(BUSY, effect="delete")), "entry[0] (id 'busy'): effect: 'delete' is not one of add, cancel"),
    (
        library_text(with_(BUSY, params=[param(DOOR, type="string"), MINUTES])),
        "entry[0] (id 'busy'): params[0] (name 'door'): type: 'string' is not one of",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, max=None)])),
        "params[1] (name 'minutes'): an int parameter needs both min and max",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, min=5, max=3)])),
        "params[1] (name 'minutes'): min 5 is above max 3",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, min=True)])),
        "params[1] (name 'minutes'): min: expected an integer, got bool",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, max=2**40)])),
        "params[1] (name 'minutes'): range [1, 1099511627776] exceeds ASP integers",
    ),
    (
        library_text(with_(BUSY, params=[param(DOOR, min=1), MINUTES])),
        "params[0] (name 'door'): min/max apply to int parameters only",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, human_operated=True)])),
        "params[1] (name 'minutes'): human_operated applies to door parameters only",
    ),
    (
        library_text(with_(BUSY, params=[param(DOOR, human_operated="yes"), MINUTES])),
        "params[0] (name 'door'): human_operated: expected true or false",
    ),
    (
        library_text(with_(BUSY, params=[param(DOOR, name="kind"), MINUTES])),
        "params[0] (name 'kind'): name: 'kind' is reserved",
    ),
    (
        library_text(with_(BUSY, params=[param(DOOR, name="t0"), MINUTES])),
        "params[0] (name 't0'): name: 't0' is reserved for the window",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, DOOR, MINUTES])),
        "params[1] (name 'door'): duplicate parameter name 'door'",
    ),
    (library_text(with_(BUSY, params=[param(DOOR, label=None), MINUTES])), "params[0] (name 'door'): label: required"),
    (
        library_text(with_(BUSY, params=[param(DOOR, colour=1), MINUTES])),
        "params[0] (name 'door'): unknown field(s) colour",
    ),
    (library_text(with_(BUSY, params=["door"])), "params[0]: expected a table, got str"),
    (library_text(with_(BUSY, window_minutes=5)), "entry[0] (id 'busy'): needs exactly one of window_param"),
    (library_text(with_(BUSY, window_param=None)), "entry[0] (id 'busy'): needs exactly one of window_param"),
    (
        library_text(with_(BUSY, window_param="door")),
        "entry[0] (id 'busy'): window_param: 'door' is not an int parameter",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, param(MINUTES, min=0)])),
        "window_param: minutes must range within [1, 10080] minutes",
    ),
    (
        library_text(
            with_(
                BUSY, window_param=None, window_minutes=0, asp=":- human_opens(${door}, T), T < ${t1}.", params=[DOOR]
            )
        ),
        "window_minutes: 0 is outside [1, 10080]",
    ),
    (library_text(with_(BUSY, asp=None)), "entry[0] (id 'busy'): asp: required"),
    (
        library_text(with_(BUSY, asp=":- robot_in(R, ${room}, S, E).")),
        "asp: placeholder(s) room are neither parameters nor t0/t1",
    ),
    (
        library_text(with_(BUSY, asp=":- human_opens(${door}, T), T < $5.")),
        "asp: a '$' that is not a ${name} placeholder",
    ),
    (
        library_text(with_(BUSY, asp=":- human_opens(d, T), T < ${t1}.")),
        "asp: parameter(s) door are not used by the template",
    ),
    (
        library_text(with_(BUSY, asp="blocked(${door}, ${t0}, ${t1}).")),
        "asp: predicate(s) blocked/3 are not in the shared vocabulary",
    ),
    (
        library_text(with_(BUSY, asp="#include <incmode>.\n:- human_opens(${door}, ${t0}).")),
        "asp: directive #include is not allowed",
    ),
    (
        library_text(with_(BUSY, asp="#script (python)\n#end.\n:- human_opens(${door}, ${t0}).")),
        "asp: directive #script is not allowed",
    ),
    (library_text(with_(BUSY, asp=":- human_opens(${door}, ${t0}). % why")), "asp: comments ('%') are not allowed"),
    (library_text(with_(BUSY, asp=":- human_opens(${door}, ${t0})")), "asp: not valid ASP"),
    (
        library_text(with_(WITHDRAW, asp=":- human_opens(d, 1).")),
        "entry[0] (id 'withdraw'): asp: a cancel entry has no asp",
    ),
    (
        library_text(with_(WITHDRAW, params=[DOOR])),
        "entry[0] (id 'withdraw'): params: a cancel entry takes exactly one parameter, of type constraint",
    ),
    (
        library_text(with_(BUSY, params=[DOOR, MINUTES, {"name": "which", "type": "constraint", "label": "W"}])),
        "entry[0] (id 'busy'): params: which is of type constraint, which only a cancel entry takes",
    ),
    (
        library_text(with_(BUSY, cancels=[{"kind": "nope", "same": ["door"]}])),
        "entry[0] (id 'busy'): cancels[0]: kind: 'nope' is not an entry",
    ),
    (
        library_text(with_(BUSY, cancels=[{"kind": "busy", "same": ["room"]}])),
        "cancels[0]: same: 'room' must be a parameter of both busy and busy",
    ),
    (
        library_text(with_(BUSY, cancels=[{"kind": "withdraw"}]), WITHDRAW),
        "cancels[0]: kind: 'withdraw' is a cancel entry",
    ),
    (library_text(with_(BUSY, cancels=[{"kind": "busy", "when": 1}])), "cancels[0]: unknown field(s) when"),
    (library_text(with_(BUSY, cancels="busy")), "cancels: expected a list of tables, got str"),
]


@pytest.mark.parametrize("text,message", ERRORS, ids=[m[1].split(": ", 1)[-1][:50] for m in ERRORS])
def test_library_file_errors_name_the_file_entry_and_field(text: str, message: str) -> None:
    with pytest.raises(LibraryError) as info:
        parse_library(text, "mine.toml")
    assert str(info.value).startswith("mine.toml: ")
    assert message in str(info.value)


def test_a_missing_library_file_is_reported_with_its_path(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.toml"):
        load_library(tmp_path / "nope.toml")


def test_a_broken_library_on_disk_is_named_by_its_file(tmp_path) -> None:
    path = tmp_path / "site_lib.toml"
    path.write_text(library_text(with_(BUSY, asp="p(${door}, ${t0}).")))
    with pytest.raises(LibraryError, match=r"^site_lib.toml: entry\[0\] \(id 'busy'\): asp: predicate\(s\) p/2"):
        load_library(path)


# ---------------------------------------------------------------------------- the library for a site


def test_library_for_site_resolves_the_sites_choices(lab_site, library) -> None:
    shown = {entry["id"]: entry for entry in entries_to_wire(library_for_site(lab_site, library))}
    json.dumps(shown)  # plain JSON data
    door, minutes = shown["door_unavailable"]["params"]
    assert door == {
        "name": "door",
        "type": "door",
        "label": "Door",
        "help": door["help"],
        "choices": ["d_storage"],
        "source": "site",
    }
    assert (minutes["type"], minutes["min"], minutes["max"]) == ("int", 1, 240)
    assert shown["forbid_room"]["params"][0]["choices"] == ["corridor", "lab", "room_a", "storage"]
    assert shown["cancel"]["params"][0] == {
        "name": "constraint_id",
        "type": "constraint",
        "label": "Constraint",
        "help": shown["cancel"]["params"][0]["help"],
        "choices": None,
        "source": "constraints",
    }
    assert shown["door_unavailable"]["window"] == {"param": "minutes"}
    assert shown["door_available_now"]["window"] == {"minutes": 10}
    assert shown["cancel"]["window"] is None and shown["cancel"]["effect"] == "cancel"
    assert all(entry["usable"] for entry in shown.values())


def test_entries_without_choices_on_a_site_are_marked_unusable(library) -> None:
    site = loads_site(LAB.read_text().replace("human_operated = true", "human_operated = false"), "no_human_doors.toml")
    shown = {entry["id"]: entry for entry in entries_to_wire(library_for_site(site, library))}
    assert shown["door_unavailable"]["params"][0]["choices"] == []
    assert not shown["door_unavailable"]["usable"] and not shown["door_available_now"]["usable"]
    assert shown["forbid_room"]["usable"] and shown["cancel"]["usable"]


def test_the_library_command_prints_the_same_json(lab_site, library) -> None:
    out = subprocess.run(
        arroch("constraints", "library", "--site", str(LAB), "--json"),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == entries_to_wire(library_for_site(lab_site, library))
    text = subprocess.run(
        arroch("constraints", "library", "--site", str(LAB), "--library", str(HERE / "lab_library.toml")),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert text.returncode == 0 and "avoid_opening" in text.stdout and "p_corridor_room_a" in text.stdout


def test_the_library_command_reports_a_bad_library_and_exits_2(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(library_text(with_(BUSY, effect="explode")))
    out = subprocess.run(
        arroch("constraints", "library", "--site", str(LAB), "--library", str(path)),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert "bad.toml: entry[0] (id 'busy'): effect: 'explode'" in out.stderr
