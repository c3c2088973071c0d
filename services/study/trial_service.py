"""The runner's own Zenoh client during a trial: what it hears and what it says.

A :class:`~runtime.service.Service` named ``study`` (it joins a secured deployment as the
``supervisor`` role, which may publish ``study/control`` and ``participant/*``). It hears the
trial's messages — ``event``, ``participant/action``, ``participant/answers``, ``human/state``,
``door/*/state``, ``door/*/sensor``, ``constraints``, ``study/control`` — on ordered subscriptions,
so they reach the trial in the order they came over the link, plus the robots' statuses (newest
only) and whether the tablet page's server is alive. It publishes the experimenter's console's
words: StudyControl (pause, resume, abort), ParticipantAction ``mark``, and in a real world a
door's DoorState on ``door/<d>/sensor`` (``by="experimenter"``).

It only moves messages: what they mean for the trial is :class:`~.trial.TrialRun`'s business
(the ``sink``), whose handlers run on this service's worker thread.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import zenoh

from protocol.messages import (
    ConstraintSet,
    DoorState,
    Event,
    HumanState,
    Message,
    ParticipantAction,
    QuestionnaireAnswers,
    RobotStatus,
    StudyControl,
)
from runtime.clock import SimClock, WallClock
from runtime.service import Service
from runtime.transport import ZenohOptions

NAME = "study"


class TrialSink(Protocol):
    """What the service hands the trial (on the worker), and asks of it."""

    def on_message(self, msg: Message, key: str) -> None: ...

    def on_status(self, msg: RobotStatus) -> None: ...

    def on_tablet(self, alive: bool) -> None: ...

    def on_signal(self, name: str) -> None: ...


class TrialService(Service):
    def __init__(
        self,
        namespace: str,
        zenoh_options: ZenohOptions,
        *,
        participant: str,
        trial: str,
        clock: WallClock | SimClock | None = None,
    ) -> None:
        super().__init__(NAME, namespace, zenoh_options, clock=clock)
        self.participant = participant
        self.trial = trial
        self.sink: TrialSink | None = None
        self._tablets: set[str] = set()

    def setup(self) -> None:
        k = self.keys
        logged: list[tuple[str, type[Message]]] = [
            (k.event(), Event),
            (k.participant_action(), ParticipantAction),
            (k.questionnaire(), QuestionnaireAnswers),
            (k.human_state(), HumanState),
            (k.door_state("*"), DoorState),
            (k.door_sensor("*"), DoorState),
            (k.constraints(), ConstraintSet),
            (k.study_control(), StudyControl),
        ]
        for key, msg_type in logged:
            self.subscribe(key, msg_type, self._on_message, ordered=True)
        self.subscribe(k.robot_status("*"), RobotStatus, self._on_status, latest=True)
        for key in (k.study_control(), k.participant_action()):
            self.advertise(key)
        self.hold(
            self.session.liveliness().declare_subscriber(k.liveliness("tablet", "*"), self._on_token, history=True)
        )

    # ------------------------------------------------------------------ hearing

    def suffix(self, key: str) -> str:
        """The key after ``arroch/<namespace>/`` (what log.jsonl records)."""
        prefix = self.keys.prefix + "/"
        return key[len(prefix) :] if key.startswith(prefix) else key

    def _on_message(self, msg: Message, key: str) -> None:
        if self.sink is not None:
            self.sink.on_message(msg, self.suffix(key))

    def _on_status(self, msg: RobotStatus, _key: str) -> None:
        if self.sink is not None:
            self.sink.on_status(msg)

    def _on_token(self, sample: Any) -> None:
        """The tablet page's server coming and going (Zenoh's thread: the sink's handler is thread-safe)."""
        instance = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.kind == zenoh.SampleKind.PUT:
            self._tablets.add(instance)
        else:
            self._tablets.discard(instance)
        if self.sink is not None:
            self.sink.on_tablet(bool(self._tablets))

    def on_stop_signal(self) -> None:
        self.log.info("received %s: ending the trial", self.signals.name)
        if self.sink is not None:
            self.sink.on_signal(self.signals.name)
        self.stop()

    # ------------------------------------------------------------------ saying

    def send_control(self, command: str, reason: str = "") -> None:
        self.publish(self.keys.study_control(), StudyControl(command=command, trial=self.trial, reason=reason[:512]))

    def send_mark(self, note: str) -> None:
        self.publish(
            self.keys.participant_action(),
            ParticipantAction(
                participant=self.participant, trial=self.trial, act="mark", note=note[:512], wall=time.time()
            ),
        )

    def send_door(self, door: str, is_open: bool) -> None:
        """A real door's state as the experimenter reports it (ValueError for an id that is no key chunk)."""
        self.publish(self.keys.door_sensor(door), DoorState(door=door, open=is_open, by="experimenter"))
