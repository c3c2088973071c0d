"""A participant in place of the simulated human (services/sim/participant.py), real doors following
their sensors (services/sim/doors.py), the experimenter's pause and abort, and the command lines
that start them (``arroch sim``, ``arroch up``). The last test runs ``arroch sim --human
participant`` as a real process on Zenoh."""

from __future__ import annotations

import argparse
import json
import math
import queue
import time

import pytest
from msgspec import UNSET

from protocol.events import data_to_wire
from protocol.messages import Clock, DoorState, Event, HumanState, ParticipantAction, StudyControl
from protocol.site import load_site
from runtime.launch.catalog import SERVICES, Launch, MissionOptions, service_argv
from services.sim.cli import build_options
from services.sim.cli import register as register_sim
from services.sim.engine import Engine, SimEvent
from services.sim.human import HumanConfig, OpenDoor, TaskDone
from services.sim.participant import ParticipantHuman, Refused
from tests.conftest import wait_for_message
from tests.procs import arroch
from tests.sim.helpers import command, small_site
from tests.sim.standin import ScriptedPlanner

SITE = small_site()  # her desk at (7, 1) in storage, behind the human-operated d_storage (centre (6, 4))
DESK = (7.0, 1.0)
DOOR_POINT = (6.0, 3.5)  # 0.5 m in front of d_storage on her side
TICK = 0.05


def her(**kw) -> ParticipantHuman:
    return ParticipantHuman(HumanConfig(), DESK, {"d_storage": DOOR_POINT}, **kw)


def walk(h: ParticipantHuman, t: float, seconds: float) -> float:
    """Step ``h`` for ``seconds`` in ticks from ``t``; returns the new time."""
    for _ in range(round(seconds / TICK)):
        assert h.step(t, TICK, {}, {}) == []  # she decides nothing on her own
        t += TICK
    return t


# ---------------------------------------------------------------------------- her avatar


def test_she_walks_to_her_door_opens_it_and_walks_back():
    h = her()
    walk_time = math.dist(DESK, DOOR_POINT)  # walk_speed 1 m/s
    assert h.available and h.pose()[:2] == DESK
    assert h.act("go_to_door", "d_storage", 0.0) == []
    assert (h.place, h.door, h.available) == ("to_door", "d_storage", False)
    t = walk(h, 0.0, 1.0)
    x, y, _ = h.pose()
    assert h.place == "to_door" and math.isclose(math.dist((x, y), DESK), 1.0, abs_tol=1e-6)
    t = walk(h, t, walk_time - 1.0 + TICK)
    assert h.place == "at_door" and h.pose()[:2] == pytest.approx(DOOR_POINT)
    t = walk(h, t, 2.0)  # she may stand there: the door is opened when she says so, not before
    assert h.place == "at_door"
    assert h.act("open_door", "d_storage", t) == [OpenDoor("d_storage")]
    assert h.place == "back" and h.opened_at == [t]
    t = walk(h, t, walk_time + TICK)
    assert h.place == "desk" and h.door == "" and h.pose()[:2] == DESK
    c = h.counters
    assert (c.door_trips, c.door_openings, c.turned_back) == (1, 1, 0)
    assert c.time_away == pytest.approx(2 * walk_time + 2.0, abs=2 * TICK)


def test_she_turns_back_the_way_she_came():
    h = her()
    h.act("go_to_door", "d_storage", 0.0)
    t = walk(h, 0.0, 1.0)
    assert h.act("back_to_desk", "", t) == []
    x, y, _ = h.pose()
    assert h.place == "back" and math.isclose(math.dist((x, y), DESK), 1.0, abs_tol=1e-6)
    t = walk(h, t, 0.5)
    assert h.place == "back" and math.isclose(math.dist(h.pose()[:2], DESK), 0.5, abs_tol=1e-6)
    t = walk(h, t, 0.5 + TICK)
    assert h.place == "desk" and h.counters.turned_back == 1 and h.counters.time_away == pytest.approx(2.0)
    # From the door itself, the whole way back; the door stays shut.
    h.act("go_to_door", "d_storage", t)
    t = walk(h, t, 3.0)
    assert h.place == "at_door"
    assert h.act("back_to_desk", "d_storage", t) == [] and h.place == "back"
    assert h.counters.turned_back == 2 and h.counters.door_openings == 0


def test_task_done_once_and_what_it_measures():
    h = her()
    assert h.task_duration is None and not h.done
    h.act("go_to_door", "d_storage", 0.0)
    t = walk(h, 0.0, 1.0)
    h.act("back_to_desk", "", t)
    t = walk(h, t, 2.0)
    assert h.act("task_done", "", 100.0) == [TaskDone(100.0)]
    assert h.done and h.done_time == 100.0 and h.task_duration == pytest.approx(98.0)  # 2 s away from her task
    assert h.focus_report() == []
    with pytest.raises(Refused, match="already done"):
        h.act("task_done", "", 101.0)


@pytest.mark.parametrize(
    ("setup", "act", "door", "field", "words"),
    [
        ([], "go_to_door", "d_office", "door", "not a door she operates"),
        ([], "go_to_door", "", "door", "not a door she operates"),
        ([], "open_door", "d_storage", "act", "not at that door"),
        ([("go_to_door", "d_storage")], "open_door", "d_storage", "act", "walking to d_storage"),
        ([("go_to_door", "d_storage")], "go_to_door", "d_storage", "act", "not at her desk"),
        ([], "back_to_desk", "", "act", "at her desk"),
        ([("go_to_door", "d_storage")], "back_to_desk", "d_office", "door", "back_to_desk from 'd_office'"),
        ([], "feedback", "d_storage", "act", "not an act the simulator takes"),
    ],
)
def test_acts_she_cannot_take_now_are_refused_naming_the_field(setup, act, door, field, words):
    h = her()
    for a, d in setup:
        h.act(a, d, 0.0)
    before = (h.place, h.door, h.counters.door_trips, h.counters.door_openings)
    with pytest.raises(Refused) as exc:
        h.act(act, door, 0.5)
    assert exc.value.field == field and words in str(exc.value)
    assert (h.place, h.door, h.counters.door_trips, h.counters.door_openings) == before  # nothing changed


def test_with_real_doors_no_avatar_walks():
    h = her(sensor=True)
    for act in ("go_to_door", "open_door", "back_to_desk"):
        with pytest.raises(Refused, match="follow their sensors"):
            h.act(act, "d_storage", 0.0)
    assert h.place == "desk" and h.act("task_done", "", 3.0) == [TaskDone(3.0)]


# ---------------------------------------------------------------------------- in the engine


def engine(**kw) -> Engine:
    e = Engine(SITE, method="arroch", seed=0, human_mode="participant", **kw)
    e.start()
    e.take_events()
    return e


def run_until(e: Engine, pred, limit: float = 120.0) -> list[SimEvent]:
    events: list[SimEvent] = []
    t_end = e.time + limit
    while not pred(e) and e.time < t_end:
        e.step()
        events += e.take_events()
    assert pred(e), f"not reached by t={e.time}"
    return events


def test_her_opening_opens_the_door_for_the_robots():
    e = engine()
    assert e.human_place() == ("desk", "")
    assert e.human_act("go_to_door", "d_storage") == ""
    assert e.human_place() == ("to_door", "d_storage")
    run_until(e, lambda e: e.human_place()[0] == "at_door")
    version = e.world_version
    assert e.human_act("open_door", "d_storage") == ""
    opened_now = [ev.kind for ev in e.take_events()]
    assert opened_now == ["human_opens_door"]
    events = run_until(e, lambda e: e.doors.passable("d_storage"))
    (opened,) = [ev for ev in events if ev.kind == "door_opened"]
    assert opened.data.by == "human" and opened.data.world_version == version + 1 and opened.data.until > 0
    run_until(e, lambda e: e.human_place() == ("desk", ""))
    assert e.human_act("open_door", "d_storage").startswith("act: open_door d_storage: she is not at that door")


def test_the_mission_ends_when_everything_is_delivered_and_she_says_her_task_is_done():
    e = engine()
    planner = ScriptedPlanner(SITE)
    answered = plans = 0
    log: list[SimEvent] = []
    while not e.objects.all_delivered and e.time < 1200:
        for event in e.take_events():
            log.append(event)
            if event.kind in ("action_done", "action_failed") and event.robot in planner.todo:
                planner.finished(event.robot, int(event.data.action_id), event.kind == "action_done")
        if e.world_version > answered:
            answered = e.world_version
            plans += 1
            poses = {rid: (r.x, r.y, r.theta) for rid, r in e.robots.items()}
            for cmd in planner.commands(plans, e.time, poses):
                e.apply_command(cmd)
            continue
        # She plays her part as a person would: a robot waits at her shut door, she goes and opens it.
        place, _ = e.human_place()
        waiting = any(r.waiting_door == "d_storage" for r in e.robots.values())
        if waiting and place == "desk" and not e.doors["d_storage"].open_or_opening:
            assert e.human_act("go_to_door", "d_storage") == ""
        elif place == "at_door":
            assert e.human_act("open_door", "d_storage") == ""
        e.step()
    assert e.objects.all_delivered and not e.done  # her task is not done: the mission goes on
    run_until(e, lambda e: e.human_place()[0] == "desk")
    for _ in range(100):
        e.step()
    assert not e.done
    t = e.time
    assert e.human_act("task_done") == ""
    log += e.take_events()
    assert e.done and e.completed
    (done,) = [ev for ev in log if ev.kind == "mission_done"]
    m = data_to_wire(done.data)
    assert m["completed"] and m["agent_completion_times"]["human"] == t == m["team_completion_time"]
    assert m["human"]["participant"] is True and m["human"]["doors"] == "sim" and m["human"]["focus"] == []
    assert m["human"]["door_openings"] >= 1 and m["human"]["door_trips"] == m["human"]["door_openings"]
    assert m["human_door_openings"] == m["door_openings"]["d_storage"]["human"]
    assert m["closed_door_crossings"] == 0 and m["params"]["human_mode"] == "participant"
    assert e.human_act("task_done").startswith("act: the mission is over")


def test_a_real_door_follows_its_sensor():
    e = engine(door_sensors=True)
    d = e.doors["d_storage"]
    assert e.door_sensor("d_storage", True, "sensor") == ""
    assert [(ev.kind, ev.data.by) for ev in e.take_events()] == [("human_opens_door", "sensor")]
    events = run_until(e, lambda e: d.passable)
    (opened,) = [ev for ev in events if ev.kind == "door_opened"]
    assert opened.data.by == "sensor" and opened.data.until is UNSET and d.open_until == 0.0
    assert e.door_sensor("d_storage", True, "sensor") == ""  # a sensor repeating itself: nothing new
    assert not [ev for ev in e.take_events() if ev.kind == "human_opens_door"]
    hold = SITE.params.door_hold_time
    events = run_until(e, lambda e: False if e.time < hold + 30 else True)
    assert d.passable and not [ev for ev in events if ev.kind == "door_closed"]  # no hold time: open while it says so
    # Shut while a robot stands in the doorway: it closes once the doorway is clear, never onto the robot.
    r0 = e.robots["r0"]
    r0.x, r0.y = 6.0, 4.0
    assert e.door_sensor("d_storage", False, "sensor") == ""
    for _ in range(40):
        e.step()
    assert d.passable
    r0.x, r0.y = 1.0, 5.0
    events = run_until(e, lambda e: not d.target_open, limit=1.0)
    assert [ev.kind for ev in events if ev.kind.startswith("door_")] == ["door_closed"]
    m = e.summary()
    assert m["door_openings"]["d_storage"] == {"human": 1} and m["human"]["door_openings"] == 1
    assert m["human"]["doors"] == "sensor"


def test_a_sensor_shutting_a_door_still_swinging_open_swings_it_back():
    e = engine(door_sensors=True)
    d = e.doors["d_storage"]
    e.door_sensor("d_storage", True, "experimenter")
    e.step()
    assert 0.0 < d.fraction < 1.0
    e.door_sensor("d_storage", False, "sensor")
    events = run_until(e, lambda e: d.fraction == 0.0, limit=3.0)
    assert not [ev for ev in events if ev.kind in ("door_opened", "door_closed")]  # it was never passable


@pytest.mark.parametrize(
    ("door", "words"),
    [("d_nowhere", "no door 'd_nowhere' on site simtest"), ("d_office", "'d_office' follows no sensor (automatic)")],
)
def test_sensor_reports_of_doors_without_a_sensor_are_refused(door, words):
    e = engine(door_sensors=True)
    assert e.door_sensor(door, True, "sensor") == f"door: {words}"
    assert e.take_events() == []


def test_the_simulated_humans_place_for_her_state():
    e = Engine(SITE, method="arroch", seed=0, human=HumanConfig(focus_count=0))
    e.start()
    assert e.human_place() == ("desk", "")
    e.human._go("d_storage", 0.0)  # what a decision to open does
    assert e.human_place() == ("to_door", "d_storage")
    run_until(e, lambda e: e.human_place()[0] != "to_door", limit=5.0)
    assert e.human_place() == ("at_door", "d_storage")  # opening it (open_time)
    run_until(e, lambda e: e.human_place()[0] != "at_door", limit=5.0)
    assert e.human_place() == ("back", "d_storage")


def test_the_simulated_human_neither_takes_acts_nor_opens_real_doors():
    e = Engine(SITE, method="arroch", seed=0)
    assert e.human_act("task_done").startswith("act: the simulated human plays her part")
    assert e.door_sensor("d_storage", True).startswith("door: 'd_storage' follows no sensor (human-operated")
    with pytest.raises(ValueError, match="go with a participant"):
        Engine(SITE, method="arroch", seed=0, door_sensors=True)


def test_an_abort_ends_the_mission_not_completed():
    e = engine()
    e.apply_command(command("r0", 1, "approach", ["d_office"], [(1.0, 5.0), (2.5, 5.0)]))
    for _ in range(20):
        e.step()
    e.take_events()
    e.abort("aborted by the experimenter: fire alarm")
    (done,) = e.take_events()
    assert done.kind == "mission_done" and done.time == 1.0
    assert done.data.completed is False and done.data.reason == "aborted by the experimenter: fire alarm"
    assert done.data.team_completion_time is None
    e.abort("again")
    e.step()
    assert e.take_events() == [] and e.time == 1.0


# ---------------------------------------------------------------------------- command lines


def sim_args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    register_sim(parser.add_subparsers())
    return parser.parse_args(["sim", *argv])


def test_sim_options():
    options = build_options(sim_args("--human", "participant", "--doors", "sensor", "--participant", "P03"))
    assert (options.human_mode, options.doors, options.participant, options.mode) == (
        "participant",
        "sensor",
        "P03",
        "realtime",
    )
    assert build_options(sim_args("--human", "participant", "--rate", "4")).mode == "rate"
    for argv, words in [
        (("--human", "participant", "--mode", "lockstep"), "not --mode lockstep"),
        (("--doors", "sensor"), "goes with --human participant"),
        (("--participant", "P03"), "goes with --human participant"),
        (("--human", "participant", "--participant", "P 03"), "not an id"),
    ]:
        with pytest.raises(ValueError, match=words):
            build_options(sim_args(*argv))


def test_a_participant_in_lockstep_is_refused_before_any_session_opens(spawn):
    # An endpoint nobody listens on: a session would be tried (and fail otherwise than with code 2).
    proc = spawn(
        arroch("sim", "--human", "participant", "--mode", "lockstep", "--connect", "tcp/127.0.0.1:9"), name="sim"
    )
    assert proc.wait(30) == 2
    assert "not --mode lockstep" in proc.output and "up on namespace" not in proc.output


def test_up_passes_the_study_options_to_the_sim_and_the_tablet(tmp_path):
    trial = tmp_path / "trial.json"
    trial.write_text("{}")
    launch = Launch(namespace="ns", mission=MissionOptions(human="participant", doors="sensor", study_trial=str(trial)))
    sim = service_argv(SERVICES["sim"], launch)
    assert sim[sim.index("--human") + 1] == "participant" and sim[sim.index("--doors") + 1] == "sensor"
    tablet = service_argv(SERVICES["tablet"], launch)
    assert tablet[tablet.index("--study-trial") + 1] == str(trial) and "--human" not in tablet
    plain = service_argv(SERVICES["sim"], Launch(namespace="ns"))
    assert "--human" not in plain and "--doors" not in plain

    from services.supervisor.cli import add_up_arguments, build_config

    def up(*argv: str):
        parser = argparse.ArgumentParser()
        add_up_arguments(parser)
        return build_config(parser.parse_args(["--namespace", "ns", *argv]))[0]

    config = up("--human", "participant", "--doors", "sensor", "--study-trial", str(trial))
    mission = config.launch.mission
    assert (mission.human, mission.doors, mission.study_trial, mission.mode) == (
        "participant",
        "sensor",
        str(trial.resolve()),
        None,  # the sim's default: realtime
    )
    for argv, words in [
        (("--human", "participant", "--mode", "lockstep"), "cannot run in lockstep"),
        (("--doors", "sensor"), "goes with --human participant"),
        (("--study-trial", str(tmp_path / "missing.json")), "no such file"),
    ]:
        with pytest.raises(ValueError, match=words):
            up(*argv)


# ---------------------------------------------------------------------------- on Zenoh


def latest(q: queue.Queue, pred, timeout: float = 10.0):
    return wait_for_message(q, pred, timeout=timeout)


@pytest.mark.integration
def test_a_participant_drives_the_sim_over_zenoh(spawn, router, namespace, client, tmp_path):
    site = load_site()
    door = sorted(d.id for d in site.doors.values() if d.human_operated and site.human.room in d.rooms)[0]
    humans = client.collect(client.keys.human_state(), HumanState)
    doors = client.collect(client.keys.door_state(door), DoorState)
    events = client.collect(client.keys.event(), Event)
    clocks = client.collect(client.keys.clock(), Clock)
    metrics = tmp_path / "metrics.json"
    rate = 4.0
    sim = spawn(
        arroch(
            "sim",
            "--connect",
            router,
            "--namespace",
            namespace,
            "--human",
            "participant",
            "--rate",
            f"{rate:g}",
            "--participant",
            "P01",
            "--until-done",
            "--metrics-out",
            str(metrics),
        ),
        name="sim",
    )
    sim.wait_for("up on namespace", timeout=30)
    first = latest(humans, lambda h: True)
    assert (first.mode, first.place, first.doors, first.open_time, first.paused) == (
        "participant",
        "desk",
        sorted(d.id for d in site.doors.values() if d.human_operated and site.human.room in d.rooms),
        3.0,
        False,
    )
    assert (first.x, first.y) == pytest.approx(site.human.position)

    def act(what: str, door: str = "", participant: str = "P01") -> None:
        msg = ParticipantAction(participant=participant, act=what, door=door)
        client.publish(client.keys.participant_action(), msg)

    act("go_to_door", door, participant="P02")  # another participant's act: refused
    sim.wait_for("refused: participant: 'P02' is not this run's 'P01'")
    act("open_door", door)  # not at the door yet: refused, naming the field
    sim.wait_for(f"refused: act: open_door {door}: she is not at that door (at her desk)")
    act("go_to_door", door)
    latest(humans, lambda h: h.place == "to_door" and h.door == door)
    at_door = latest(humans, lambda h: h.place == "at_door", timeout=15)
    assert (at_door.x, at_door.y) == pytest.approx(site.doors[door].beside(site.human.room, 0.5), abs=1e-6)
    act("open_door", door)
    opened = latest(doors, lambda d: d.open, timeout=10)
    assert opened.by == "human" and opened.until > opened.stamp
    latest(humans, lambda h: h.place == "back")
    latest(humans, lambda h: h.place == "desk", timeout=15)
    act("task_done")
    done_event = latest(events, lambda e: e.kind == "human_done")
    assert latest(humans, lambda h: h.task_done).task_done

    # Pause: site time stands still, the clock and her state say so; resume: on from there, no jump.
    client.publish(client.keys.study_control(), StudyControl(command="pause", reason="a question"))
    paused = latest(humans, lambda h: h.paused)
    stopped = latest(clocks, lambda c: c.paused)
    time.sleep(1.0)
    still = latest(clocks, lambda c: True)
    assert still.paused and still.time == stopped.time and paused.paused
    client.publish(client.keys.study_control(), StudyControl(command="resume"))
    going = latest(clocks, lambda c: not c.paused)
    assert stopped.time <= going.time < stopped.time + 0.5 * rate
    latest(humans, lambda h: not h.paused)
    client.publish(client.keys.study_control(), StudyControl(command="resume"))  # not paused: refused
    sim.wait_for("study control resume refused: command: resume, but the trial is not paused")

    client.publish(client.keys.study_control(), StudyControl(command="abort", reason="the participant left"))
    done = latest(events, lambda e: e.kind == "mission_done")
    assert done.data.completed is False
    assert done.data.reason == "aborted by the experimenter: the participant left"
    assert sim.wait(15) == 4
    m = json.loads(metrics.read_text())
    assert m["human"]["participant"] is True and m["human"]["door_openings"] == 1
    assert m["agent_completion_times"]["human"] == done_event.stamp
    counters = m["run"]["counters"]
    assert counters["participant_actions"] == 3 and counters["participant_actions_refused"] == 2
    assert counters["study_pause"] == counters["study_resume"] == counters["study_abort"] == 1
    assert counters["study_control_refused"] == 1
