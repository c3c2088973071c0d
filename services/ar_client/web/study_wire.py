"""The study page's messages to the server (``arroch tablet --study-trial``), declared like the
other page messages of :mod:`.wire` (which accepts them through its ``PAGE_MESSAGES``).

These Structs fix the *shape* only: a message of the wrong shape is a protocol violation and closes
that page's socket, as any other malformed message. Whether a well-formed request makes sense — a
piece that exists, a door she operates, an answer on its scale, a move while she is at her desk —
is the study's to judge (:mod:`.study`), which refuses it with a reason and keeps the socket open.

Every message carries ``wall``: the page's ``Date.now() / 1000`` when she acted, which the
ParticipantAction or QuestionnaireAnswers it becomes carries on.

- ``{"type": "consent", "answer": "given"|"refused", "wall"}``
- ``{"type": "view", "view": "puzzle"|"ar"|"map", "note": ""|"hidden"|"visible", "wall"}``
- ``{"type": "puzzle_move", "piece": p, "other": q, "wall"}``: swap pieces p and q
- ``{"type": "door", "act": "go_to_door"|"open_door"|"back_to_desk", "door", "held", "wall"}``:
  ``held`` = seconds the "hold to open" was held (open_door)
- ``{"type": "answers", "answers": {instrument: {item: value}}, "wall"}``
"""

from __future__ import annotations

from typing import Annotated, Literal

from msgspec import Meta, Struct

Wall = Annotated[float, Meta(gt=0.0, lt=1e10)]  # Unix seconds, finite
PieceId = Annotated[int, Meta(gt=-(2**31), lt=2**31)]  # whether the piece exists is the puzzle's question
ItemId = Annotated[str, Meta(min_length=1, max_length=32)]
AnswerValue = Annotated[int, Meta(gt=-(2**31), lt=2**31)]


class ConsentAnswer(Struct, frozen=True, kw_only=True):
    answer: Literal["given", "refused"]
    wall: Wall


class ViewChange(Struct, frozen=True, kw_only=True):
    view: Literal["puzzle", "ar", "map"]
    note: Literal["", "hidden", "visible"] = ""
    wall: Wall


class PuzzleMoveRequest(Struct, frozen=True, kw_only=True):
    piece: PieceId
    other: PieceId
    wall: Wall


class DoorRequest(Struct, frozen=True, kw_only=True):
    act: Literal["go_to_door", "open_door", "back_to_desk"]
    door: Annotated[str, Meta(max_length=64)] = ""
    held: Annotated[float, Meta(ge=0.0, le=1e5)] = 0.0
    wall: Wall


class AnswersSubmission(Struct, frozen=True, kw_only=True):
    answers: Annotated[
        dict[Annotated[str, Meta(max_length=32)], Annotated[dict[ItemId, AnswerValue], Meta(max_length=16)]],
        Meta(min_length=1, max_length=4),
    ]
    wall: Wall


StudyMessage = ConsentAnswer | ViewChange | PuzzleMoveRequest | DoorRequest | AnswersSubmission

STUDY_MESSAGES: dict[str, type[Struct]] = {
    "consent": ConsentAnswer,
    "view": ViewChange,
    "puzzle_move": PuzzleMoveRequest,
    "door": DoorRequest,
    "answers": AnswersSubmission,
}
