"""The shared ASP vocabulary as data, and what a constraint states in it as structured terms.

:data:`VOCABULARY` is the one list of the predicates a constraint may use
(:mod:`protocol.asp_vocabulary` checks texts against it): the atoms the planner's encoding defines
for the plan being solved (:data:`PLANNER_ATOMS`) and the facts the restrictor may state, which the
encoding interprets (:data:`INTERPRETED`). :class:`ConstraintTerms` is what the planner needs to
know of one constraint (the interpreted facts it states, the rooms it watches, the integers it
writes), carried beside its ASP text so that the planner reads fields instead of parsing text.

Plain data only (no clingo): every process that handles messages imports it.
"""

from __future__ import annotations

from msgspec import Struct

from .schema import Choice, Ident, Int, List

# (name, arity) -> meaning. The planner defines these for the plan being solved.
PLANNER_ATOMS: dict[tuple[str, int], str] = {
    ("human_opens", 2): "human_opens(D, T): the plan asks the human to open door D at second T",
    ("robot_in", 4): "robot_in(R, Room, S, E): robot R is in Room during [S, E)",
    ("goes_through", 3): "goes_through(R, X, T): robot R goes through opening X starting at second T",
}
# The restrictor states these as facts ``name(Subject, T0, T1)``; the planner's encoding interprets them.
INTERPRETED: dict[tuple[str, int], str] = {
    ("human_unavailable", 3): "human_unavailable(D, T0, T1): the human will not open D in [T0, T1)",
    ("room_forbidden", 3): "room_forbidden(Room, T0, T1): no robot in Room during [T0, T1)",
    ("human_available", 3): "human_available(D, T0, T1): the human offers to open D in [T0, T1)",
}
VOCABULARY: dict[tuple[str, int], str] = {**PLANNER_ATOMS, **INTERPRETED}
INTERPRETED_NAMES: tuple[str, ...] = tuple(name for name, _ in INTERPRETED)
ROOM_PREDICATES = ("robot_in", "room_forbidden")  # a constraint using one needs the planner's room stays

# ASP integers are 32-bit signed in clingo.
ASP_INT_MIN = -(2**31)
ASP_INT_MAX = 2**31 - 1
AspInt = Int(ASP_INT_MIN, ASP_INT_MAX)


class InterpretedFact(Struct, kw_only=True):
    """``predicate(subject, start, end).``: e.g. the human will not open door ``subject`` in [start, end)."""

    predicate: Choice(*INTERPRETED_NAMES)
    subject: Ident  # a door or a room
    start: AspInt
    end: AspInt

    @property
    def asp(self) -> str:
        return f"{self.predicate}({self.subject}, {self.start}, {self.end}).\n"


class ConstraintTerms(Struct, kw_only=True):
    """What one constraint's ASP says, as fields: the predicates it uses, the interpreted facts it
    states, the rooms whose stays it looks at (``robot_in/4`` with a room constant, or every room
    when the room is a variable) and the integers it writes."""

    predicates: List(Choice(*(name for name, _ in VOCABULARY)), 16) = []
    facts: List(InterpretedFact, 256) = []
    rooms: List(Ident, 256) = []
    any_room: bool = False
    numbers: List(AspInt, 1024) = []

    @property
    def mentions_rooms(self) -> bool:
        """True when it needs the planner's room stays (robot_in/4 or room_forbidden/3)."""
        return any(p in ROOM_PREDICATES for p in self.predicates)

    @property
    def states_interpreted(self) -> bool:
        """True when it uses a fact the encoding interprets (which says itself where a wait may end)."""
        return any(p in INTERPRETED_NAMES for p in self.predicates)
