"""A trial's log read as a timeline (services/study/timeline.py) and the per-trial pieces of the fits
built on it, on hand-made logs whose answers follow from the rules' wording."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from services.study.fits import declared_windows, fit_focus_minutes, move_intervals
from services.study.layout import StudyError
from services.study.timeline import build_timeline, load_timeline


def act(t: float, name: str, **kw: object) -> dict:
    return {"t": t, "type": "ParticipantAction", "participant": "P01", "act": name, **kw}


def place(t: float, where: str) -> dict:
    return {"t": t, "type": "HumanState", "place": where, "doors": ["d1"]}


def event(t: float, kind: str, **kw: object) -> dict:
    return {"t": t, "type": "Event", "kind": kind, **kw}


def test_trips_views_and_time_away() -> None:
    records = [
        event(0.0, "mission_started"),
        place(0.0, "desk"),
        act(10.0, "view", view="ar"),
        act(20.0, "go_to_door", door="d1"),  # leaves from the AR view: away spans overlap
        place(20.0, "to_door"),
        act(26.0, "open_door", door="d1"),
        event(27.5, "door_opened", door="d1"),
        place(35.0, "desk"),
        act(40.0, "view", view="puzzle"),
        act(60.0, "view", view="map"),
        act(65.0, "view", view="puzzle"),
        act(100.0, "task_done"),
        act(110.0, "go_to_door", door="d1"),  # after her task: not time away from it
        place(120.0, "desk"),
        event(130.0, "door_closed", door="d1"),
        event(150.0, "mission_done"),
    ]
    tl = build_timeline(records, "log")
    assert [(t.start, t.end, t.opened) for t in tl.trips] == [(20.0, 35.0, True), (110.0, 120.0, False)]
    assert [(s.start, s.end) for s in tl.views_away] == [(10.0, 40.0), (60.0, 65.0)]
    assert tl.time_away() == (40.0 - 10.0) + (65.0 - 60.0)
    assert tl.active_time() == 100.0 - tl.time_away()
    assert tl.is_open("d1", 26.0) and tl.is_open("d1", 129.0) and not tl.is_open("d1", 25.9)
    assert tl.doors == ["d1"] and (tl.start, tl.end, tl.task_done) == (0.0, 150.0, 100.0)


def test_without_her_place_a_trip_ends_at_her_next_move() -> None:
    records = [
        act(0.0, "view", view="puzzle"),
        act(5.0, "go_to_door", door="d1"),
        act(11.0, "puzzle_move", piece=1),  # on her way (the page may be in her hand): not yet back
        act(12.0, "open_door", door="d1"),
        act(30.0, "puzzle_move", piece=2, correct=True, placed=1, total=16),
    ]
    tl = build_timeline(records, "log")
    assert [(t.start, t.end) for t in tl.trips] == [(5.0, 30.0)]
    assert [m.placed for m in tl.moves] == [0, 1]


def test_declarations_grouped_and_timed() -> None:
    records = [
        act(0.0, "view", view="puzzle"),
        act(10.0, "view", view="ar"),
        act(11.0, "feedback", door="d1", minutes=2, note="door_unavailable"),
        act(11.5, "feedback", door="d2", minutes=2, note="door_unavailable"),  # one declaration, two doors
        act(14.0, "view", view="puzzle"),
        act(50.0, "feedback", door="d1", minutes=3, note="door_unavailable"),  # from the puzzle view
        act(52.0, "feedback", door="d2", minutes=3, note="door_unavailable"),  # 2 s later: the same one
        act(70.0, "feedback", door="d1", minutes=1, note="door_unavailable"),  # 18 s later: another
        act(90.0, "feedback", door="d1", minutes=0, note="door_available_now"),
        act(200.0, "task_done"),
    ]
    tl = build_timeline(records, "log")
    assert [len(g) for g in tl.declarations()] == [2, 2, 1]
    assert tl.declaration_times() == [4.0]
    windows = declared_windows(tl)
    # Each declaration holds for its minutes; "door_available_now" at 90 s ends d1's windows open then,
    # and her task done (200 s) ends any window.
    assert [(s.start, s.end) for s in windows["d1"]] == [(11.0, 90.0), (50.0, 90.0), (70.0, 90.0)]
    assert [(s.start, s.end) for s in windows["d2"]] == [(11.5, 11.5 + 2 * 60), (52.0, 200.0)]


def test_move_intervals_compare_with_the_length_biased_usual() -> None:
    records = [act(0.0, "view", view="puzzle"), place(0.0, "desk")]
    moves = [0.0, 2.0, 6.0, 8.0, 12.0]  # plain intervals 2, 4, 2, 4
    records += [act(t, "puzzle_move") for t in moves]
    records += [act(13.0, "go_to_door", door="d1"), place(13.0, "to_door"), place(33.0, "desk")]
    records += [act(48.0, "puzzle_move"), act(48.0, "task_done")]  # 36 s between moves, 20 s away: 16 working
    iv = move_intervals(build_timeline(records, "log"))
    assert iv.plain == [2.0, 4.0, 2.0, 4.0] and iv.door == [16.0] and iv.several == 0
    assert iv.usual == pytest.approx((4 + 16 + 4 + 16) / 12)  # sum L^2 / sum L, not the mean 3


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("[1, 2]", "record 2 is not a JSON object"),
        ('{"type": "Event"}', "record 2 has no numeric 't'"),
        ('{"t": "soon", "type": "Event"}', "record 2 has no numeric 't'"),
        ('{"t": 3.0}', "record 2 has no message 'type'"),
        ('{"t": 3.0, "type": "ParticipantAction", "act": "view", "view": 4}', "field 'view' should be str"),
    ],
)
def test_bad_records_are_named(tmp_path: Path, line: str, words: str) -> None:
    path = tmp_path / "log.jsonl"
    first, last = json.dumps(act(0.0, "view", view="puzzle")), json.dumps(act(9.0, "task_done"))
    path.write_text(f"{first}\n{line}\n{last}\n")
    with pytest.raises(StudyError, match=words) as info:
        load_timeline(path)
    assert str(path) in str(info.value)


def test_a_torn_last_line_is_skipped_but_an_empty_log_is_not(tmp_path: Path) -> None:
    path = tmp_path / "log.jsonl"
    path.write_text(json.dumps(act(0.0, "view", view="puzzle")) + "\n" + '{"t": 5, "ty')
    assert load_timeline(path).end == 0.0
    path.write_text("")
    with pytest.raises(StudyError, match="empty"):
        load_timeline(path)


def test_few_declared_minutes_widen_the_bounds() -> None:
    records = [act(0.0, "view", view="puzzle")]
    for t in (10.0, 200.0, 400.0):
        records += [
            act(t, "view", view="ar"),
            act(t + 1, "feedback", door="d1", minutes=2, note="door_unavailable"),
            act(t + 3, "view", view="puzzle"),
        ]
    low, high = fit_focus_minutes([build_timeline(records, "log")], (2, 4))
    # Three declarations all of 2 minutes. Were the range j minutes wider, all three would miss those
    # values with probability (1 / (1 + j))^3: 1/27 >= 2.5 % for j = 2, 1/64 < 2.5 % for j = 3.
    assert (low.estimate, low.low, low.high) == (2, 1, 2)  # never below 1 minute
    assert (high.estimate, high.low, high.high) == (2, 2, 4)
    assert not low.identified and low.n == 3
