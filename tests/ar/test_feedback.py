"""Feedback buttons: the panel's layout and taps, the library they are built from coming from a
real restrictor process (asked again until one answers), and a press reaching it over Zenoh with
its ack (or refusal) coming back and shown on the panel."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from protocol.messages import Constraint, ConstraintSet
from protocol.site import load_site
from runtime.feedback_client import fetch_library, wait_for_library
from services.ar_client.feedback import FeedbackPanel, restrictor_sender
from services.restrictor.library import library_for_site
from tests.procs import arroch

OFFICE_DOOR = "d_storage"


def _panel(sender=None) -> FeedbackPanel:  # noqa: ANN001
    return FeedbackPanel(library_for_site(load_site()), sender)


def _restrictor(spawn, router: str, namespace: str, state):  # noqa: ANN001, ANN202
    return spawn(
        arroch(
            "restrictor", "--namespace", namespace, "--connect", router, "--clock", "wall", "--state-dir", str(state)
        ),
        name="restrictor",
    )


def test_every_usable_library_entry_becomes_a_button_with_parameter_chips():
    panel = _panel()
    prims = panel.primitives(1280, 720)
    assert {p.layer for p in prims} == {"ui"}
    texts = [p.text for p in prims if p.kind == "text"]
    for entry in panel.entries:
        assert any(t.startswith(entry.label[:10]) for t in texts), entry.id
    assert any(t.startswith("Door: ") for t in texts) and any(t.startswith("Minutes: 15") for t in texts)
    # Tapping a chip cycles its value; tapping the cancel button does nothing without a live constraint.
    chip = next(b for b in panel._buttons if b.action == ("cycle", "door_unavailable", "minutes"))
    x0, y0, x1, y1 = chip.rect
    assert panel.press_at((x0 + x1) / 2, (y0 + y1) / 2) == chip.action
    assert panel.values("door_unavailable")["minutes"] == 30
    assert not panel.ready("cancel") and not panel.press("cancel")
    panel.on_constraints(
        ConstraintSet(version=3, constraints=[Constraint(id="c7", kind="forbid_room", start=0, end=60, asp="")])
    )
    assert panel.ready("cancel") and panel.values("cancel") == {"constraint_id": "c7"}
    assert panel.press_at(-5, -5) is None


def test_a_panel_without_a_library_says_it_waits_and_shows_the_entries_once_given():
    panel = FeedbackPanel()
    texts = [p.text for p in panel.primitives(1280, 720) if p.kind == "text"]
    assert texts == ["Feedback: waiting for the restrictor's library"] and panel._buttons == []
    panel.set_entries(library_for_site(load_site()))
    texts = [p.text for p in panel.primitives(1280, 720) if p.kind == "text"]
    assert "Feedback: waiting for the restrictor's library" not in texts
    assert {b.action[1] for b in panel._buttons if b.action[0] == "send"} >= {"door_unavailable", "forbid_room"}


def test_a_small_frame_still_lays_out_without_overflow():
    prims = _panel().primitives(320, 240)
    for p in prims:
        for u, v in p.points:
            assert -1 <= u <= 321 and -1 <= v <= 241


@pytest.mark.integration
def test_the_library_comes_from_the_restrictor_once_one_answers(router, namespace, client, spawn, tmp_path, caplog):
    got: list = []
    with caplog.at_level(logging.INFO):
        waiter = threading.Thread(target=lambda: got.append(wait_for_library(client, retry=0.5, timeout=0.5)))
        waiter.start()
        time.sleep(1.5)  # asked more than once, nobody answered
        assert not got and waiter.is_alive()
        _restrictor(spawn, router, namespace, tmp_path / "state").wait_for("up on namespace", timeout=30)
        waiter.join(15.0)
    assert got and got[0] is not None, "the restrictor's library never arrived"
    assert got[0].site == "office" and got[0].entries == library_for_site(load_site())
    assert "no restrictor answers on" in caplog.text and "constraints/library" in caplog.text
    assert "answered: 4 library entries" in caplog.text


@pytest.mark.integration
def test_a_press_reaches_the_restrictor_and_its_ack_comes_back(router, namespace, client, spawn, tmp_path):
    restrictor = _restrictor(spawn, router, namespace, tmp_path / "state")
    restrictor.wait_for("up on namespace", timeout=30)
    # Its queryable reaches the router a moment after its log line: ask again, as the page does.
    deadline = time.monotonic() + 15.0
    library = fetch_library(client, timeout=2.0)
    while library is None and time.monotonic() < deadline:
        time.sleep(0.2)
        library = fetch_library(client, timeout=2.0)
    assert library is not None, "the restrictor never answered for its library"
    panel = FeedbackPanel(library.entries, restrictor_sender(client, timeout=10.0))
    panel.set_value("door_unavailable", "door", OFFICE_DOOR)
    panel.primitives(1280, 720)  # lay out, so the tap below hits the button
    send = next(b for b in panel._buttons if b.action == ("send", "door_unavailable"))
    x0, y0, x1, y1 = send.rect
    assert panel.press_at((x0 + x1) / 2, (y0 + y1) / 2) == ("send", "door_unavailable")
    assert panel.result is not None and panel.result.status in ("pending", "accepted")
    result = panel.wait(15.0)
    assert result is not None and result.status == "accepted", result
    assert result.constraint_id and result.params == {"door": OFFICE_DOOR, "minutes": 15}
    # The answer is on screen.
    assert any(
        p.kind == "text" and p.text.startswith("door_unavailable: accepted") for p in panel.primitives(1280, 720)
    )

    # A value the restrictor refuses (here: a room the site does not have) comes back with its reason.
    assert panel.press("forbid_room", {"room": "ballroom", "minutes": 5})
    refused = panel.wait(15.0)
    assert refused is not None and refused.status == "refused" and "ballroom" in refused.reason
    assert restrictor.alive()


def test_no_restrictor_means_no_answer_not_a_hang(router, namespace, client):
    panel = _panel(restrictor_sender(client, timeout=1.5))
    started = time.monotonic()
    assert panel.press("door_available_now")
    result = panel.wait(10.0)
    assert result is not None and result.status == "no answer"
    assert time.monotonic() - started < 5.0
