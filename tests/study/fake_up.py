"""A stand-in for ``arroch up`` in the study runner's tests: a real process on real Zenoh that says
what a participant's world would, without planner, simulator or page.

  python -m tests.study.fake_up [arroch up's options...]      (scenario from FAKE_UP_SCENARIO)

It takes up's options as the runner gives them (``--router-listen``, ``--namespace``, ``--run-dir``,
``--study-trial``; the rest is ignored), is the router itself (a session in router mode listening
where up's router would), prints a tablet URL as up does, creates ``<run-dir>/<timestamp>/`` with
``pid``, ``heard.jsonl`` (every StudyControl, ParticipantAction and door sensor message it hears,
for the tests to check) and, when the mission ends, ``metrics.json``. Scenarios:

- ``complete``: consent (when page.json asks: only once the runner has paused it), the puzzle, a
  door opened, deliveries, her task, some bad messages, ``mission_done``, then her questionnaire;
- ``refuse``: she refuses consent;
- ``hang``: the world runs and never ends (HumanState every 0.3 s); an ``abort`` ends the mission
  as the simulator does;
- ``crash``: exits with code 3 soon after starting.

Like up with ``--linger`` it stays until SIGTERM/SIGINT (``crash`` aside), then exits 0.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path

from protocol.messages import (
    Clock,
    ConstraintSet,
    DoorState,
    Event,
    HumanState,
    Message,
    ParticipantAction,
    QuestionnaireAnswers,
    StudyControl,
)
from runtime.service import Service
from runtime.signals import StopSignals
from runtime.transport import ZenohOptions

METRICS = {
    "completed": True,
    "time": 321.5,
    "team_completion_time": 321.5,
    "agent_completion_times": {"r0": 300.0, "human": 250.0},
    "human_door_openings": 1,
}
QUESTIONNAIRE = {"Q1": 4, "Q2": 5, "Q3": 3, "Q4": 4, "Q5": 2}


class FakeWorld(Service):
    def __init__(self, namespace: str, listen: str, run_dir: Path, page: dict) -> None:
        super().__init__("sim", namespace, ZenohOptions(mode="router", listen=[listen]), instance="fake-sim")
        self.run_dir = run_dir
        self.page = page
        self.lock = threading.Lock()
        self.paused = False
        self.t = 0.0
        self.aborted = ""

    def setup(self) -> None:
        k = self.keys
        self.subscribe(k.study_control(), StudyControl, self._on_control, inline=True)
        self.subscribe(k.participant_action(), ParticipantAction, self._on_heard, inline=True)
        self.subscribe(k.door_sensor("*"), DoorState, self._on_heard, inline=True)

    def _on_heard(self, msg: Message, key: str) -> None:
        record = {"key": key.split("/", 2)[2], "type": msg.TYPE, "src": msg.src}
        record.update(
            {name: getattr(msg, name) for name in ("act", "note", "door", "open", "by") if hasattr(msg, name)}
        )
        with self.lock, open(self.run_dir / "heard.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")

    def _on_control(self, msg: StudyControl, key: str) -> None:
        with self.lock, open(self.run_dir / "heard.jsonl", "a") as f:
            f.write(json.dumps({"type": msg.TYPE, "control": msg.command, "reason": msg.reason, "trial": msg.trial}))
            f.write("\n")
        if msg.command == "pause":
            self.paused = True
        elif msg.command == "resume":
            self.paused = False
        elif msg.command == "abort":
            self.aborted = msg.reason

    # what the world says
    def human(self, place: str = "desk", door: str = "", task_done: bool = False) -> None:
        self.publish(
            self.keys.human_state(),
            HumanState(
                mode="participant", place=place, door=door, doors=["d1"], task_done=task_done, paused=self.paused
            ),
        )

    def act(self, act: str, **fields: object) -> None:
        pid, tid = self.page["participant"], self.page["trial"]
        self.publish(self.keys.participant_action(), ParticipantAction(participant=pid, trial=tid, act=act, **fields))

    def event(self, kind: str, **fields: object) -> None:
        self.publish(self.keys.event(), Event(kind=kind, **fields))

    def tick(self, dt: float = 1.0) -> None:
        if not self.paused:
            self.t += dt
        self.clock_stamp()

    def clock_stamp(self) -> None:
        msg = Clock(time=self.t, mode="rate", rate=1.0, paused=self.paused)
        msg.src, msg.seq, msg.stamp = self.src, self.next_seq(), self.t
        self.publish(self.keys.clock(), msg, stamp=False)


def _args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="fake_up")
    parser.add_argument("--namespace", required=True)
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--router-listen", required=True)
    parser.add_argument("--study-trial", required=True)
    for flag in ("--human", "--time-limit", "--services", "--camera", "--mode", "--rate", "--method", "--seed"):
        parser.add_argument(flag)  # taken as up takes them (--help lists them), not used
    for flag in ("--until-done", "--linger"):
        parser.add_argument(flag, action="store_true")
    args, _unknown = parser.parse_known_args(argv)
    return args


def _wait(condition, timeout: float, signals: StopSignals) -> bool:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not signals.received:
        if condition():
            return True
        time.sleep(0.05)
    return False


def main(argv: list[str]) -> int:
    args = _args(argv)
    scenario = os.environ.get("FAKE_UP_SCENARIO", "complete")
    signals = StopSignals()
    signals.install()
    run_dir = Path(args.run_dir) / time.strftime("%Y%m%d-%H%M%S")
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "pid").write_text(str(os.getpid()))
    page = json.loads(Path(args.study_trial).read_text())
    world = FakeWorld(args.namespace, args.router_listen, run_dir, page)
    world.open()
    print("[router] router ready", flush=True)
    print("[tablet] Tablet page (the token in it is this run's access key; share it only with the tablet):", flush=True)
    print("[tablet]   https://127.0.0.1:9/?token=fake-token_123", flush=True)
    print("[up] supervising; Ctrl-C stops everything", flush=True)
    if scenario == "crash":
        world.human()
        time.sleep(0.3)
        world.close()
        print("[up] ERROR the sim crashed and could not be restarted", flush=True)
        return 3
    # The runner joins once the router listens; wait for its liveliness before saying anything.
    runner_up = _wait(
        lambda: bool(list(world.session.liveliness().get(world.keys.liveliness("study", "*"), timeout=1.0))),
        20,
        signals,
    )
    if not runner_up:
        print("[up] the runner never joined", flush=True)
    world.human()
    if page["consent"]["required"]:
        # The world is held until she answers: only go on once the runner has paused it.
        _wait(lambda: world.paused, 10, signals)
        world.human()  # "paused": the hold is seen
        world.act("consent", note="refused" if scenario == "refuse" else "given", wall=time.time())
        if scenario != "refuse":
            _wait(lambda: not world.paused, 10, signals)
            world.human()
    if scenario == "complete":
        _complete(world, run_dir)
    while not signals.received:  # --linger: up keeps the world (and the page) up until told to stop
        if scenario == "hang":
            world.tick(0.3)
            world.human()
        if world.aborted and not (run_dir / "metrics.json").exists():
            world.event("mission_done", data={**METRICS, "completed": False, "reason": world.aborted})
            (run_dir / "metrics.json").write_text(json.dumps({**METRICS, "completed": False}))
        time.sleep(0.3)
    (run_dir / "run.json").write_text(json.dumps({"stop_reason": f"received {signals.name}"}))
    world.close()
    return 0


def _complete(world: FakeWorld, run_dir: Path) -> None:
    """A whole trial, as the world and her page would say it (with some bad messages among it)."""
    step = 0.05
    world.tick()
    world.human()  # the same state again: logged once
    world.act("view", view="puzzle")
    world.act("puzzle_move", piece=3, correct=True, placed=1, total=16)
    world.publish(world.keys.constraints(), ConstraintSet(version=1))
    world.publish(world.keys.constraints(), ConstraintSet(version=1))  # repeated: logged once
    time.sleep(step)
    world.act("go_to_door", door="d1")
    world.tick()
    world.human("to_door", "d1")
    world.human("at_door", "d1")
    world.act("open_door", door="d1")
    for _ in range(2):  # a door state repeated (as the sim does once a second): logged once
        world.publish(world.keys.door_state("d1"), DoorState(door="d1", open=True, by="human"))
    world.event("door_opened", door="d1", data={"by": "human"})
    world.tick()
    world.event("delivered", robot="r0", object="o1")
    world.human("back", "d1")
    world.human("desk")
    time.sleep(step)
    # Bad input: a payload that is no message, another participant's act, answers off the scale.
    world.session.put(world.keys.participant_action(), b"\x93not a message")
    world.publish(world.keys.participant_action(), ParticipantAction(participant="P99", trial="", act="task_done"))
    pid, tid = world.page["participant"], world.page["trial"]
    world.publish(
        world.keys.questionnaire(),
        QuestionnaireAnswers(participant=pid, trial=tid, instrument="arroch-q", answers={**QUESTIONNAIRE, "Q1": 9}),
    )
    world.act("puzzle_move", piece=5, correct=True, placed=16, total=16)
    world.act("task_done")
    world.human("desk", task_done=True)
    world.event("human_done", data={"task_duration": 250.0})
    world.tick()
    world.event("mission_done", data=METRICS)
    (run_dir / "metrics.json").write_text(json.dumps(METRICS))
    time.sleep(0.3)  # her questionnaire comes after the mission
    world.publish(
        world.keys.questionnaire(),
        QuestionnaireAnswers(
            participant=pid, trial=tid, instrument="arroch-q", answers=QUESTIONNAIRE, wall=time.time()
        ),
    )


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
