"""What the experimenter's console shows of a running trial: a thread-safe picture, updated from
the trial's messages on the runner's worker and read by the console's web thread as a snapshot."""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Any

from protocol.events import data_to_wire
from protocol.messages import DoorState, Event, HumanState, ParticipantAction, QuestionnaireAnswers, RobotStatus

RECENT = 40  # lines of recent happenings the console lists
PAGE_QUIET = 30.0  # wall seconds without a word from the page before the console says so


class TrialProgress:
    def __init__(
        self,
        *,
        participant: str,
        trial: str,
        condition: str,
        attempt: int,
        world: str,
        questionnaires: list[str],
        site_time: Callable[[], float | None] = lambda: None,
    ) -> None:
        self._lock = threading.Lock()
        self._site_time = site_time
        self.participant = participant
        self.trial = trial
        self.condition = condition
        self.attempt = attempt
        self.world = world  # virtual | real
        self.phase = "starting"  # starting, consent, running, mission done, complete, incomplete
        self.outcome = ""
        self.consent = "not asked"
        self.paused = False
        self.experimenter_paused = False
        self.mission_done = False
        self.mission: dict[str, Any] = {}
        self.robots: dict[str, dict[str, Any]] = {}
        self.doors: dict[str, dict[str, Any]] = {}
        self.human: dict[str, Any] = {}
        self.her_doors: list[str] = []
        self.puzzle = {"placed": 0, "total": 0, "moves": 0, "done": False}
        self.view = ""
        self.feedback: list[dict[str, Any]] = []
        self.marks = 0
        self.questionnaires = {name: False for name in questionnaires}
        self.page_heard: float | None = None  # wall time of the page's last message
        self.tablet_alive = False
        self.tablet_urls: list[str] = []
        self.world_state = "starting"
        self.dropped = 0
        self.started = time.time()
        self.recent: collections.deque[dict[str, Any]] = collections.deque(maxlen=RECENT)

    # ------------------------------------------------------------------ updates (worker thread)

    def note(self, text: str, t: float | None = None) -> None:
        with self._lock:
            self._note(text, t)

    def _note(self, text: str, t: float | None) -> None:
        self.recent.append({"wall": round(time.time(), 3), "t": t, "text": text})

    def set(self, **fields: Any) -> None:
        with self._lock:
            for name, value in fields.items():
                setattr(self, name, value)

    def on_status(self, msg: RobotStatus) -> None:
        with self._lock:
            self.robots[msg.robot] = {
                "state": msg.state,
                "delivered": len(msg.delivered),
                "carrying": len(msg.carrying),
                "action": msg.action,
                "waiting_door": msg.waiting_door,
            }

    def on_door(self, msg: DoorState) -> None:
        with self._lock:
            self.doors[msg.door] = {"open": msg.open, "by": msg.by}

    def on_human(self, msg: HumanState) -> None:
        with self._lock:
            self.human = {"place": msg.place, "door": msg.door, "task_done": msg.task_done, "mode": msg.mode}
            self.her_doors = list(msg.doors)
            self.paused = msg.paused

    def on_event(self, msg: Event) -> None:
        with self._lock:
            if msg.kind == "mission_done":
                self.mission_done = True
                self.mission = data_to_wire(msg.data)
                if self.phase in ("running", "consent", "starting"):
                    self.phase = "mission done"
            what = " ".join(part for part in (msg.kind, msg.robot, msg.door, msg.object) if part)
            self._note(what, msg.stamp)

    def on_action(self, msg: ParticipantAction, from_page: bool) -> None:
        with self._lock:
            if from_page:
                self.page_heard = time.time()
            if msg.act == "puzzle_move":
                self.puzzle["placed"], self.puzzle["total"] = msg.placed, msg.total
                self.puzzle["moves"] += 1
                return  # too many to list
            if msg.act == "view":
                self.view = msg.view
                return
            if msg.act == "task_done":
                self.puzzle["done"] = True
            elif msg.act == "feedback":
                self.feedback.append({"t": msg.stamp, "door": msg.door, "minutes": msg.minutes, "kind": msg.note})
            elif msg.act == "mark":
                self.marks += 1
            elif msg.act == "consent":
                self.consent = msg.note
            detail = " ".join(part for part in (msg.door, msg.note) if part)
            self._note(f"{msg.act} {detail}".strip(), msg.stamp)

    def on_answers(self, msg: QuestionnaireAnswers, accepted: bool) -> None:
        with self._lock:
            self.page_heard = time.time()
            if accepted:
                self.questionnaires[msg.instrument] = True
            self._note(f"questionnaire {msg.instrument} {'received' if accepted else 'refused'}", msg.stamp)

    def set_tablet_alive(self, alive: bool) -> None:
        with self._lock:
            self.tablet_alive = alive

    def add_tablet_url(self, url: str) -> None:
        with self._lock:
            if url not in self.tablet_urls:
                self.tablet_urls.append(url)

    def count_dropped(self) -> None:
        with self._lock:
            self.dropped += 1

    # ------------------------------------------------------------------ reading (any thread)

    def snapshot(self) -> dict[str, Any]:
        site_time = self._site_time()
        now = time.time()
        with self._lock:
            page = "not heard yet"
            if self.page_heard is not None:
                quiet = now - self.page_heard
                page = f"heard {quiet:.0f} s ago" + (" (closed or offline?)" if quiet > PAGE_QUIET else "")
            return {
                "participant": self.participant,
                "trial": self.trial,
                "condition": self.condition,
                "attempt": self.attempt,
                "world": self.world,
                "phase": self.phase,
                "outcome": self.outcome,
                "consent": self.consent,
                "site_time": None if site_time is None else round(site_time, 1),
                "wall_elapsed": round(now - self.started, 1),
                "paused": self.paused,
                "experimenter_paused": self.experimenter_paused,
                "mission_done": self.mission_done,
                "mission": {k: self.mission.get(k) for k in ("completed", "time", "team_completion_time", "reason")},
                "robots": dict(sorted(self.robots.items())),
                "doors": dict(sorted(self.doors.items())),
                "human": dict(self.human),
                "her_doors": list(self.her_doors),
                "puzzle": dict(self.puzzle),
                "view": self.view,
                "feedback": {"sent": len(self.feedback), "last": self.feedback[-1] if self.feedback else None},
                "marks": self.marks,
                "questionnaires": dict(self.questionnaires),
                "page": page,
                "tablet_alive": self.tablet_alive,
                "tablet_urls": list(self.tablet_urls),
                "world_state": self.world_state,
                "dropped": self.dropped,
                "recent": list(self.recent)[::-1],
            }
