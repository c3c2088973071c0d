"""Client side of the restrictor's contract: send feedback and wait for its ack; fetch the live
set; fetch the constraint library the running restrictor serves.

Used by ``arroch feedback send`` and ``arroch constraints show``, the AR client, the tablet page, the
simulated human and the ROS 2 bridge: anything that talks to a restrictor from a blocking context
(the calls block up to their timeout, so do not make them from a service's worker thread).

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
from protocol.constraint_library import ConstraintLibrary, decode_library
from protocol.errors import ProtocolError
from protocol.messages import ConstraintSet, Feedback, FeedbackAck
from runtime.service import Service

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


def fetch_library(client: Service, *, timeout: float = 2.0) -> ConstraintLibrary | None:
    """The constraint library a running restrictor serves, or None when none answers in ``timeout`` s.

    A reply that is not a valid library is counted as a bad message of the key and skipped."""
    key = client.keys.constraint_library()
    for reply in client.session.get(key, timeout=timeout):
        if reply.ok is None:
            continue
        payload = reply.ok.payload.to_bytes()
        try:
            return decode_library(payload)
        except ProtocolError as exc:
            client.note_bad_message(key, payload, exc)
    return None


def wait_for_library(
    client: Service, *, retry: float = 2.0, timeout: float = 2.0, what: str = "feedback buttons"
) -> ConstraintLibrary | None:
    """:func:`fetch_library` again every ``retry`` s until a restrictor answers or ``client`` stops.

    Logs once, at WARNING, that no restrictor answers yet (and what waits for it), and at INFO
    the answer that came. For a background thread of a running service: a closed session ends it (None)."""
    key = client.keys.constraint_library()
    warned = False
    while not client.stopping:
        try:
            library = fetch_library(client, timeout=timeout)
        except Exception as exc:  # the session closed while asking
            client.log.debug("library query failed: %s", exc)
            return None
        if library is not None:
            client.log.info(
                "restrictor %s answered: %d library entries for the %s", library.src, len(library.entries), what
            )
            return library
        if not warned:
            client.log.warning(
                "no restrictor answers on %s yet: no %s until one does (asking every %g s)", key, what, retry
            )
            warned = True
        deadline = time.monotonic() + retry
        while not client.stopping and time.monotonic() < deadline:
            time.sleep(0.1)
    return None
