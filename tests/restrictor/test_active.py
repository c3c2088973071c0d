"""The active set and its persistence: apply, withdraw, replace, expire, duplicates, restarts (real SQLite)."""

from __future__ import annotations

import sqlite3

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.messages import Feedback
from services.restrictor.active import ActiveSet
from services.restrictor.store import MAX_ACKS, StateStore, StoreError


def feedback(kind: str, src: str = "tablet", seq: int = 1, **params) -> Feedback:
    return Feedback(kind=kind, params=params, src=src, seq=seq)


@pytest.fixture
def state_dir(tmp_path):
    return tmp_path / "state"


@pytest.fixture
def open_set(library, lab_site, state_dir):
    """``open_set()`` opens an ActiveSet on ``state_dir``; all are closed at teardown."""
    stores: list[StateStore] = []

    def _open(max_acks: int = MAX_ACKS, **options) -> ActiveSet:
        store = StateStore(state_dir, lab_site.name, max_acks=max_acks)
        stores.append(store)
        return ActiveSet(library, lab_site, store, **options)

    yield _open
    for store in stores:
        store.close()


def reopen(active: ActiveSet, open_set) -> ActiveSet:
    """What a restart does: close the store, open the same directory again."""
    active.store.close()
    return open_set()


def test_accepted_feedback_becomes_a_versioned_constraint(open_set) -> None:
    active = open_set()
    assert active.version == 0 and active.message().constraints == []
    out = active.handle(feedback("door_unavailable", door="d_storage", minutes=4), now=100.5)
    assert out.ack.accepted and out.changed and not out.duplicate
    assert (out.ack.to, out.ack.feedback_seq, out.ack.constraint_id, out.ack.constraints_version) == (
        "tablet",
        1,
        "c1",
        1,
    )
    assert out.ack.reason == "added c1: door_unavailable(door=d_storage, minutes=4) during [100, 341)"
    message = active.message()
    assert message.version == 1
    [c] = message.constraints
    assert (c.id, c.kind, c.params, c.start, c.end, c.origin) == (
        "c1",
        "door_unavailable",
        {"door": "d_storage", "minutes": 4},
        100.0,
        341.0,
        "tablet",
    )
    assert (
        message.asp
        == c.asp
        == "human_unavailable(d_storage, 100, 341).\n:- human_opens(d_storage, T), T >= 100, T < 341.\n"
    )


def test_refused_feedback_changes_nothing(open_set) -> None:
    active = open_set()
    out = active.handle(feedback("door_unavailable", door="d_lab", minutes=4), now=100.0)
    assert not out.ack.accepted and not out.changed
    assert out.ack.reason.startswith("door_unavailable: door d_lab is not human-operated")
    assert (out.ack.constraint_id, out.ack.constraints_version) == ("", 0)
    assert active.version == 0 and active.constraints == []


def test_an_unknown_clock_refuses_feedback(open_set) -> None:
    out = open_set().handle(feedback("forbid_room", room="lab", minutes=1), now=None)
    assert not out.ack.accepted and "site clock is not known yet" in out.ack.reason


def test_cancel_withdraws_an_active_constraint(open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=5), now=0.0)
    active.handle(feedback("forbid_room", seq=2, room="room_a", minutes=5), now=0.0)
    out = active.handle(feedback("cancel", seq=3, constraint_id="c1"), now=10.0)
    assert out.ack.accepted and out.ack.constraint_id == "c1" and out.ack.constraints_version == 3
    assert out.ack.reason == "withdrew c1: forbid_room(room=lab, minutes=5)"
    assert [c.id for c in active.constraints] == ["c2"] and "lab" not in active.message().asp
    again = active.handle(feedback("cancel", seq=4, constraint_id="c1"), now=11.0)
    assert (
        not again.ack.accepted
        and again.ack.reason == "cancel: no active constraint c1 (it may have expired or been withdrawn)"
    )
    assert active.version == 3


def test_door_available_now_replaces_door_unavailable_on_that_door_and_back(open_set) -> None:
    active = open_set()
    active.handle(feedback("door_unavailable", seq=1, door="d_storage", minutes=30), now=0.0)  # c1
    active.handle(feedback("forbid_room", seq=2, room="lab", minutes=30), now=0.0)  # c2
    out = active.handle(feedback("door_available_now", seq=3, door="d_storage"), now=60.0)  # c3 replaces c1
    assert out.ack.accepted and out.ack.reason.endswith("; withdrew c1")
    assert [c.id for c in active.constraints] == ["c2", "c3"] and active.version == 3  # one change, one version
    out = active.handle(feedback("door_unavailable", seq=4, door="d_storage", minutes=2), now=90.0)  # c4 replaces c3
    assert out.ack.reason.endswith("; withdrew c3")
    assert [c.kind for c in active.constraints] == ["forbid_room", "door_unavailable"]


def test_expiry_drops_constraints_when_their_window_ends(open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=1), now=100.0)  # [100, 160)
    active.handle(feedback("forbid_room", seq=2, room="room_a", minutes=2), now=100.0)  # [100, 220)
    assert active.expire(159.9) == [] and active.version == 2
    assert active.expire(160.0) == ["c1"] and active.version == 3
    assert [c.id for c in active.constraints] == ["c2"]
    # feedback arriving later first drops what expired meanwhile, and says so
    out = active.handle(feedback("door_unavailable", seq=3, door="d_storage", minutes=1), now=300.0)
    assert out.expired == ["c2"] and out.changed
    assert [c.id for c in active.constraints] == ["c3"] and active.version == 5


def test_duplicate_feedback_is_applied_once_and_answered_the_same(open_set) -> None:
    active = open_set()
    first = active.handle(feedback("door_unavailable", seq=7, door="d_storage", minutes=4), now=100.0)
    second = active.handle(feedback("door_unavailable", seq=7, door="d_storage", minutes=4), now=130.0)
    assert second.duplicate and not second.changed
    assert second.ack == first.ack
    assert len(active.constraints) == 1 and active.version == 1
    # a refusal is answered the same way too, even if the world changed in between
    refused = active.handle(feedback("cancel", seq=8, constraint_id="c2"), now=140.0)
    active.handle(feedback("forbid_room", seq=9, room="lab", minutes=1), now=140.0)  # this is c2
    assert active.handle(feedback("cancel", seq=8, constraint_id="c2"), now=150.0).ack == refused.ack
    # the same seq from another sender is another feedback
    other = active.handle(
        feedback("door_unavailable", src="human-model", seq=7, door="d_storage", minutes=4), now=160.0
    )
    assert other.ack.accepted and not other.duplicate and other.ack.constraint_id == "c3"


def test_a_reused_seq_with_other_content_is_new_feedback(open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=1), now=0.0)
    out = active.handle(feedback("forbid_room", seq=1, room="room_a", minutes=1), now=5.0)  # a restarted tablet
    assert out.ack.accepted and not out.duplicate and out.ack.constraint_id == "c2"


def test_a_restart_restores_the_set_version_ids_and_answers(open_set) -> None:
    active = open_set()
    active.handle(feedback("door_unavailable", seq=1, door="d_storage", minutes=10), now=0.0)
    active.handle(feedback("forbid_room", seq=2, room="lab", minutes=10), now=0.0)
    active.handle(feedback("cancel", seq=3, constraint_id="c1"), now=1.0)
    before = active.message()
    restarted = reopen(active, open_set)
    after = restarted.message()
    assert after == before and after.version == 3 and [c.id for c in after.constraints] == ["c2"]
    # a retry of feedback answered before the restart is still a duplicate
    assert restarted.handle(feedback("forbid_room", seq=2, room="lab", minutes=10), now=2.0).duplicate
    # new ids continue where they were: c1 is never given out again
    assert restarted.handle(feedback("forbid_room", seq=4, room="room_a", minutes=1), now=2.0).ack.constraint_id == "c3"


def test_a_fresh_start_forgets_the_set_but_not_the_version_or_ids(open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=5), now=0.0)
    active.handle(feedback("forbid_room", seq=2, room="room_a", minutes=5), now=0.0)
    active.store.close()
    store = StateStore(active.store.path.parent, "lab")
    store.clear()
    store.close()
    fresh = open_set()
    assert fresh.message().constraints == [] and fresh.version == 3
    out = fresh.handle(feedback("forbid_room", seq=1, room="lab", minutes=5), now=0.0)  # not a duplicate any more
    assert not out.duplicate and out.ack.constraint_id == "c3"


def test_expiry_while_down_happens_at_the_first_check_after_restart(open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=1), now=0.0)
    restarted = reopen(active, open_set)
    assert [c.id for c in restarted.constraints] == ["c1"] and restarted.version == 1
    assert restarted.expire(1000.0) == ["c1"] and restarted.version == 2
    assert reopen(restarted, open_set).message().constraints == []


def test_the_number_of_active_constraints_is_bounded(open_set) -> None:
    active = open_set(max_active=2)
    for seq, room in enumerate(["lab", "room_a"], start=1):
        assert active.handle(feedback("forbid_room", seq=seq, room=room, minutes=5), now=0.0).ack.accepted
    out = active.handle(feedback("forbid_room", seq=3, room="storage", minutes=5), now=0.0)
    assert not out.ack.accepted and out.ack.reason.startswith("too many active constraints (2)")
    # a replacement does not grow the set, so it is still accepted at the bound
    assert active.handle(feedback("cancel", seq=4, constraint_id="c1"), now=0.0).ack.accepted


def test_a_failed_write_refuses_the_feedback_and_keeps_memory_and_disk_equal(open_set, state_dir) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=5), now=0.0)
    blocker = sqlite3.connect(state_dir / "restrictor.sqlite3", timeout=0)
    blocker.execute("BEGIN EXCLUSIVE")  # another writer holds the database: the next commit fails
    active.store._db.execute("PRAGMA busy_timeout = 0")
    try:
        out = active.handle(feedback("forbid_room", seq=2, room="room_a", minutes=5), now=0.0)
    finally:
        blocker.rollback()
        blocker.close()
    assert not out.ack.accepted and out.ack.reason == "the restrictor could not store this change; nothing was applied"
    assert active.version == 1 and [c.id for c in active.constraints] == ["c1"]
    assert reopen(active, open_set).message() == active.message()


def test_answers_kept_for_duplicates_are_bounded(open_set) -> None:
    active = open_set(max_acks=20)
    for seq in range(25):
        active.handle(feedback("cancel", seq=seq, constraint_id="c9"), now=0.0)  # refused, but remembered
    rows = active.store._db.execute("SELECT COUNT(*), MIN(seq) FROM acks").fetchone()
    assert rows == (20, 5)
    assert len(active._acks) == 20 and ("tablet", 4) not in active._acks
    restarted = reopen(active, open_set)
    assert restarted.handle(feedback("cancel", seq=5, constraint_id="c9"), now=0.0).duplicate
    assert not restarted.handle(feedback("cancel", seq=4, constraint_id="c9"), now=0.0).duplicate  # forgotten


def test_one_state_directory_serves_one_restrictor_and_one_site(library, lab_site, state_dir) -> None:
    store = StateStore(state_dir, lab_site.name)
    try:
        with pytest.raises(StoreError, match="another restrictor is using the state directory"):
            StateStore(state_dir, lab_site.name)
    finally:
        store.close()
    with pytest.raises(StoreError, match="belongs to site 'lab', not 'office'; use another --state-dir"):
        StateStore(state_dir, "office")
    StateStore(state_dir, lab_site.name).close()  # the failed opens left no lock behind


def test_a_corrupt_state_row_is_reported_not_loaded(library, lab_site, state_dir, open_set) -> None:
    active = open_set()
    active.handle(feedback("forbid_room", seq=1, room="lab", minutes=5), now=0.0)
    active.store._db.execute("UPDATE constraints SET body = json_set(body, '$.asp', 'p(1).')")
    active.store.close()
    with pytest.raises(
        StoreError, match=r"restrictor.sqlite3: constraints row 1 is not a valid constraint: predicate\(s\) p/1"
    ):
        open_set()


SCALARS = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=30),
    st.sampled_from(["d_storage", "d_lab", "lab", "room_a", "c1", "c2"]),
)


FEEDBACK = st.tuples(
    st.one_of(
        st.sampled_from(["door_unavailable", "forbid_room", "door_available_now", "cancel"]), st.text(max_size=20)
    ),
    st.dictionaries(st.sampled_from(["door", "room", "minutes", "constraint_id", "x"]), SCALARS, max_size=4),
)


@settings(max_examples=150, deadline=None)
@given(feedbacks=st.lists(FEEDBACK, min_size=1, max_size=6), now=st.floats(min_value=0, max_value=1e9))
def test_any_feedback_gets_an_answer_and_only_valid_feedback_changes_the_set(library, lab_site, feedbacks, now) -> None:
    from runtime.asp_check import check_program

    store = StateStore(None, lab_site.name)  # in-memory SQLite: a fresh set per example
    try:
        active = ActiveSet(library, lab_site, store)
        for seq, (kind, params) in enumerate(feedbacks):
            version = active.version
            out = active.handle(Feedback(kind=kind, params=params, src="fuzz", seq=seq), now=now + seq)
            assert out.ack.to == "fuzz" and out.ack.feedback_seq == seq and out.ack.reason
            assert active.version == version + (1 if out.ack.accepted else 0) + (1 if out.expired else 0)
            assert out.ack.constraints_version == (
                active.version if out.ack.accepted else version + (1 if out.expired else 0)
            )
            for constraint in active.constraints:
                check_program(constraint.asp)
    finally:
        store.close()
