"""Validation first: every refusal reason, and no client text ever reaching the solver."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.asp_check import check_program
from services.restrictor.compile import Compiled, compile_feedback
from services.restrictor.library import CONSTRAINT, INT, site_choices
from services.restrictor.validate import Refusal, Validated, split_tablet_feedback, validate
from tests.restrictor.helpers import valid_params

ACTIVE = ("c1", "c7")


def refusal(library, site, kind, params, active=ACTIVE) -> str:
    with pytest.raises(Refusal) as info:
        validate(kind, params, library, site, active)
    return info.value.reason


# ---------------------------------------------------------------------------- accepted


def test_valid_feedback_for_every_entry_is_accepted(library, lab_site) -> None:
    for entry in library.entries.values():
        params = valid_params(entry, lab_site, ACTIVE)
        result = validate(entry.id, params, library, lab_site, ACTIVE)
        assert isinstance(result, Validated) and result.entry is entry and result.values == params


def test_a_passage_may_be_named_either_way_round(lab_site) -> None:
    from services.restrictor.library import load_library
    from tests.restrictor.conftest import HERE

    lib = load_library(HERE / "lab_library.toml")
    result = validate("avoid_opening", {"opening": "p_room_a_corridor", "minutes": 3}, lib, lab_site)
    assert result.values["opening"] == "p_corridor_room_a"  # the site's id is what reaches the ASP


# ---------------------------------------------------------------------------- every refusal reason

REASONS = [
    # (kind, params, expected reason)
    (
        "door_closed",
        {"door": "d_storage"},
        "unknown constraint kind 'door_closed'; the library has: door_unavailable, forbid_room, door_available_now, "
        "cancel",
    ),
    (7, {}, "kind must name a library entry, got int"),
    (None, {}, "kind must name a library entry, got NoneType"),
    ("door_unavailable", ["d_storage", 4], "door_unavailable: parameters must be a map, got list"),
    ("door_unavailable", {"door": "d_storage"}, "door_unavailable: missing parameter minutes (Minutes)"),
    ("door_unavailable", {"minutes": 4}, "door_unavailable: missing parameter door (Door)"),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": 4, "robot": "r0"},
        "door_unavailable: unknown parameter(s) 'robot'; it takes: door, minutes",
    ),
    (
        "door_available_now",
        {"door": "d_storage", "minutes": 4},
        "door_available_now: unknown parameter(s) 'minutes'; it takes: door",
    ),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": True},
        "door_unavailable: minutes must be an integer, got a boolean",
    ),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": 4.0},
        "door_unavailable: minutes must be an integer, got the number 4.0",
    ),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": 4.5},
        "door_unavailable: minutes must be an integer, got the number 4.5",
    ),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": "4"},
        "door_unavailable: minutes must be an integer, got the text '4'",
    ),
    ("door_unavailable", {"door": "d_storage", "minutes": 0}, "door_unavailable: minutes 0 is below the minimum 1"),
    ("door_unavailable", {"door": "d_storage", "minutes": -3}, "door_unavailable: minutes -3 is below the minimum 1"),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": 241},
        "door_unavailable: minutes 241 is above the maximum 240",
    ),
    (
        "door_unavailable",
        {"door": "d_storage", "minutes": 2**70},
        "door_unavailable: minutes 1180591620717411303424 is above the maximum 240",
    ),
    ("door_unavailable", {"door": 3, "minutes": 4}, "door_unavailable: door must be a door id, got the number 3"),
    ("door_unavailable", {"door": True, "minutes": 4}, "door_unavailable: door must be a door id, got a boolean"),
    (
        "door_unavailable",
        {"door": "d_kitchen", "minutes": 4},
        "door_unavailable: site lab has no door 'd_kitchen'; choices: d_storage",
    ),
    (
        "door_unavailable",
        {"door": "storage", "minutes": 4},
        "door_unavailable: site lab has no door 'storage'; choices: d_storage",
    ),
    (
        "door_unavailable",
        {"door": "d_lab", "minutes": 4},
        "door_unavailable: door d_lab is not human-operated (robots open it themselves); choices: d_storage",
    ),
    (
        "forbid_room",
        {"room": "kitchen", "minutes": 4},
        "forbid_room: site lab has no room 'kitchen'; choices: corridor, lab, room_a, storage",
    ),
    ("forbid_room", {"room": "d_storage", "minutes": 4}, "forbid_room: site lab has no room 'd_storage'"),
    ("cancel", {"constraint_id": "c3"}, "cancel: no active constraint c3 (it may have expired or been withdrawn)"),
    (
        "cancel",
        {"constraint_id": "c1; human_opens(d,1)."},
        "cancel: constraint_id 'c1; human_opens(d,1).' is not a constraint id (like c12)",
    ),
    ("cancel", {"constraint_id": 1}, "cancel: constraint_id must be a constraint id, got the number 1"),
]


@pytest.mark.parametrize("kind,params,reason", REASONS, ids=[r[2][:60] for r in REASONS])
def test_every_refusal_reason(library, lab_site, kind, params, reason: str) -> None:
    assert refusal(library, lab_site, kind, params).startswith(reason)


def test_a_site_id_that_is_not_an_asp_constant_is_refused_not_written(library, lab_site) -> None:
    import dataclasses

    # The site loader only takes lower-case ASP constants; a Site built another way (e.g. by a
    # generator) is checked again here, so a bad id can never be written into a constraint.
    site = dataclasses.replace(lab_site, rooms={**lab_site.rooms, "Room_A": lab_site.rooms["room_a"]})
    assert "Room_A" not in site_choices(library.get("forbid_room").params[0], site)
    assert (
        refusal(library, site, "forbid_room", {"room": "Room_A", "minutes": 4})
        == "forbid_room: room 'Room_A' is not an ASP constant, so it cannot be used in a constraint"
    )


def test_offline_a_cancel_is_only_checked_for_shape(library, lab_site) -> None:
    assert validate("cancel", {"constraint_id": "c99"}, library, lab_site, None).values == {"constraint_id": "c99"}
    with pytest.raises(Refusal):
        validate("cancel", {"constraint_id": "c99 x"}, library, lab_site, None)


def test_the_tablet_json_form(library) -> None:
    assert split_tablet_feedback({"kind": "door_unavailable", "door": "d_storage", "minutes": 4}) == (
        "door_unavailable",
        {"door": "d_storage", "minutes": 4},
    )
    for data, reason in [
        ([1, 2], "feedback must be a JSON object, got list"),
        ({"door": "d_storage"}, 'feedback needs a "kind"'),
        ({"kind": "forbid_room", "room": {"id": "lab"}}, "parameter 'room' must be a number or an id, got dict"),
        ({"kind": "forbid_room", "room": None}, "parameter 'room' must be a number or an id, got NoneType"),
        ({"kind": "forbid_room", "room": ["lab"]}, "parameter 'room' must be a number or an id, got list"),
    ]:
        with pytest.raises(Refusal, match=reason.replace("(", r"\(").replace(")", r"\)")):
            split_tablet_feedback(data)


# ---------------------------------------------------------------------------- injection corpus

INJECTIONS = [
    "d_storage. human_opens(d_storage, 0).",
    "d_storage, 0, 1). :- human_opens(X, Y",
    "d_storage) :- human_opens(d_storage",
    ":- human_opens(d_storage, T).",
    "d_storage.",
    "d_storage % the rest is a comment",
    "%",
    "%* block *% d_storage",
    '#include "/etc/passwd".',
    "#include <incmode>.",
    "#script (python)\nimport os\nos.system('touch /tmp/arroch_pwned')\n#end.",
    "#const d_storage = room_a.",
    "#show.",
    "#program base.",
    '"d_storage"',
    "'d_storage'",
    "d_storage\n:- human_opens(D, T).",
    "d_storage\r\nhuman_opens(d_storage, 1).",
    "d_storage\n",
    " d_storage",
    "d_storage\t",
    "d_storage\x00",
    "d_st\u043erage",  # Cyrillic o
    "\uff44_storage",  # full-width d
    "d_storage\u200b",  # zero-width space
    "\u202ed_storage",  # right-to-left override
    "D_storage",  # a variable, not a constant
    "_",
    "X",
    "not",
    "d_storage;room_a",
    "(d_storage;room_a)",
    "1..100",
    "@system(1)",
    "&diff{ a }",
    "${t0}",
    "$door",
    "${door}",
    "",
    "a" * 10_000,
]
NUMERIC_INJECTIONS = [
    True,
    False,
    4.0,
    1e308,
    -0.0,
    "4",
    "4).",
    "4. human_opens(d_storage, 1)",
    "0x10",
    "1e3",
    2**31,
    -(2**31),
    2**64,
]


def _all_slots(library, site):
    """(entry, parameter) for every parameter of every entry."""
    for entry in library.entries.values():
        for param in entry.params:
            yield entry, param


@pytest.mark.parametrize("bad", INJECTIONS, ids=range(len(INJECTIONS)))
def test_injected_text_through_every_parameter_is_refused(library, lab_site, bad: str) -> None:
    for entry, param in _all_slots(library, lab_site):
        params = valid_params(entry, lab_site, ACTIVE)
        params[param.name] = bad
        with pytest.raises(Refusal):
            compile_feedback(entry.id, params, library, lab_site, 100.0, ACTIVE)


@pytest.mark.parametrize("bad", NUMERIC_INJECTIONS, ids=range(len(NUMERIC_INJECTIONS)))
def test_non_integers_and_huge_numbers_through_int_parameters_are_refused(library, lab_site, bad) -> None:
    slots = [(e, p) for e, p in _all_slots(library, lab_site) if p.type == INT]
    assert slots
    for entry, param in slots:
        params = valid_params(entry, lab_site, ACTIVE)
        params[param.name] = bad
        with pytest.raises(Refusal):
            compile_feedback(entry.id, params, library, lab_site, 100.0, ACTIVE)


@pytest.mark.parametrize(
    "bad", INJECTIONS + ["door_unavailable ", "Door_unavailable", "door_unavailable."], ids=range(len(INJECTIONS) + 3)
)
def test_injected_text_through_the_kind_is_refused(library, lab_site, bad: str) -> None:
    params = valid_params(library.get("door_unavailable"), lab_site)
    with pytest.raises(Refusal) as info:
        compile_feedback(bad, params, library, lab_site, 100.0, ACTIVE)
    assert info.value.reason.startswith("unknown constraint kind")
    assert "\n" not in info.value.reason and len(info.value.reason) < 300


def test_injected_parameter_names_are_refused(library, lab_site) -> None:
    for name in ["door).\nhuman_opens(d_storage, 1", "t0", "t1", "kind", "#include", "${door}"]:
        params = valid_params(library.get("door_unavailable"), lab_site)
        params[name] = "d_storage"
        with pytest.raises(Refusal, match="unknown parameter"):
            compile_feedback("door_unavailable", params, library, lab_site, 100.0, ACTIVE)


def test_reasons_quote_client_text_safely(library, lab_site) -> None:
    reason = refusal(
        library, lab_site, "forbid_room", {"room": "x\n:- human_opens(D,T).\u202e" + "y" * 500, "minutes": 4}
    )
    assert reason.isascii() and "\n" not in reason and len(reason) < 300


@settings(max_examples=300, deadline=None)
@given(
    value=st.one_of(
        st.text(max_size=40), st.sampled_from(["d_storage", "d_lab", "room_a", "storage", "lab", "corridor"])
    ),
    slot=st.integers(min_value=0, max_value=100),
)
def test_any_text_is_accepted_exactly_when_it_is_a_site_choice(library, lab_site, value: str, slot: int) -> None:
    symbol_slots = [(e, p) for e, p in _all_slots(library, lab_site) if p.type not in (INT, CONSTRAINT)]
    entry, param = symbol_slots[slot % len(symbol_slots)]
    params = valid_params(entry, lab_site, ACTIVE)
    params[param.name] = value
    try:
        result = compile_feedback(entry.id, params, library, lab_site, 100.0, ACTIVE)
    except Refusal:
        assert value not in site_choices(param, lab_site)
        return
    assert value in site_choices(param, lab_site)
    assert isinstance(result, Compiled)
    check_program(result.asp)  # over the vocabulary, with nothing but site ids and integers
    assert value in result.asp
