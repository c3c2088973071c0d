"""Templates → ASP: windows, clingo accepting every entry's ASP, and each constraint's intended effect
on a small planning program over the shared vocabulary (run with real clingo)."""

from __future__ import annotations

import json
import math
import subprocess

import pytest

from protocol.asp_vocabulary import ASP_INT_MAX
from services.restrictor.compile import Compiled, compile_feedback, window
from services.restrictor.library import ADD, load_library
from services.restrictor.validate import Refusal
from tests.procs import ROOT, arroch
from tests.restrictor.conftest import HERE, LAB
from tests.restrictor.helpers import answer_sets, possible, valid_params, values_of

# ---------------------------------------------------------------------------- the toy planning programs
# The planner defines human_opens/2, robot_in/4 and goes_through/3 for the plan it solves; these
# programs define them over a few choices, so a constraint's effect shows in the answer sets.

SLOTS = "slot(0..20).\n"  # 30-second slots: times 0, 30, ..., 600

DOOR_PLAN = (
    SLOTS
    + """
door(d_storage; d_lab).
1 { human_opens(D, S * 30) : slot(S) } 1 :- door(D).
"""
)

ROOM_PLAN = (
    SLOTS
    + """
room(room_a; lab).
% robot r0 visits one room for one minute, starting at some slot
1 { visit(Room, S * 30) : room(Room), slot(S) } 1.
robot_in(r0, Room, T, T + 60) :- visit(Room, T).
"""
)

OPENING_PLAN = (
    SLOTS
    + """
opening(d_storage; p_corridor_room_a).
1 { goes_through(r0, X, S * 30) : opening(X), slot(S) } 1.
"""
)

# The planner's reading of human_available (preferred, not forced), for the door_available_now test.
PREFER_OFFERED = """
offered(D, T) :- human_opens(D, T), human_available(D, T0, T1), T >= T0, T < T1.
#minimize { 1@2, D : human_opens(D, T), not offered(D, T) }.
#minimize { T@1, D : human_opens(D, T) }.
#defined human_available/3.
"""

ALL_TIMES = {str(s * 30) for s in range(21)}


def compiled(library, site, kind: str, now: float, **params) -> Compiled:
    result = compile_feedback(kind, params, library, site, now)
    assert isinstance(result, Compiled)
    return result


# ---------------------------------------------------------------------------- windows


@pytest.mark.parametrize(
    "now,minutes,expected",
    [
        (0.0, 1, (0, 60)),
        (100.0, 4, (100, 340)),
        (100.25, 4, (100, 341)),  # floor the start, ceil the end: the window covers [now, now + 240)
        (99.999, 1, (99, 160)),
        (1_795_000_000.5, 240, (1_795_000_000, 1_795_014_401)),  # wall-clock seconds still fit ASP integers
    ],
)
def test_windows_are_widened_to_whole_seconds(now: float, minutes: int, expected: tuple[int, int]) -> None:
    start, end = window(now, minutes)
    assert (start, end) == expected
    assert start <= now and end >= now + 60 * minutes


def test_a_window_beyond_asp_integers_is_refused() -> None:
    with pytest.raises(Refusal, match="does not fit ASP integers"):
        window(float(ASP_INT_MAX - 100), 4)
    with pytest.raises(Refusal):
        window(math.nan, 4)


# ---------------------------------------------------------------------------- every entry


def test_every_add_entry_compiles_to_asp_clingo_accepts(library, lab_site) -> None:
    for library_ in (library, load_library(HERE / "lab_library.toml")):
        for entry in library_.entries.values():
            if entry.effect != ADD:
                continue
            result = compiled(library_, lab_site, entry.id, 123.4, **valid_params(entry, lab_site))
            assert (result.start, result.end)[0] == 123
            # alone (atoms the planner would define are simply false), and with plan programs
            assert (
                possible(result.asp, "#defined human_opens/2. #defined robot_in/4. #defined goes_through/3.")
                is not None
            )
            assert possible(DOOR_PLAN, ROOM_PLAN, OPENING_PLAN, result.asp)


def test_the_asp_is_the_documented_form(library, lab_site) -> None:
    assert compiled(library, lab_site, "door_unavailable", 100.0, door="d_storage", minutes=4).asp == (
        "human_unavailable(d_storage, 100, 340).\n:- human_opens(d_storage, T), T >= 100, T < 340.\n"
    )
    assert compiled(library, lab_site, "forbid_room", 100.0, room="room_a", minutes=2).asp == (
        "room_forbidden(room_a, 100, 220).\n:- robot_in(R, room_a, S, E), S < 220, E > 100.\n"
    )
    assert compiled(library, lab_site, "door_available_now", 100.0, door="d_storage").asp == (
        "human_available(d_storage, 100, 700).\n"
    )


# ---------------------------------------------------------------------------- intended effects


def test_door_unavailable_forbids_exactly_the_openings_inside_its_window(library, lab_site) -> None:
    before = possible(DOOR_PLAN)
    assert values_of(before, "human_opens") == {(d, t) for d in ("d_storage", "d_lab") for t in ALL_TIMES}
    c = compiled(library, lab_site, "door_unavailable", 90.0, door="d_storage", minutes=4)  # [90, 330)
    after = possible(DOOR_PLAN, c.asp)
    storage_times = {int(t) for d, t in values_of(after, "human_opens") if d == "d_storage"}
    assert storage_times == {int(t) for t in ALL_TIMES} - set(range(90, 330))
    assert 60 in storage_times and 330 in storage_times and 90 not in storage_times and 300 not in storage_times
    # other doors are untouched, and the fact is stated for the planner's reading
    assert {t for d, t in values_of(after, "human_opens") if d == "d_lab"} == ALL_TIMES
    assert values_of(after, "human_unavailable") == {("d_storage", "90", "330")}


def test_forbid_room_keeps_robots_out_of_the_room_during_its_window(library, lab_site) -> None:
    c = compiled(library, lab_site, "forbid_room", 120.0, room="room_a", minutes=4)  # [120, 360)
    after = possible(ROOM_PLAN, c.asp)
    stays = {(room, int(s), int(e)) for _r, room, s, e in values_of(after, "robot_in")}
    room_a = {s for room, s, _e in stays if room == "room_a"}
    # a stay [S, S+60) overlapping [120, 360) is out; one ending at 120 or starting at 360 is fine
    assert room_a == {s for s in range(0, 601, 30)} - {s for s in range(0, 601, 30) if s < 360 and s + 60 > 120}
    assert 60 in room_a and 360 in room_a and 90 not in room_a and 330 not in room_a
    assert {s for room, s, _e in stays if room == "lab"} == set(range(0, 601, 30))
    assert values_of(after, "room_forbidden") == {("room_a", "120", "360")}


def test_door_available_now_makes_openings_in_its_window_preferred_but_not_forced(library, lab_site) -> None:
    c = compiled(library, lab_site, "door_available_now", 300.0, door="d_storage")  # [300, 900)
    plan = DOOR_PLAN + ":- human_opens(d_lab, T), T > 0.\n"  # keep the other door out of the way
    assert values_of(answer_sets(plan, PREFER_OFFERED, optimal=True), "human_opens") >= {("d_storage", "0")}
    best = values_of(answer_sets(plan, PREFER_OFFERED, c.asp, optimal=True), "human_opens")
    assert ("d_storage", "300") in best and ("d_storage", "0") not in best
    # not forced: if the plan cannot use the window, it still opens the door outside it
    forced_early = answer_sets(plan, PREFER_OFFERED, c.asp, ":- human_opens(d_storage, T), T >= 300.", optimal=True)
    assert ("d_storage", "0") in values_of(forced_early, "human_opens")


def test_avoid_opening_from_a_site_library_acts_on_goes_through(lab_site) -> None:
    lib = load_library(HERE / "lab_library.toml")
    c = compiled(lib, lab_site, "avoid_opening", 0.0, opening="p_room_a_corridor", minutes=5)  # [0, 300)
    after = possible(OPENING_PLAN, c.asp)
    through = values_of(after, "goes_through")
    assert {int(t) for _r, x, t in through if x == "p_corridor_room_a"} == set(range(300, 601, 30))
    assert {int(t) for _r, x, t in through if x == "d_storage"} == set(range(0, 601, 30))


def test_a_whole_constraint_set_grounds_together(library, lab_site) -> None:
    parts = [
        compiled(library, lab_site, "door_unavailable", 0.0, door="d_storage", minutes=2).asp,
        compiled(library, lab_site, "door_unavailable", 600.0, door="d_storage", minutes=1).asp,
        compiled(library, lab_site, "forbid_room", 0.0, room="lab", minutes=10).asp,
        compiled(library, lab_site, "door_available_now", 30.0, door="d_storage").asp,
    ]
    after = possible(DOOR_PLAN, ROOM_PLAN, "".join(parts))
    storage = {int(t) for d, t in values_of(after, "human_opens") if d == "d_storage"}
    assert storage == set(range(120, 600, 30))  # [0, 120) and [600, 660) are out
    assert {int(s) for _r, room, s, _e in values_of(after, "robot_in") if room == "lab"} == {600}  # [0, 600) is out
    assert len(answer_sets(DOOR_PLAN, "".join(parts[:2]))) == len(storage) * 21  # and d_lab free: 21 slots


# ---------------------------------------------------------------------------- arroch constraints compile


def run_compile(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        arroch("constraints", "compile", "--site", str(LAB), *args),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_the_compile_command_prints_the_asp_or_the_refusal() -> None:
    ok = run_compile("--feedback", '{"kind": "door_unavailable", "door": "d_storage", "minutes": 4}', "--now", "100.5")
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout == "human_unavailable(d_storage, 100, 341).\n:- human_opens(d_storage, T), T >= 100, T < 341.\n"
    refused = run_compile("--feedback", '{"kind": "door_unavailable", "door": "d_storage", "minutes": 4, "x": "p."}')
    assert refused.returncode == 1
    assert refused.stdout.strip() == "refused: door_unavailable: unknown parameter(s) 'x'; it takes: door, minutes"
    injected = run_compile(
        "--feedback", '{"kind": "forbid_room", "room": "lab).\\n#include \\"/etc/passwd\\".", "minutes": 4}'
    )
    assert injected.returncode == 1 and injected.stdout.startswith("refused: forbid_room: site lab has no room")
    not_json = run_compile("--feedback", "{kind: forbid_room}")
    assert not_json.returncode == 1 and not_json.stdout.startswith("refused: feedback is not JSON")
    as_json = run_compile("--feedback", '{"kind": "forbid_room", "room": "lab", "minutes": 1}', "--json")
    assert json.loads(as_json.stdout) == {
        "accepted": True,
        "kind": "forbid_room",
        "params": {"room": "lab", "minutes": 1},
        "start": 0,
        "end": 60,
        "asp": "room_forbidden(lab, 0, 60).\n:- robot_in(R, lab, S, E), S < 60, E > 0.\n",
    }
    cancel = run_compile("--feedback", '{"kind": "cancel", "constraint_id": "c4"}')
    assert cancel.returncode == 0 and "withdraws c4" in cancel.stdout
