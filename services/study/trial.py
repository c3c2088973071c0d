"""One attempt of a trial while its world runs: what the messages mean, and when the trial ends.

Everything here runs on the runner's service worker (messages, the tick, the console's commands,
which come through a queue), so the trial's state needs no locks; the console reads
:class:`~.progress.TrialProgress`, which has its own.

- **Consent** (a participant's first trial): the world starts with the page showing the consent form
  and the mission held: the runner keeps the simulator paused (StudyControl ``pause``, repeated until
  HumanState says ``paused``) until she answers. ``given``: ``consent.json`` is written and the world
  resumes. ``refused``: ``consent.json`` says so, the world is aborted and her trials are marked
  incomplete "consent refused". A ``refused`` after consent was given is her withdrawal: the same,
  "consent withdrawn".
- **The experimenter's pause** is held the same way: the runner says what it wants (paused or
  not) until the world's HumanState agrees, so a simulator restarted by ``up`` is paused again.
- **The end**: complete once the mission is done and every questionnaire the plan asks has come;
  incomplete when the world stops before the mission ends (``up`` crashed or could not start), when
  the experimenter aborts (StudyControl ``abort`` goes to the world first) or ends the trial after
  the mission without the questionnaire, when consent is refused, or when the runner is told to stop.
- **Bad input** (a message of another participant or trial, answers off their scale, a consent that
  is neither given nor refused) is dropped, counted and logged with the reason; the run's recording
  keeps every message anyway.
"""

from __future__ import annotations

import concurrent.futures
import logging
import queue
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from protocol.events import data_to_wire
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

from .layout import StudyFolder
from .page import record_consent
from .progress import TrialProgress
from .trial_log import Questionnaires, TrialLog
from .trial_service import TrialService
from .world import World

log = logging.getLogger("arroch.study.run")

HOLD_PERIOD = 0.5  # wall seconds between two pauses while the world has not said it is paused
# ... while nothing at all has been heard of her in the world: the simulator may be starting, and the
# sooner a pause follows its subscription, the less site time runs before she has consented.
HOLD_PERIOD_UNHEARD = 0.1
RESUME_PERIOD = 1.0  # ... between two resumes while it still says paused
HOLD_PATIENCE = 60.0  # wall seconds the world may leave a pause or resume unanswered before a warning (up starts
# the simulator last, once the others are up)
ABORT_GRACE = 1.0  # wall seconds the world gets to hear an abort (and say mission_done) before the end
MAX_NOTE = 512
LOG_DROPS = 10  # drops logged one by one; after that every 100th


class CommandRefused(Exception):
    """A console command that cannot be done now; the message says why, for the console."""


@dataclass
class Command:
    kind: str
    args: dict[str, Any]
    future: concurrent.futures.Future = field(default_factory=concurrent.futures.Future)


class TrialRun:
    """The trial's state while its world runs (the sink of :class:`~.trial_service.TrialService`)."""

    def __init__(
        self,
        *,
        folder: StudyFolder,
        participant: str,
        trial: str,
        world_kind: str,
        world: World,
        progress: TrialProgress,
        trial_log: TrialLog,
        questionnaires: Questionnaires,
        consent_required: bool,
        consent_sha256: str,
        on_urls: Callable[[list[str]], None] = lambda urls: None,
    ) -> None:
        self.folder = folder
        self.pid = participant
        self.tid = trial
        self.world_kind = world_kind
        self.world = world
        self.progress = progress
        self.log = trial_log
        self.questionnaires = questionnaires
        self.consent = "pending" if consent_required else "earlier"  # pending | given | earlier | refused
        self.consent_sha256 = consent_sha256
        self.on_urls = on_urls
        self.service: TrialService | None = None
        self.commands: queue.Queue[Command] = queue.Queue()
        self.outcome: tuple[str, str] | None = None  # (complete|incomplete, reason)
        self.consent_ended = ""  # "consent refused" / "consent withdrawn": her other trials end too
        self.mission_done = False
        self.mission: dict[str, Any] = {}
        self.world_paused: bool | None = None  # what the world's HumanState last said
        self.experimenter_paused = False
        self.drops: Counter[str] = Counter()
        self._stop_at: float | None = None
        self._last_control = 0.0
        self._pause_said = False  # a pause went out (it may still be on its way to the world)
        self._last_said = ""  # the last control said, "pause" or "resume" ("" before any)
        self._unanswered_since: float | None = None
        self._warned_unanswered = False
        self._world_exit_noted = False
        self._urls_shown = False
        progress.set(consent="to be given on the tablet page" if consent_required else "given before")
        progress.set(phase="consent" if consent_required else "running")

    def attach(self, service: TrialService) -> None:
        self.service = service
        service.sink = self
        service.every(0.1, self.tick, first=0.0)

    # ------------------------------------------------------------------ messages (worker)

    def on_message(self, msg: Message, key: str) -> None:
        if isinstance(msg, ParticipantAction):
            self._on_action(msg, key)
        elif isinstance(msg, QuestionnaireAnswers):
            self._on_answers(msg, key)
        elif isinstance(msg, Event):
            self.log.record(msg, key)
            self.progress.on_event(msg)
            if msg.kind == "mission_done" and not self.mission_done:
                self.mission_done = True
                self.mission = data_to_wire(msg.data)
                log.info("mission done at t=%.1f s%s", msg.stamp, self._waiting_for())
        elif isinstance(msg, HumanState):
            self.log.record(msg, key)
            self.progress.on_human(msg)
            self.world_paused = msg.paused
        elif isinstance(msg, DoorState):
            self.log.record(msg, key)
            if key.endswith("/state"):
                self.progress.on_door(msg)
        elif isinstance(msg, StudyControl):
            if msg.trial and msg.trial != self.tid:
                return self._drop(key, msg, f"trial: {msg.trial!r} is not this trial ({self.tid})")
            self.log.record(msg, key)
        elif isinstance(msg, ConstraintSet):
            self.log.record(msg, key)

    def on_status(self, msg: RobotStatus) -> None:
        self.progress.on_status(msg)

    def on_tablet(self, alive: bool) -> None:
        self.progress.set_tablet_alive(alive)

    def _not_hers(self, participant: str, trial: str) -> str:
        if participant != self.pid:
            return f"participant: {participant!r} is not this trial's ({self.pid})"
        if trial and trial != self.tid:
            return f"trial: {trial!r} is not this trial ({self.tid})"
        return ""

    def _on_action(self, msg: ParticipantAction, key: str) -> None:
        problem = self._not_hers(msg.participant, msg.trial)
        if problem:
            return self._drop(key, msg, problem)
        self.log.record(msg, key)
        own = self.service is not None and msg.src == self.service.src
        self.progress.on_action(msg, from_page=not own)
        if msg.act == "consent":
            self._on_consent(msg, key)

    def _on_answers(self, msg: QuestionnaireAnswers, key: str) -> None:
        problem = self._not_hers(msg.participant, msg.trial)
        if problem:
            return self._drop(key, msg, problem)
        problem = self.questionnaires.take(msg)
        self.progress.on_answers(msg, accepted=not problem)
        if problem:  # not hers to analyse (the run's recording keeps it)
            return self._drop(key, msg, problem)
        self.log.record(msg, key)
        log.info("questionnaire %s received%s", msg.instrument, self._waiting_for())

    def _drop(self, key: str, msg: Message, reason: str) -> None:
        self.drops[reason.split(":", 1)[0]] += 1
        total = sum(self.drops.values())
        self.progress.count_dropped()
        if total <= LOG_DROPS or total % 100 == 0:
            log.warning("dropped a %s on %s from %s: %s (%d dropped so far)", msg.TYPE, key, msg.src, reason, total)

    def _on_consent(self, msg: ParticipantAction, key: str) -> None:
        if msg.note not in ("given", "refused"):
            return self._drop(key, msg, f"note: consent is 'given' or 'refused', not {msg.note!r}")
        given = msg.note == "given"
        if self.consent == "pending":
            record_consent(self.folder, self.pid, given, self.consent_sha256)
            if given:
                self.consent = "given"
                self.progress.set(consent="given", phase="running")
                log.info("%s gave consent: the world goes on", self.pid)
                self._hold(time.monotonic(), now_please=True)
            else:
                self.consent = "refused"
                self.progress.set(consent="refused")
                log.warning("%s refused consent: the trial ends here and none of hers will run", self.pid)
                self.consent_ended = "consent refused"
                self.end("incomplete", "consent refused", abort=True)
        elif not given and self.consent in ("given", "earlier"):
            record_consent(self.folder, self.pid, False, self.consent_sha256)
            self.consent = "refused"
            self.progress.set(consent="withdrawn")
            log.warning("%s withdrew consent: the trial ends here", self.pid)
            self.consent_ended = "consent withdrawn"
            self.end("incomplete", "consent withdrawn", abort=True)

    def _waiting_for(self) -> str:
        if self.outcome is not None:
            return ""
        if not self.mission_done:
            return "; waiting for the mission to end"
        missing = self.questionnaires.missing
        return f"; waiting for the questionnaire ({', '.join(missing)})" if missing else ""

    # ------------------------------------------------------------------ the tick (worker)

    def tick(self) -> None:
        now = time.monotonic()
        self._run_commands()
        self._show_urls()
        self._watch_world()
        if self.outcome is None and self.mission_done and self.questionnaires.complete:
            self.end("complete")
        self._hold(now)
        if self._stop_at is not None and time.monotonic() >= self._stop_at and self.service is not None:
            self.service.stop()

    def _show_urls(self) -> None:
        if self._urls_shown:
            return
        urls = self.world.urls_settled()
        if urls:
            self._urls_shown = True
            for url in urls:
                self.progress.add_tablet_url(url)
            self.on_urls(urls)

    def _watch_world(self) -> None:
        if self._world_exit_noted or self.world.running():
            return
        self._world_exit_noted = True
        how = self.world.describe_exit()
        self.progress.set(world_state=f"stopped ({how})")
        if self.outcome is not None:
            return
        if not self.mission_done:
            hint = " (bad options: see its output above)" if self.world.returncode() == 2 else ""
            for line in self.world.last_lines():
                log.error("world: %s", line)
            self.end("incomplete", f"the world stopped before the mission ended: arroch up {how}{hint}")
        elif self.questionnaires.complete:
            self.end("complete")
        else:
            log.warning(
                "the world stopped (%s) after the mission; the questionnaire (%s) has not come: "
                "end the trial from the console, or Ctrl-C",
                how,
                ", ".join(self.questionnaires.missing),
            )

    def _hold(self, now: float, *, now_please: bool = False) -> None:
        """Say pause or resume until the world's HumanState shows what the trial wants."""
        if self.service is None or self.outcome is not None or self.mission_done:
            return
        want_paused = self.consent == "pending" or self.experimenter_paused
        # A pause must be seen taken. A resume need not be when the world was never told to pause (no
        # HumanState yet counts as running); once a pause went out it may still be on its way, so the
        # world must be seen running.
        # A resume is said after the last pause whatever the world shows: a HumanState saying "not
        # paused" may be older than a pause still on its way (seen under load: she consented, the
        # world had not yet heard the pauses said while it waited, and took them after). Controls from
        # one sender arrive in order, so the last said is the one the world ends with.
        if want_paused:
            settled = self.world_paused is True
        elif self._last_said == "pause":
            settled = False
        else:
            settled = self.world_paused is False if self._pause_said else not self.world_paused
        if settled:
            self._unanswered_since = None
            return
        if self._unanswered_since is None:
            self._unanswered_since = now
        elif now - self._unanswered_since > HOLD_PATIENCE and not self._warned_unanswered:
            self._warned_unanswered = True
            log.warning(
                "the world has not shown itself %s for %.0f s: is the simulator up, in participant mode?",
                "paused" if want_paused else "resumed",
                HOLD_PATIENCE,
            )
        period = (HOLD_PERIOD_UNHEARD if self.world_paused is None else HOLD_PERIOD) if want_paused else RESUME_PERIOD
        if now_please or now - self._last_control >= period:
            self._say_hold(now, paused=want_paused)

    def _say_hold(self, now: float, *, paused: bool) -> None:
        assert self.service is not None
        if paused:
            why = "waiting for her consent" if self.consent == "pending" else "paused by the experimenter"
            self.service.send_control("pause", why)
            self._pause_said = True
        else:
            self.service.send_control("resume")
        self._last_said = "pause" if paused else "resume"
        self._last_control = now

    # ------------------------------------------------------------------ the end

    def end(self, status: str, reason: str = "", *, abort: bool = False) -> None:
        """Decide the trial's outcome (once) and stop the service's loop (``abort``: after the world
        has been told, and given :data:`ABORT_GRACE` to answer)."""
        if self.outcome is not None:
            return
        self.outcome = (status, reason)
        self.progress.set(phase=status, outcome=reason)
        log.info("trial %s: %s%s", self.tid, status, f" ({reason})" if reason else "")
        if abort and self.service is not None and self.world.running():
            self.service.send_control("abort", reason)
            self._stop_at = time.monotonic() + ABORT_GRACE
        else:
            self._stop_at = time.monotonic()

    def on_signal(self, name: str) -> None:
        if self.outcome is None:
            reason = f"interrupted: the runner received {name}"
            if self.mission_done:
                reason += f" after the mission, before the questionnaire ({', '.join(self.questionnaires.missing)})"
            self.outcome = ("incomplete", reason)
            self.progress.set(phase="incomplete", outcome=reason)
            if self.service is not None and self.world.running() and not self.mission_done:
                self.service.send_control("abort", reason)

    # ------------------------------------------------------------------ the console's commands

    def submit(self, kind: str, **args: Any) -> concurrent.futures.Future:
        """From any thread: queue a command for the worker; the future holds its answer (a dict) or
        :class:`CommandRefused`."""
        command = Command(kind, args)
        self.commands.put(command)
        return command.future

    def _run_commands(self) -> None:
        while True:
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                return
            if not command.future.set_running_or_notify_cancel():  # the console gave up waiting
                continue
            try:
                command.future.set_result(self._command(command.kind, command.args))
            except CommandRefused as exc:
                command.future.set_exception(exc)
            except Exception as exc:  # a bug must not end the trial: say it to the console and the log
                log.exception("console command %s failed", command.kind)
                command.future.set_exception(CommandRefused(f"{command.kind} failed: {exc}"))

    def refuse_pending(self) -> None:
        """After the end: every command still queued is refused."""
        while True:
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                return
            if command.future.set_running_or_notify_cancel():
                command.future.set_exception(CommandRefused("the trial has ended"))

    def _command(self, kind: str, args: dict[str, Any]) -> dict[str, Any]:
        if self.outcome is not None or self.service is None:
            raise CommandRefused("the trial has ended")
        if kind == "mark":
            note = str(args.get("note", "")).strip()
            if not note:
                raise CommandRefused("note: say what to mark")
            self.service.send_mark(note[:MAX_NOTE])
            return {"marked": note[:MAX_NOTE]}
        if kind == "pause":
            if self.mission_done:
                raise CommandRefused("the mission is over: nothing to pause")
            self.experimenter_paused = True
            self.progress.set(experimenter_paused=True)
            self._say_hold(time.monotonic(), paused=True)  # said at once; the hold repeats it until seen
            return {"paused": True}
        if kind == "resume":
            if self.consent == "pending":
                raise CommandRefused("her consent has not been given: the world stays paused until it is")
            self.experimenter_paused = False
            self.progress.set(experimenter_paused=False)
            self._say_hold(time.monotonic(), paused=False)
            return {"paused": False}
        if kind == "door":
            return self._door(args)
        if kind == "abort":
            reason = str(args.get("reason", "")).strip()
            if not reason:
                raise CommandRefused("reason: say why the trial is aborted (it is kept with the trial)")
            self.end("incomplete", f"aborted by the experimenter: {reason}"[:MAX_NOTE], abort=True)
            return {"aborted": reason}
        if kind == "end":
            if not self.mission_done:
                raise CommandRefused("the mission is still running: abort the trial instead")
            if self.questionnaires.complete:
                self.end("complete")
            else:
                self.end("incomplete", f"no questionnaire ({', '.join(self.questionnaires.missing)} not received)")
            return {"ended": self.outcome[0] if self.outcome else ""}
        raise CommandRefused(f"unknown command {kind!r}")

    def _door(self, args: dict[str, Any]) -> dict[str, Any]:
        assert self.service is not None
        if self.world_kind != "real":
            raise CommandRefused("a virtual world's door is hers to open on the page")
        door = str(args.get("door", ""))
        is_open = args.get("open", True)
        if not isinstance(is_open, bool):
            raise CommandRefused("open: true or false")
        known = self.progress.snapshot()["her_doors"]
        if known and door not in known:
            raise CommandRefused(f"door: {door!r} is not one of hers ({', '.join(known)})")
        try:
            self.service.send_door(door, is_open)
        except ValueError as exc:
            raise CommandRefused(f"door: {exc}") from None
        return {"door": door, "open": is_open}
