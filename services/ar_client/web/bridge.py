"""The tablet server's Zenoh side: what the pages see of the system, and what they say to it.

A :class:`TabletBridge` is a :class:`runtime.service.Service` named ``tablet``. Its worker thread
(:meth:`Service.run`, on a thread of the server's) feeds:

- a :class:`WorldView` from ``robot/*/pose`` (latest), ``robot/*/status``, ``intent/*`` and
  ``door/*/state`` — read by every page's pipeline and by the map view;
- the live ``constraints`` (and a query for them at start), for the "cancel" choices of the pages;
- the constraint library the running restrictor serves (``constraints/library``, asked every
  second until one answers), which the pages build their feedback buttons from;
- with a sim camera (``--camera-source sim:CID``), the newest ``camera/<CID>/frame`` for viewer pages;
- in study mode (``--study-trial``): the newest ``human/state`` (where the simulator has the
  participant), the newest ``clock`` (its rate and pause, for the page's press-and-hold) and
  ``event`` (``mission_done`` opens the questionnaire).

These are handed to the web server's event loop through the ``on_constraints`` / ``on_library`` /
``on_sim_frame`` / ``on_human_state`` / ``on_clock`` / ``on_mission_done`` callbacks (called on the
worker; the server makes them thread-safe).

Outwards: each page's Overlays on ``ar/<cid>/overlay`` (for recorders) and feedback to the
restrictor with :func:`runtime.feedback_client.send_feedback` (query with ack, retried until
answered), which blocks and so runs on the server's feedback threads, never on the worker. In study
mode, what the participant does on ``participant/action`` and her answers on ``participant/answers``
(the tablet publishes as the ``ar`` role of the deployment's access table).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from protocol.constraint_library import entries_to_wire
from protocol.messages import (
    CameraFrame,
    ConstraintSet,
    Event,
    FeedbackAck,
    HumanState,
    Overlay,
    ParticipantAction,
    QuestionnaireAnswers,
)
from protocol.messages import Clock as ClockMessage
from runtime.clock import SimClock, WallClock
from runtime.feedback_client import newest_constraints, send_feedback, wait_for_library
from runtime.service import Service
from runtime.transport import ZenohOptions

from ..world import WorldView

FEEDBACK_TIMEOUT = 8.0  # seconds a page waits for the restrictor's answer
LIBRARY_RETRY = 1.0  # wall seconds between queries for the restrictor's library until one answers


class TabletBridge(Service):
    def __init__(
        self,
        *,
        namespace: str,
        zenoh_options: ZenohOptions,
        sim_camera: str | None = None,
        clock: WallClock | SimClock | None = None,
        instance: str | None = None,
        study: bool = False,
    ) -> None:
        super().__init__("tablet", namespace, zenoh_options, clock=clock, instance=instance)
        self.study = study
        if sim_camera is not None:
            self.keys.camera_frame(sim_camera)  # an id unusable in a key fails here, before any session
        self.sim_camera = sim_camera
        self.world = WorldView()
        self.constraints: ConstraintSet | None = None
        self.library: list[dict[str, Any]] | None = None  # None until a restrictor answers
        self.on_constraints: Callable[[ConstraintSet], None] = lambda msg: None
        self.on_library: Callable[[list[dict[str, Any]]], None] = lambda entries: None
        self.on_sim_frame: Callable[[CameraFrame], None] = lambda msg: None
        self.on_human_state: Callable[[HumanState], None] = lambda msg: None
        self.on_clock: Callable[[ClockMessage], None] = lambda msg: None
        self.on_mission_done: Callable[[Event], None] = lambda msg: None
        self._constraints_lock = threading.Lock()

    def setup(self) -> None:
        k = self.keys
        self.world.follow(self)
        self.subscribe(k.constraints(), ConstraintSet, self._constraints)
        if self.sim_camera is not None:
            self.subscribe(
                k.camera_frame(self.sim_camera), CameraFrame, lambda msg, key: self.on_sim_frame(msg), latest=True
            )
            self.log.info("viewer stream from %s", k.camera_frame(self.sim_camera))
        if self.study:
            self.subscribe(k.human_state(), HumanState, lambda msg, key: self.on_human_state(msg), latest=True)
            # Its own subscription: a wall-clock tablet (no SimClock) still needs the sim's rate and pause.
            self.subscribe(k.clock(), ClockMessage, lambda msg, key: self.on_clock(msg), latest=True)
            self.subscribe(k.event(), Event, self._event)
            self.advertise(k.participant_action())
            self.advertise(k.questionnaire())
        # A late joiner asks for the live set, and every page needs the library; off the worker,
        # since queries block.
        threading.Thread(target=self._fetch_constraints, name="tablet-constraints", daemon=True).start()
        threading.Thread(target=self._fetch_library, name="tablet-library", daemon=True).start()

    def _constraints(self, msg: ConstraintSet, _key: str = "") -> None:
        with self._constraints_lock:
            if self.constraints is not None and msg.version <= self.constraints.version:
                return  # an older set overtaken on the wire (or the query's answer after a newer publication)
            self.constraints = msg
        self.on_constraints(msg)

    def _event(self, msg: Event, _key: str) -> None:
        if msg.kind == "mission_done":
            self.on_mission_done(msg)

    def _fetch_constraints(self) -> None:
        newest = newest_constraints(self)
        if newest is not None:
            self._constraints(newest)

    def _fetch_library(self) -> None:
        library = wait_for_library(self, retry=LIBRARY_RETRY, what="feedback buttons on the tablet pages")
        if library is not None:
            # The page's script reads the entries as JSON maps.
            self.library = entries_to_wire(library.entries)
            self.on_library(self.library)

    def now(self) -> float:
        """Site-clock time for drawing (before the sim's first clock message: wall time)."""
        import time

        return self.clock.now() if self.clock.synced else time.time()

    def publish_overlay(self, overlay: Overlay, reason: str = "") -> None:
        self.publish(self.keys.overlay(overlay.camera), overlay, extra={"reason": reason} if reason else None)

    def publish_action(self, msg: ParticipantAction) -> None:
        self.publish(self.keys.participant_action(), msg)

    def publish_answers(self, msg: QuestionnaireAnswers) -> None:
        self.publish(self.keys.questionnaire(), msg)

    def send_feedback(self, kind: str, params: dict[str, Any]) -> FeedbackAck | None:
        """Blocks until the restrictor answers or :data:`FEEDBACK_TIMEOUT` passes (None)."""
        return send_feedback(self, kind, params, timeout=FEEDBACK_TIMEOUT, retry=1.0)
