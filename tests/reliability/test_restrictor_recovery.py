"""Feedback reaching a restrictor that does not know the site clock yet (just restarted mid-mission):
it waits for the clock instead of being refused, and a refusal for want of a clock is never kept as
the answer to that feedback's retries."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from protocol.messages import Clock, ConstraintSet, Feedback, FeedbackAck
from protocol.site import load_site
from services.restrictor.active import CLOCK_UNKNOWN, ActiveSet
from services.restrictor.library import load_library
from services.restrictor.service import CLOCK_WAIT
from services.restrictor.store import StateStore
from tests.procs import arroch

from .watch import Watch

SITE = load_site()


def test_a_refusal_for_want_of_a_clock_is_not_the_answer_to_the_retry():
    store = StateStore(None, SITE.name)
    try:
        active = ActiveSet(load_library(), SITE, store)
        feedback = Feedback(kind="forbid_room", params={"room": "lab", "minutes": 2}, src="tablet-1", seq=7)
        early = active.handle(feedback, now=None)
        assert not early.ack.accepted and early.ack.reason == CLOCK_UNKNOWN and not early.changed
        retry = active.handle(feedback, now=50.0)  # the same src and seq, once the clock is known
        assert retry.ack.accepted and not retry.duplicate and retry.ack.constraints_version == 1
        again = active.handle(feedback, now=51.0)
        assert again.duplicate and again.ack == retry.ack and active.version == 1
    finally:
        store.close()


@pytest.mark.integration
def test_feedback_waits_for_the_first_clock_message_instead_of_being_refused(
    spawn, router, namespace, client, tmp_path: Path
):
    sets = Watch(client, client.keys.constraints(), ConstraintSet)
    proc = spawn(
        arroch("restrictor", "--connect", router, "--namespace", namespace, "--state-dir", str(tmp_path)),
        name="restrictor",
    )
    proc.wait_for("up on namespace", timeout=30)
    sets.first(lambda s: s.version == 0, "the restored (empty) set")

    answers: list[list[FeedbackAck]] = []
    ask = threading.Thread(
        target=lambda: answers.append(
            client.query(
                client.keys.feedback(),
                FeedbackAck,
                payload=Feedback(kind="forbid_room", params={"room": "lab", "minutes": 2}),
                timeout=10.0,
            )
        )
    )
    asked = time.monotonic()
    ask.start()
    time.sleep(CLOCK_WAIT / 2)  # the simulator's first clock message comes while the feedback waits
    client.publish(client.keys.clock(), Clock(time=300.0, mode="lockstep", world_version=40, paused=True))
    ask.join(15)
    [[ack]] = answers
    assert ack.accepted, ack
    assert CLOCK_WAIT / 2 <= time.monotonic() - asked < CLOCK_WAIT + 5
    _, added = sets.first(lambda s: s.version == 1, "the set with the constraint")
    assert [(c.id, c.start, c.end) for c in added.constraints] == [(ack.constraint_id, 300.0, 420.0)]
