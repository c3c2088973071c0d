"""Client side of the restrictor's contract: send feedback and wait for its ack; fetch the live set.

Used by ``arroch feedback send`` and ``arroch constraints show``, and by anything else that talks
to a restrictor from a blocking context (the calls block up to their timeout, so do not make
them from a service's worker thread).

Sending is at-least-once with exactly-once effect: the Feedback is stamped once and the same
bytes (same ``src`` and ``seq``) are re-sent until an ack arrives, either as the reply to the
query on ``feedback`` or on ``feedback/ack/<src>``; the restrictor applies a repeated
``(src, seq)`` only once and answers it again with the same ack.
"""

from __future__ import annotations

import logging
import queue
import time
from typing import Any

import zenoh

from protocol.codec import encode
from protocol.messages import ConstraintSet, Feedback, FeedbackAck
from protocol.service import Service

log = logging.getLogger("arroch.feedback")


def send_feedback(
    client: Service, kind: str, params: dict[str, Any], *, timeout: float = 10.0, retry: float = 1.0
) -> FeedbackAck | None:
    """Send one Feedback through ``client`` (an open Service); the ack, or None after ``timeout`` s."""
    feedback = client.stamp(Feedback(kind=kind, params=params))
    payload = encode(feedback)
    acks: queue.Queue[FeedbackAck] = queue.Queue()

    def mine(ack: FeedbackAck) -> bool:
        return ack.to == feedback.src and ack.feedback_seq == feedback.seq

    ack_key = client.keys.feedback_ack(feedback.src)

    def on_ack(sample: zenoh.Sample) -> None:
        ack = client.decode_or_count(sample.payload.to_bytes(), FeedbackAck, ack_key)  # bad: counted, logged
        if ack is not None and mine(ack):
            acks.put(ack)

    # Declared before the first send, so an ack published for it cannot slip past.
    subscriber = client.session.declare_subscriber(ack_key, on_ack)
    try:
        deadline = time.monotonic() + timeout
        attempt = 0
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            attempt += 1
            if attempt > 1:
                log.info("no ack yet for %s/%d; sending again (attempt %d)", feedback.src, feedback.seq, attempt)
            started = time.monotonic()
            for reply in client.session.get(client.keys.feedback(), payload=payload, timeout=min(retry, remaining)):
                if reply.ok is None:
                    continue
                ack = client.decode_or_count(reply.ok.payload.to_bytes(), FeedbackAck, client.keys.feedback())
                if ack is None:
                    continue
                if mine(ack) or (ack.to == "" and not ack.accepted):  # "" : the restrictor could not read it
                    return ack
            # No reply: maybe the ack went out on the ack key, or no restrictor is up yet.
            wait = max(0.0, min(retry - (time.monotonic() - started), deadline - time.monotonic()))
            try:
                return acks.get(timeout=wait)
            except queue.Empty:
                continue
    finally:
        subscriber.undeclare()


def fetch_constraints(client: Service, *, timeout: float = 3.0) -> ConstraintSet | None:
    """The live ConstraintSet from the restrictor's queryable (the newest version if several answer)."""
    sets = client.query(client.keys.constraints(), ConstraintSet, timeout=timeout)
    return max(sets, key=lambda s: s.version) if sets else None


def newest_constraints(client: Service, *, timeout: float = 2.0) -> ConstraintSet | None:
    """:func:`fetch_constraints` for a background thread of a running service: a session closed
    while asking gives None (logged at debug level), not an error."""
    try:
        return fetch_constraints(client, timeout=timeout)
    except Exception as exc:  # the session closed while asking: nothing to do
        client.log.debug("constraints query failed: %s", exc)
        return None
