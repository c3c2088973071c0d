"""The active ConstraintSet: applying feedback, withdrawing and expiring constraints, answering duplicates.

This is the restrictor's state machine, independent of Zenoh (the service feeds it messages and
the clock). Every change bumps ``version`` by one and is written to the :class:`StateStore`
before it takes effect in memory, so what was acknowledged is what a restart restores.

Duplicates: a sender's feedback is identified by ``(src, seq)``. The answer to each is kept; the
same ``(src, seq)`` with the same content gets that answer again and changes nothing (a retry
whose first ack was lost). The same ``(src, seq)`` with *different* content is a sender that
restarted its counter: it is handled as new feedback.
"""

from __future__ import annotations

import collections
import hashlib
import json
import logging
import sqlite3
from dataclasses import dataclass, field

from protocol.messages import Constraint, ConstraintSet, Feedback, FeedbackAck

from .compile import describe, render
from .library import CANCEL, Cancels, Library, SiteLike
from .store import AckRecord, StateStore
from .validate import Refusal, quote, validate

log = logging.getLogger("arroch.restrictor")

DEFAULT_MAX_ACTIVE = 200  # a human gives a handful; this bounds the planner's work if a client misbehaves
_MAX_REASON = 1000  # FeedbackAck.reason allows 1024
CLOCK_UNKNOWN = "the site clock is not known yet (no clock messages from the simulator); try again shortly"


@dataclass
class Outcome:
    """What handling one feedback did: the answer, and whether the set changed (publish it then)."""

    ack: FeedbackAck
    changed: bool = False
    duplicate: bool = False
    expired: list[str] = field(default_factory=list)


def fingerprint(kind: str, params: dict[str, object]) -> str:
    """A digest of a feedback's content, to tell a retry from a reused seq."""
    text = json.dumps([kind, params], sort_keys=True, ensure_ascii=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class ActiveSet:
    def __init__(
        self, library: Library, site: SiteLike, store: StateStore, *, max_active: int = DEFAULT_MAX_ACTIVE
    ) -> None:
        self.library = library
        self.site = site
        self.store = store
        self.max_active = max_active
        stored = store.load()
        self.version = stored.version
        self._next_number = stored.next_number
        self._constraints: dict[str, Constraint] = {c.id: c for c in stored.constraints}
        self._acks: collections.OrderedDict[tuple[str, int], AckRecord] = collections.OrderedDict(
            ((a.src, a.seq), a) for a in stored.acks[-store.max_acks :]
        )

    @property
    def constraints(self) -> list[Constraint]:
        return list(self._constraints.values())

    def message(self) -> ConstraintSet:
        """The set as a (not yet stamped) message; ``asp`` is every constraint's ASP, in order."""
        constraints = self.constraints
        return ConstraintSet(version=self.version, constraints=constraints, asp="".join(c.asp for c in constraints))

    # ------------------------------------------------------------------ feedback

    def handle(self, feedback: Feedback, now: float | None) -> Outcome:
        """Apply one feedback at site time ``now`` (``None``: the clock is not known yet)."""
        key = (feedback.src, feedback.seq)
        digest = fingerprint(feedback.kind, feedback.params)
        previous = self._acks.get(key)
        if previous is not None:
            if previous.fingerprint == digest:
                return Outcome(ack=self._ack_message(previous), duplicate=True)
            log.warning(
                "sender %s reused seq %d for different feedback: handling it as new", quote(feedback.src), feedback.seq
            )
        if now is None:
            # Not remembered: the same feedback sent again once the clock is known must be applied,
            # not answered with this refusal as a duplicate.
            record = self._record(feedback, digest, False, CLOCK_UNKNOWN)
            return Outcome(ack=self._ack_message(record))
        expired = self.expire(now)
        try:
            record = self._apply(feedback, digest, now)
            changed = True
        except Refusal as refusal:
            record = self._record(feedback, digest, False, refusal.reason)
            try:
                self.store.record_ack(record)
            except sqlite3.Error as exc:  # the answer still goes out; only its dedup is lost
                log.error("could not store the answer to %s/%d: %s", quote(feedback.src), feedback.seq, exc)
            changed = False
        self._remember(key, record)
        return Outcome(ack=self._ack_message(record), changed=changed or bool(expired), expired=expired)

    def _apply(self, feedback: Feedback, digest: str, now: float) -> AckRecord:
        validated = validate(
            feedback.kind, feedback.params, self.library, self.site, active_ids=self._constraints.keys()
        )
        entry = validated.entry
        added: list[Constraint] = []
        if entry.effect == CANCEL:
            target = str(validated.values[entry.params[0].name])
            removed = [target]
            old = self._constraints[target]
            constraint_id = target
            reason = f"withdrew {target}: {describe(old.kind, old.params)}"
        else:
            compiled = render(validated, now)
            removed = [
                c.id for c in self._constraints.values() if self._replaced_by(entry.cancels, validated.values, c)
            ]
            if len(self._constraints) - len(removed) >= self.max_active:
                raise Refusal(f"too many active constraints ({len(self._constraints)}); withdraw some first")
            constraint_id = f"c{self._next_number}"
            added.append(
                Constraint(
                    id=constraint_id,
                    kind=entry.id,
                    params=dict(validated.values),
                    start=float(compiled.start),
                    end=float(compiled.end),
                    asp=compiled.asp,
                    origin=feedback.src,
                    terms=compiled.terms,
                )
            )
            reason = (
                f"added {constraint_id}: {describe(entry.id, validated.values)} during [{compiled.start}, "
                f"{compiled.end})"
            )
            if removed:
                reason += f"; withdrew {', '.join(removed)}"
        record = self._record(feedback, digest, True, reason, constraint_id=constraint_id, version=self.version + 1)
        next_number = self._next_number + len(added)
        try:
            self.store.commit(version=self.version + 1, next_number=next_number, add=added, remove=removed, ack=record)
        except sqlite3.Error as exc:
            log.error("could not store a change to the active set: %s", exc)
            raise Refusal("the restrictor could not store this change; nothing was applied") from None
        for cid in removed:
            self._constraints.pop(cid, None)
        for constraint in added:
            self._constraints[constraint.id] = constraint
        self.version += 1
        self._next_number = next_number
        return record

    @staticmethod
    def _replaced_by(cancels: tuple[Cancels, ...], values: dict[str, int | str], constraint: Constraint) -> bool:
        """True when an entry's ``cancels`` rules cover this active constraint (same kind, same values)."""
        return any(
            c.kind == constraint.kind and all(constraint.params.get(name) == values.get(name) for name in c.same)
            for c in cancels
        )

    # ------------------------------------------------------------------ expiry

    def expire(self, now: float) -> list[str]:
        """Drop constraints whose window ended (``end <= now``); returns their ids."""
        gone = [cid for cid, c in self._constraints.items() if c.end <= now]
        if not gone:
            return []
        try:
            self.store.commit(version=self.version + 1, next_number=self._next_number, remove=gone)
        except sqlite3.Error as exc:  # keep them until the next try rather than diverge from the store
            log.error("could not store expiry of %s: %s", ", ".join(gone), exc)
            return []
        for cid in gone:
            del self._constraints[cid]
        self.version += 1
        return gone

    # ------------------------------------------------------------------ answers

    def _record(
        self,
        feedback: Feedback,
        digest: str,
        accepted: bool,
        reason: str,
        *,
        constraint_id: str = "",
        version: int | None = None,
    ) -> AckRecord:
        return AckRecord(
            src=feedback.src,
            seq=feedback.seq,
            fingerprint=digest,
            accepted=accepted,
            reason=reason[:_MAX_REASON],
            constraint_id=constraint_id,
            constraints_version=self.version if version is None else version,
        )

    def _remember(self, key: tuple[str, int], record: AckRecord) -> None:
        self._acks.pop(key, None)
        self._acks[key] = record
        while len(self._acks) > self.store.max_acks:
            self._acks.popitem(last=False)

    @staticmethod
    def _ack_message(record: AckRecord) -> FeedbackAck:
        return FeedbackAck(
            to=record.src,
            feedback_seq=record.seq,
            accepted=record.accepted,
            reason=record.reason,
            constraint_id=record.constraint_id,
            constraints_version=record.constraints_version,
        )
