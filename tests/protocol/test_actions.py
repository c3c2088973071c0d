"""The one Action type and its step table: same strings on the wire, one account of each effect."""

from __future__ import annotations

import pytest

from protocol.actions import STEPS, Action, EndsAt, Fluents
from protocol.codec import decoder_for, encoder_for
from protocol.messages import RobotCommand


def test_actions_are_their_wire_names_and_a_command_made_with_one_encodes_the_same():
    assert [a.value for a in Action] == ["approach", "opendoor", "gothrough", "load", "unload"]
    assert Action.LOAD == "load" and f"{Action.GOTHROUGH}" == "gothrough"
    plain = RobotCommand(robot="r0", plan_id=1, action_id=2, action="load", args=["o0"])
    typed = RobotCommand(robot="r0", plan_id=1, action_id=2, action=Action.LOAD, args=["o0"])
    encode = encoder_for(RobotCommand)
    assert encode(typed) == encode(plain)
    assert decoder_for(RobotCommand)(encode(typed)).action == "load"


def test_an_unknown_action_is_named_in_the_error():
    assert Action.parse("unload") is Action.UNLOAD
    with pytest.raises(ValueError, match="'fly'.*approach"):
        Action.parse("fly")


def test_every_action_has_one_rule():
    assert set(STEPS) == set(Action) and all(rule.action is a for a, rule in STEPS.items())
    assert {a for a, r in STEPS.items() if r.in_place} == {Action.LOAD, Action.UNLOAD}
    assert STEPS[Action.OPENDOOR].ends_at is EndsAt.STAYS and not STEPS[Action.OPENDOOR].straight_line


def test_a_delivery_changes_the_fluents_step_by_step():
    f = Fluents(room="hall")
    f.apply(Action.APPROACH, "d1")
    assert f.beside == "d1"
    f.apply(Action.OPENDOOR, "d1")
    assert f.beside == "d1" and f.room == "hall"
    f.apply(Action.GOTHROUGH, "d1", room_after="storage")
    assert (f.room, f.beside) == ("storage", "")
    f.apply("load", "o0")  # names as plans carry them
    assert f.carrying == {"o0"}
    f.apply(Action.UNLOAD, "o0")
    assert (f.carrying, f.delivered) == (set(), {"o0"})
    with pytest.raises(ValueError):
        f.apply("fly", "x")
