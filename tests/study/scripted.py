"""Scripted participants: the simulated human (services.sim.human.HumanModel) with known parameters,
her trials written into a study folder as the page and the simulator would log them.

A trial: robots come to her door one after another (each comes back a while after passing through
it, a fixed number of times) and wait there until the door is open; she is the model, stepped tick
by tick, seeing who waits and whether the door is open. What she does becomes log.jsonl records:

- the simulator's: Event ``mission_started`` / ``waiting_at_door`` / ``door_opened`` /
  ``door_closed`` / ``delivered`` / ``mission_done`` (with the metrics), DoorState and HumanState
  (her place: desk, to_door, at_door, back) at the moment each happens;
- the page's ParticipantActions: ``view`` (the puzzle at the start; the AR view while she declares),
  ``go_to_door``, ``open_door``, ``back_to_desk`` (a walk turned back), ``feedback`` (a2(N) as
  ``door_unavailable`` with its minutes), ``puzzle_move`` and ``task_done``.

Her puzzle moves come at a steady rate of work: ``moves`` moves spread evenly over her task's work
time, the last one finishing it. An interruption's cost appears as work that makes no progress
right after she is back at her desk, so her first move after a trip comes ``interruption_cost``
seconds later than it would have.

One deliberate difference from the model (``cost_on_every_trip``, on by default): the model charges
``interruption_cost`` only to trips made during a focus interval, but a participant pays it on
every trip, and that is what ``arroch study calibrate`` measures. With it off the scripted
participant is exactly the model, and the calibration then measures the model's mean cost per trip.

Every time here is exact (the model accounts for time exactly within a tick): decisions and trips
start at tick ends, legs of a trip end when they end, puzzle moves when the work reaches them.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from services.sim.human import Declare, HumanConfig, HumanModel, OpenDoor, TaskDone
from services.sim.streams import Streams
from services.study.layout import CONDITION_METHOD, StudyFolder, StudyPlan, write_json

DOOR = "d_office"


@dataclass(frozen=True)
class ScriptConfig:
    """The scripted world. Sources: swing_time is the simulator's DoorConfig default; the rest is
    chosen to keep robots coming through a whole trial (three robots, as in the paper's real-world
    runs) with a door that is often shut when one arrives."""

    tick: float = 0.1  # s per model step (the simulator's default is 0.05; the model is exact at any tick)
    robots: int = 3
    deliveries: int = 5  # times each robot passes her door
    walk: float = 6.0  # m from her desk to where she opens the door (chosen)
    swing_time: float = 1.5  # s for the door to become passable once she opens it (DoorConfig default)
    hold_time: float = 8.0  # s it stays passable (chosen, shorter than the office site's 20 s: more waits)
    first_arrival: tuple[float, float] = (0.0, 60.0)  # s, uniform (chosen)
    return_after: tuple[float, float] = (40.0, 120.0)  # s, uniform, from passing the door to the next arrival
    moves: int = 48  # puzzle moves over her task, a third of them placing a piece (a 4x4 puzzle: 16)
    pieces: int = 16
    time_limit: float = 4000.0  # s: a safety stop; no scripted trial comes near it
    cost_on_every_trip: bool = True


class ScriptedHuman(HumanModel):
    """The model, optionally paying the interruption cost on every trip (module docstring)."""

    every_trip = True

    def _go(self, door: str, t: float) -> None:
        charged_by_model = self.in_focus(t) and not self.done
        super()._go(door, t)
        if self.every_trip and not charged_by_model and not self.done:
            self.counters.interruptions += 1
            self.counters.time_lost += self.config.interruption_cost


@dataclass
class TrialTruth:
    """What the model did in one trial: the numbers the calibration should find."""

    task_duration: float
    done_time: float | None
    ar_decisions: int
    ar_triggers: int
    declarations: int
    door_trips: int
    interruptions: int
    time_lost: float
    focus: list[dict[str, Any]] = field(default_factory=list)


class _Log:
    def __init__(self, participant: str, trial: str) -> None:
        self.records: list[dict[str, Any]] = []
        self.participant = participant
        self.trial = trial

    def add(self, t: float, type_: str, key: str, **fields: Any) -> None:
        self.records.append({"t": t, "wall": 1.7e9 + t, "key": key, "type": type_, "stamp": t, **fields})

    def event(self, t: float, kind: str, robot: str = "", door: str = "", data: Any = None) -> None:
        self.add(t, "Event", "event", kind=kind, robot=robot, door=door, object="", data=data)

    def act(self, t: float, act: str, **fields: Any) -> None:
        self.add(t, "ParticipantAction", "participant/action", participant=self.participant, trial=self.trial,
                 act=act, **fields)  # fmt: skip

    def place(self, t: float, place: str, task_done: bool = False) -> None:
        self.add(t, "HumanState", "human/state", mode="participant", place=place, door=DOOR if place != "desk" else "",
                 doors=[DOOR], task_done=task_done)  # fmt: skip

    def door(self, t: float, is_open: bool) -> None:
        self.add(t, "DoorState", f"door/{DOOR}/state", door=DOOR, open=is_open, by="human" if is_open else "")


def run_trial(
    human: HumanConfig, method: str, seed: int, participant: str, trial: str, cfg: ScriptConfig = ScriptConfig()
) -> tuple[list[dict[str, Any]], dict[str, Any], TrialTruth]:
    """One trial: (log records, metrics.json, what the model did)."""
    model = ScriptedHuman(human, method, Streams(seed), (0.0, 0.0), {DOOR: (cfg.walk, 0.0)})
    model.every_trip = cfg.cost_on_every_trip
    rng = np.random.default_rng([seed, 7])
    log = _Log(participant, trial)
    robots = [f"r{i}" for i in range(cfg.robots)]
    arrive = {r: float(rng.uniform(*cfg.first_arrival)) for r in robots}
    passes = dict.fromkeys(robots, 0)
    robot_done: dict[str, float] = {}
    waiting: dict[str, float] = {}
    door = "closed"  # closed | opening | open
    passable_at = close_at = math.inf
    debt = effective = 0.0
    step_work = model.task_duration / cfg.moves
    next_move = 1
    declaring = False
    log.event(0.0, "mission_started", data={"method": method, "seed": seed})
    log.place(0.0, "desk")
    log.door(0.0, False)
    log.act(0.0, "view", view="puzzle")
    ticks = 0
    end = None
    while end is None:
        now = round(ticks * cfg.tick, 9)
        ticks += 1
        t1 = round(ticks * cfg.tick, 9)
        # The door: becomes passable (the robots waiting go through), then closes.
        if door == "opening" and passable_at <= t1:
            door = "open"
            log.event(passable_at, "door_opened", door=DOOR, data={"by": "human"})
            log.door(passable_at, True)
            for r in sorted(waiting):
                del waiting[r]
                _passed(r, passable_at, passes, arrive, robot_done, cfg, rng, log)
        if door == "open" and close_at <= t1:
            door = "closed"
            log.event(close_at, "door_closed", door=DOOR)
            log.door(close_at, False)
        # Robots reaching the door: through it if passable, else they wait.
        for r in robots:
            if r in waiting or r in robot_done or arrive[r] > t1:
                continue
            if door == "open":
                _passed(r, t1, passes, arrive, robot_done, cfg, rng, log)
            else:
                waiting[r] = t1
                log.event(t1, "waiting_at_door", robot=r, door=DOOR)
        # She: what she was doing before the step, then the step, then what changed.
        trip0 = model.trip
        leg0, left0 = (trip0.leg, trip0.left) if trip0 else (None, 0.0)
        c0 = model.counters
        away0, declaring0, lost0, trips0 = c0.time_away, c0.time_declaring, c0.time_lost, c0.door_trips
        turned0, work0, pause0 = c0.turned_back, model.work_done, model.pause
        actions = model.step(now, cfg.tick, {DOOR: dict(waiting)}, {DOOR: door != "closed"})
        c = model.counters
        spent_away = c.time_away - away0
        spent_declaring = c.time_declaring - declaring0
        new_trip = c.door_trips > trips0
        # The trip's legs, each at the moment it ended.
        if leg0 == "to" and any(isinstance(a, OpenDoor) for a in actions):
            o = now + left0
            log.act(o, "open_door", door=DOOR)
            log.place(o, "at_door")
            door, passable_at, close_at = "opening", o + cfg.swing_time, o + cfg.swing_time + cfg.hold_time
        elif leg0 == "to" and c.turned_back > turned0:
            back_at = now + left0 if spent_away >= left0 - 1e-9 else t1
            log.act(back_at, "back_to_desk", door=DOOR)
            log.place(back_at, "back")
        elif leg0 == "at" and model.trip is not None and model.trip.leg == "back":
            log.place(now + left0, "back")
        if leg0 == "back" and (model.trip is None or new_trip):
            log.place(now + left0, "desk")
        # Declaring: the AR view from the a2(N) until the pause is spent.
        if declaring and pause0 > 0 and model.pause <= 1e-12 and (model.trip is None or new_trip):
            log.act(now + spent_away + spent_declaring, "view", view="puzzle")
            declaring = False
        # Work: the interruption's cost first (no progress), then moves as the work reaches them.
        gained = model.work_done - work0
        if gained > 0:
            start = now + spent_away + spent_declaring
            pay = min(debt, gained)
            debt -= pay
            before = effective
            effective += gained - pay
            while next_move <= cfg.moves and next_move * step_work <= effective + 1e-9:
                at = start + pay + (next_move * step_work - before)
                log.act(at, "puzzle_move", piece=next_move, correct=next_move % 3 == 0,
                        placed=min(cfg.pieces, next_move // 3), total=cfg.pieces)  # fmt: skip
                next_move += 1
        for a in actions:
            if isinstance(a, TaskDone):
                log.act(a.time, "task_done")
                log.place(a.time, "desk", task_done=True)
            elif isinstance(a, Declare):
                if not declaring:
                    log.act(t1, "view", view="ar")
                    declaring = True
                log.act(t1, "feedback", door=a.door, minutes=a.minutes, note="door_unavailable")
        if new_trip:
            debt += c.time_lost - lost0
            log.act(t1, "go_to_door", door=DOOR)
            log.place(t1, "to_door")
        if (model.done and len(robot_done) == len(robots)) or t1 >= cfg.time_limit:
            end = t1
    completed = model.done and len(robot_done) == len(robots)
    agents: dict[str, float | None] = {r: robot_done.get(r) for r in robots}
    agents["human"] = model.done_time
    finished = [v for v in agents.values() if v is not None]
    metrics = {
        "completed": completed,
        "time": end,
        "team_completion_time": max(finished) if completed else None,
        "agent_completion_times": agents,
        "human_door_openings": model.counters.door_openings,
        "feedback": {"sent": model.counters.declarations, "accepted": model.counters.declarations},
        "robots": {r: {"completion_time": robot_done.get(r), "passes": passes[r]} for r in robots},
        "human": {
            "completion_time": model.done_time,
            "door_openings": model.counters.door_openings,
            "door_trips": model.counters.door_trips,
            "time_away": model.counters.time_away,
            "participant": True,
        },
        "params": {"method": method, "seed": seed, "engine": {"tick": cfg.tick}, "human": asdict(human)},
    }
    log.event(end, "mission_done", data=metrics)
    truth = TrialTruth(
        task_duration=model.task_duration,
        done_time=model.done_time,
        ar_decisions=model.counters.ar_decisions,
        ar_triggers=model.counters.ar_triggers,
        declarations=model.counters.declarations,
        door_trips=model.counters.door_trips,
        interruptions=model.counters.interruptions,
        time_lost=model.counters.time_lost,
        focus=model.focus_report(),
    )
    return sorted(log.records, key=lambda r: r["t"]), metrics, truth


def _passed(
    robot: str,
    t: float,
    passes: dict[str, int],
    arrive: dict[str, float],
    robot_done: dict[str, float],
    cfg: ScriptConfig,
    rng: np.random.Generator,
    log: _Log,
) -> None:
    passes[robot] += 1
    log.event(t, "delivered", robot=robot, door=DOOR)
    if passes[robot] >= cfg.deliveries:
        robot_done[robot] = t
    else:
        arrive[robot] = t + float(rng.uniform(*cfg.return_after))


def write_trial(
    folder: StudyFolder,
    plan: StudyPlan,
    pid: str,
    tid: str,
    records: list[dict[str, Any]],
    metrics: dict[str, Any],
    answers: dict[str, dict[str, int]] | None = None,
    status: str = "complete",
) -> None:
    """One trial's files as the runner leaves them: trial.json, log.jsonl, run/<stamp>/metrics.json, answers."""
    trial = next(t for t in plan.participant(pid).trials if t.id == tid)
    state = folder.trial_state(pid, trial)
    state.status = status  # type: ignore[assignment]
    state.attempt = 1
    state.reason = "" if status == "complete" else "page closed and not resumed"
    folder.save_trial_state(state)
    path = folder.log_file(pid, tid)
    path.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    write_json(folder.run_dir(pid, tid) / "20260101T000000Z" / "metrics.json", metrics)
    if answers is not None:
        write_json(folder.questionnaire_file(pid, tid), answers)


def write_study(
    root: Path, plan: StudyPlan, human: HumanConfig, cfg: ScriptConfig = ScriptConfig()
) -> dict[str, TrialTruth]:
    """Every trial of ``plan`` played by the scripted participant; returns the truth per trial id.

    Her draws (task time, focus intervals, decisions) come from the trial's puzzle seed: a new draw
    in every trial, as the model makes for every mission (the scripted participants have no personal
    pace shared across their trials).
    """
    folder = StudyFolder(root)
    write_json(folder.plan_file, plan)
    truths = {}
    for p in plan.participants:
        for t in p.trials:
            records, metrics, truth = run_trial(human, CONDITION_METHOD[t.condition], t.puzzle_seed, p.id, t.id, cfg)
            write_trial(folder, plan, p.id, t.id, records, metrics)
            truths[t.id] = truth
    return truths
