"""Key-expression builders: every key, its wildcard form, refused chunks, and the docs table."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
import zenoh

from protocol.keys import Keys, chunk_at

ROOT = Path(__file__).resolve().parents[2]

# builder -> (arguments, expected key below arroch/office/)
EXPECTED = {
    "clock": ((), "clock"),
    "robot_pose": (("r0",), "robot/r0/pose"),
    "robot_status": (("r0",), "robot/r0/status"),
    "robot_traffic": (("r0",), "robot/r0/traffic"),
    "robot_command": (("r0",), "robot/r0/command"),
    "door_state": (("d_storage",), "door/d_storage/state"),
    "door_sensor": (("d_storage",), "door/d_storage/sensor"),
    "human_state": ((), "human/state"),
    "participant_action": ((), "participant/action"),
    "questionnaire": ((), "participant/answers"),
    "study_control": ((), "study/control"),
    "plan": ((), "plan"),
    "intent": (("r1",), "intent/r1"),
    "feedback": ((), "feedback"),
    "feedback_ack": (("tablet-3",), "feedback/ack/tablet-3"),
    "constraints": ((), "constraints"),
    "constraint_library": ((), "constraints/library"),
    "camera_frame": (("tablet",), "camera/tablet/frame"),
    "camera_truth": (("tablet",), "camera/tablet/truth"),
    "overlay": (("tablet",), "ar/tablet/overlay"),
    "event": ((), "event"),
    "liveliness": (("planner", "planner-12"), "@liveliness/planner/planner-12"),
    "stats": (("planner", "planner-12"), "stats/planner/planner-12"),
    "drain": (("replay-12-ab3f",), "drain/replay-12-ab3f"),
    "ping_reply": ((), "ping/reply"),
    "all": ((), "**"),
}


def builders() -> list[str]:
    return sorted(name for name, fn in inspect.getmembers(Keys, inspect.isfunction) if not name.startswith("_"))


def test_every_builder_is_checked_here():
    assert builders() == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_concrete_keys(name):
    args, expected = EXPECTED[name]
    key = getattr(Keys("office"), name)(*args)
    assert key == f"arroch/office/{expected}"
    zenoh.KeyExpr(key)  # a valid key expression for Zenoh


@pytest.mark.parametrize("name", [n for n, (args, _) in EXPECTED.items() if args])
def test_wildcard_defaults_match_the_concrete_keys(name):
    keys = Keys("office")
    args, _ = EXPECTED[name]
    wildcard = getattr(keys, name)()
    assert "*" in wildcard
    assert zenoh.KeyExpr(wildcard).intersects(zenoh.KeyExpr(getattr(keys, name)(*args)))
    # ... and only within its own namespace.
    assert not zenoh.KeyExpr(wildcard).intersects(zenoh.KeyExpr(getattr(Keys("other"), name)(*args)))


def test_liveliness_tokens_are_outside_the_namespace_wildcard():
    keys = Keys("office")
    # '@' chunks are verbatim in zenoh 1.x: arroch/office/** does not cover liveliness tokens.
    assert not zenoh.KeyExpr(keys.all()).intersects(zenoh.KeyExpr(keys.liveliness("planner", "p-1")))
    assert zenoh.KeyExpr(keys.all()).intersects(zenoh.KeyExpr(keys.stats("planner", "p-1")))


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "**", "r 0", "r0$", "ü", "a?b", "#"])
def test_invalid_chunks_refused(bad):
    keys = Keys("office")
    for build in (
        keys.robot_pose,
        keys.robot_status,
        keys.robot_traffic,
        keys.robot_command,
        keys.door_state,
        keys.intent,
        keys.feedback_ack,
        keys.camera_frame,
        keys.camera_truth,
        keys.overlay,
    ):
        with pytest.raises(ValueError, match="cannot be used in a key expression"):
            build(bad)
    with pytest.raises(ValueError):
        keys.stats(bad, "x")
    with pytest.raises(ValueError):
        keys.liveliness("x", bad)
    with pytest.raises(ValueError, match="site name"):
        Keys(bad)


def test_chunk_at():
    assert chunk_at(Keys("office").robot_pose("r7"), 3) == "r7"
    assert chunk_at(Keys("office").door_state("d1"), 3) == "d1"


def _doc_key_patterns() -> set[str]:
    """The keys of docs/architecture.md's key table, placeholders turned into '*'."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("## Keys", 1)[1].split("\n## ", 1)[0]
    keys = re.findall(r"^\| `([^`]+)` \|", section, flags=re.MULTILINE)
    return {re.sub(r"<[^>]+>", "*", key) for key in keys}


def test_docs_key_table_lists_every_builder():
    documented = _doc_key_patterns()
    keys = Keys("office")
    for name in builders():
        if name == "all":
            continue
        pattern = getattr(keys, name)().removeprefix("arroch/office/")
        assert pattern in documented, f"Keys.{name}() ({pattern}) is missing from docs/architecture.md's key table"
