"""The engine over a whole mission (in process): determinism, metrics, the lockstep gate, pacing."""

from __future__ import annotations

import json

import msgspec
import pytest

from protocol.codec import decode, encode
from protocol.messages import Event, PlanStep, TeamPlan
from protocol.site import load_site
from runtime.lockstep import LockstepGate
from services.sim.engine import Engine
from services.sim.human import HumanConfig
from services.sim.pacing import WallPacer
from tests.sim.helpers import run_mission, small_site


def log_of(events) -> list[str]:
    return [json.dumps(e.as_dict(), sort_keys=True) for e in events]


@pytest.mark.parametrize("method", ["arroch", "no-feedback", "no-comm"])
def test_same_seed_same_events_other_seed_other_events(method):
    site = load_site(None)
    a = log_of(run_mission(Engine(site, method=method, seed=7)))
    b = log_of(run_mission(Engine(site, method=method, seed=7)))
    c = log_of(run_mission(Engine(site, method=method, seed=8)))
    assert a == b
    assert a != c
    assert json.loads(a[-1])["kind"] == "mission_done"


def test_mission_metrics_are_the_papers():
    engine = Engine(load_site(None), method="arroch", seed=3)
    events = run_mission(engine)
    done = events[-1]
    assert done.kind == "mission_done"
    m = msgspec.to_builtins(done.data)  # the MissionDone's fields as the JSON map events.jsonl holds
    assert m["completed"] is True
    agents = m["agent_completion_times"]
    assert set(agents) == {"r0", "r1", "r2", "human"}
    assert m["team_completion_time"] == max(agents.values())  # the slowest agent, human included
    for rid in ("r0", "r1", "r2"):
        last = max(e.time for e in events if e.kind == "delivered" and e.robot == rid)
        assert agents[rid] == pytest.approx(last)
    assert agents["human"] == next(e.time for e in events if e.kind == "human_done")
    opened_by_human = [e for e in events if e.kind == "human_opens_door"]
    assert m["human_door_openings"] == len(opened_by_human) > 0
    sent = [e for e in events if e.kind == "feedback_sent"]
    assert m["feedback"]["sent"] == len(sent) and m["feedback"]["accepted"] == len(sent)
    for e in sent:
        assert e.data.kind == "door_unavailable" and e.data.params["door"] == "d_storage"
    assert m["params"]["method"] == "arroch" and m["params"]["seed"] == 3
    assert m["params"]["human"]["no_comm_probability"] == 0.6
    assert m["params"]["human"]["declare_probability"] == 0.9


def test_without_a_planner_the_mission_ends_unfinished_at_the_time_limit():
    from services.sim.engine import EngineConfig

    engine = Engine(
        small_site(),
        method="no-comm",
        seed=1,
        config=EngineConfig(time_limit=60.0),
        human=HumanConfig(task_mean=30.0, task_std=0.0, task_min=1.0),
    )
    engine.start()
    while not engine.done:
        engine.step()
    done = engine.take_events()[-1]
    assert done.kind == "mission_done" and done.data.completed is False
    assert done.time == pytest.approx(60.0)
    assert done.data.team_completion_time is None
    assert done.data.agent_completion_times["human"] == pytest.approx(30.0, abs=10.0)


def plan(plan_id: int, world: int, constraints: int = 0, fronts: dict[str, int] | None = None) -> TeamPlan:
    robots = {
        rid: [PlanStep(action="approach", args=["d"], start=0, end=1, action_id=aid)]
        for rid, aid in (fronts or {}).items()
    }
    return TeamPlan(plan_id=plan_id, world_version=world, constraints_version=constraints, robots=robots)


def test_lockstep_gate_waits_for_the_plan_its_commands_and_the_feedback():
    gate = LockstepGate()
    assert gate.blocker(1, {}) != ""  # no plan yet
    assert gate.waits_for(1, {})[0] == "plan"
    gate.on_plan(plan(1, 1, fronts={"r0": 3}))
    assert "r0's command 3" in gate.blocker(1, {"r0": 2}) and gate.waits_for(1, {"r0": 2})[0] == "command"
    assert gate.blocker(1, {"r0": 3}) == "" and gate.waits_for(1, {"r0": 3}) == ("", "")
    assert "world version 2" in gate.blocker(2, {"r0": 3}) and gate.waits_for(2, {"r0": 3})[0] == "plan"
    assert not gate.on_plan(plan(0, 2))  # older plan ignored
    gate.feedback_sent()
    gate.on_plan(plan(2, 2))
    assert "ack" in gate.blocker(2, {}) and gate.waits_for(2, {})[0] == "feedback"
    gate.feedback_answered(True, 5)
    assert "constraints version 5" in gate.blocker(2, {}) and gate.waits_for(2, {})[0] == "plan"
    gate.on_plan(plan(3, 2, constraints=5))
    assert gate.blocker(2, {}) == ""
    gate.feedback_sent()
    gate.feedback_answered(None, 0)  # no ack at all: time goes on
    assert gate.blocker(2, {}) == ""


def test_wall_pacer_follows_the_rate_and_drops_a_backlog():
    pacer = WallPacer(10.0, 0.05)
    assert pacer.due(0.0, 100.0) == 0
    assert pacer.due(0.0, 100.1) == 20  # 0.1 wall s at 10x is 1 sim s, 20 ticks
    assert pacer.due(1.0, 100.2) == 20
    assert pacer.due(2.0, 110.0) == 1  # 10 s stalled: the backlog is dropped, not sprinted through
    assert pacer.dropped > 90.0
    assert pacer.due(2.05, 110.05) == 9  # counted from where it resumed: (2.0 + 0.5 - 2.05) / 0.05


def test_every_event_a_mission_emits_crosses_the_wire():
    """Struct limits are checked on decoding only: an event the engine builds must also decode, or
    every receiver drops it (wall contacts once did: their position is [x, y], not a pose)."""
    events = run_mission(Engine(load_site(None), method="arroch", seed=1))
    # What goes wrong is rare in a scripted mission: the engine's own watches report a robot put
    # into a wall and two robots put onto each other.
    engine = Engine(load_site(None), method="arroch", seed=1)
    engine.start()
    r0, r1, r2 = (engine.robots[rid] for rid in ("r0", "r1", "r2"))
    walls = engine.wall_contacts.walls
    r0.x = next(x for x in (r0.x + 0.01 * k for k in range(1, 2000)) if walls.depth(x, r0.y) > 0.01)
    r2.x, r2.y = r1.x + 0.1, r1.y
    engine.step()
    events += engine.take_events()
    assert {"delivered", "mission_done", "wall_contact", "robot_overlap"} <= {e.kind for e in events}
    for event in events:
        msg = Event(data=event.data, robot=event.robot, door=event.door, object=event.object)  # as the sim sends it
        assert decode(encode(msg), Event) == msg, event.kind
