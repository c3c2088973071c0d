"""The participant's Jigsaw puzzle: the arrangement of its pieces, the moves, progress and completion.

The picture is cut into ``rows × cols`` pieces; piece ``p`` belongs in slot ``p`` (slots counted
row by row). ``slots[s]`` is the piece lying in slot ``s``. A move swaps two pieces; a piece lying
in its own slot is locked and cannot be moved again.

Same difficulty every trial, a different puzzle each trial (the paper: "puzzles at the same
difficulty level were randomly generated in each trial"): the shuffle is a uniformly random
*single cycle* through every piece (Sattolo's algorithm) drawn from the trial's seed, so no piece
starts in place and the fewest swaps that solve it is always ``rows × cols − 1``. The random stream
is :class:`random.Random` seeded with a string, whose ``random()`` sequence Python guarantees across
versions: a seed gives the same puzzle on every machine.

The state lives on the server (one per trial), so a reloaded or reconnected page resumes it.
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from typing import Any


class MoveRefused(ValueError):
    """A move the puzzle does not allow; the message says why, in words for the page."""


@dataclass(frozen=True)
class Move:
    """One accepted move: ``piece`` went to where ``other`` was, and ``other`` to where ``piece`` was."""

    piece: int
    other: int
    correct: bool  # ``piece`` now lies in its own slot
    other_correct: bool
    placed: int  # pieces in their own slot after the move
    total: int
    done: bool
    moves: int  # accepted moves so far, this one included


def _draw(rng: random.Random, n: int) -> int:
    """An integer in [0, n) from ``random()`` (whose sequence Python keeps stable across versions)."""
    return min(int(rng.random() * n), n - 1)


def shuffle(seed: int, total: int) -> list[int]:
    """The starting arrangement for ``seed``: one random cycle through all ``total`` pieces."""
    if total < 2:
        raise ValueError("a puzzle needs at least 2 pieces")
    rng = random.Random(f"arroch-puzzle-shuffle:{seed}")
    slots = list(range(total))
    for i in range(total - 1, 0, -1):  # Sattolo: j < i, so the result is a single cycle
        j = _draw(rng, i)
        slots[i], slots[j] = slots[j], slots[i]
    return slots


class Puzzle:
    """One trial's puzzle: ``slots[s]`` is the piece in slot ``s``."""

    def __init__(self, seed: int, rows: int, cols: int, slots: list[int] | None = None, moves: int = 0) -> None:
        if rows < 2 or cols < 2:
            raise ValueError(f"a puzzle is at least 2x2, not {rows}x{cols}")
        self.seed = seed
        self.rows = rows
        self.cols = cols
        total = rows * cols
        if slots is None:
            slots = shuffle(seed, total)
        elif sorted(slots) != list(range(total)):
            raise ValueError(f"an arrangement of a {rows}x{cols} puzzle holds each of its {total} pieces once")
        self.slots = list(slots)
        self.moves = moves

    @property
    def total(self) -> int:
        return self.rows * self.cols

    @property
    def placed(self) -> int:
        return sum(1 for s, p in enumerate(self.slots) if s == p)

    @property
    def done(self) -> bool:
        return all(s == p for s, p in enumerate(self.slots))

    def slot_of(self, piece: int) -> int:
        return self.slots.index(piece)

    def in_place(self, piece: int) -> bool:
        return self.slots[piece] == piece

    def _check_piece(self, piece: int, name: str) -> None:
        if not 0 <= piece < self.total:
            raise MoveRefused(f"there is no piece {piece} ({name}): this puzzle has pieces 0 to {self.total - 1}")
        if self.in_place(piece):
            raise MoveRefused(f"piece {piece} ({name}) is in its place and locked")

    def swap(self, piece: int, other: int) -> Move:
        """Swap two pieces; :class:`MoveRefused` when the puzzle is done, a piece does not exist, is
        locked in place, or both are the same."""
        if self.done:
            raise MoveRefused("the puzzle is already complete")
        self._check_piece(piece, "the first one")
        self._check_piece(other, "the second one")
        if piece == other:
            raise MoveRefused("a piece cannot be swapped with itself")
        a, b = self.slot_of(piece), self.slot_of(other)
        self.slots[a], self.slots[b] = other, piece
        self.moves += 1
        return Move(
            piece=piece,
            other=other,
            correct=self.in_place(piece),
            other_correct=self.in_place(other),
            placed=self.placed,
            total=self.total,
            done=self.done,
            moves=self.moves,
        )

    # ------------------------------------------------------------------ state out and back

    def to_json(self) -> dict[str, Any]:
        """The state a page draws (and a resumed server reloads)."""
        return {
            "seed": self.seed,
            "rows": self.rows,
            "cols": self.cols,
            "slots": list(self.slots),
            "moves": self.moves,
            "placed": self.placed,
            "total": self.total,
            "done": self.done,
        }

    @classmethod
    def resume(cls, seed: int, rows: int, cols: int, saved: dict[str, Any] | None) -> Puzzle:
        """The puzzle saved earlier for this seed and size, or a fresh one when ``saved`` is None or
        belongs to another puzzle (another seed or size) or is damaged."""
        if saved and (saved.get("seed"), saved.get("rows"), saved.get("cols")) == (seed, rows, cols):
            try:
                moves = saved.get("moves", 0)
                if not isinstance(moves, int) or moves < 0:
                    raise ValueError("bad move count")
                return cls(seed, rows, cols, slots=[int(p) for p in saved["slots"]], moves=moves)
            except (KeyError, TypeError, ValueError):
                pass
        return cls(seed, rows, cols)
