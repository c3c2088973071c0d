"""The planner service's parts, without Zenoh: triggers, replan scheduler, lockstep follower,
world cache, readiness, off-track watch and plan continuation."""

from __future__ import annotations

import logging

from protocol.actions import Action
from protocol.messages import Clock, DoorState, RobotStatus, TeamPlan
from services.planner.continuation import CONTINUE_TOLERANCE, continued
from services.planner.dispatcher import Dispatched
from services.planner.lockstep import LockstepFollower
from services.planner.off_track import OffTrackWatch
from services.planner.plan import RobotPlan, Step, TeamResult
from services.planner.readiness import Readiness
from services.planner.scheduler import ReplanScheduler
from services.planner.triggers import (
    ActionEnded,
    DoorChanged,
    NewConstraints,
    NewWorldVersion,
    OffTrack,
    Start,
    StatusChanged,
)
from services.planner.world_cache import WorldCache

from .conftest import planner_for, site_named

LOG = logging.getLogger("test")

# ------------------------------------------------------------------ triggers


def test_triggers_read_as_the_logs_show_them_and_compare_by_value():
    assert [str(t) for t in (Start(), NewWorldVersion(), NewConstraints(3))] == [
        "start",
        "world_version",
        "constraints:v3",
    ]
    assert str(StatusChanged("r0", "moving")) == "status:r0:moving"
    assert str(ActionEnded("r1", failed=True)) == "action_failed:r1"
    assert str(DoorChanged("d1", open=False)) == "door:d1:closed"
    assert len({OffTrack("r0"), OffTrack("r0"), OffTrack("r1")}) == 2


def test_only_routine_news_keeps_the_plan_and_only_versions_constraints_start_are_awaited():
    assert StatusChanged("r0", "moving").keeps_plan() and NewWorldVersion().keeps_plan()
    assert not StatusChanged("r0", "waiting_at_door").keeps_plan()
    assert not DoorChanged("d1", True).keeps_plan() and not OffTrack("r0").keeps_plan()
    awaited = {type(t) for t in (Start(), NewWorldVersion(), NewConstraints(1)) if t.answered_in_lockstep}
    assert len(awaited) == 3
    assert not StatusChanged("r0", "done").answered_in_lockstep and not ActionEnded("r0").answered_in_lockstep


# ------------------------------------------------------------------ scheduler


def test_a_burst_is_answered_once_it_settles_or_at_the_latest_after_max_delay():
    s = ReplanScheduler(settle=0.03, max_delay=0.25)
    assert not s
    s.add(StatusChanged("r0", "done"), now=10.0)
    s.add(ActionEnded("r0"), now=10.02)
    assert not s.settled(10.04)  # news 20 ms ago
    assert s.settled(10.06)
    for k in range(20):  # news every 20 ms never settles, but the burst ends after max_delay
        s.add(StatusChanged(f"r{k}", "moving"), now=10.02 + 0.02 * k)
    assert s.settled(10.26)
    taken = s.take()
    assert [str(t) for t in taken] == sorted(str(t) for t in taken) and not s


def test_new_constraints_are_planned_at_once_and_take_the_burst_with_them():
    s = ReplanScheduler(settle=0.03, max_delay=0.25)
    s.add(StatusChanged("r0", "done"), now=10.0)
    assert not s.settled(10.01)
    s.add(NewConstraints(3), now=10.01)
    assert s.settled(10.01)  # the human waits: no settling
    assert [str(t) for t in s.take()] == ["constraints:v3", "status:r0:done"]


def test_held_news_joins_the_burst_a_new_version_starts():
    s = ReplanScheduler(settle=0.03, max_delay=0.25)
    s.add(StatusChanged("r0", "moving"), now=1.0)
    assert s.answers_nothing_awaited()
    s.hold()
    s.add(StatusChanged("r1", "moving"), now=5.0)  # more news a simulator does not wait for: still held
    assert s.held and s.first_at == 1.0
    s.add(NewWorldVersion(), now=9.0)
    assert not s.held and s.first_at == 9.0 and not s.answers_nothing_awaited()
    assert len(s.take()) == 3


# ------------------------------------------------------------------ lockstep follower


def clock(version: int, *, paused: bool = True, awaiting: str = "plan", cs: int = 0, t: float = 5.0) -> Clock:
    return Clock(
        time=t, mode="lockstep", world_version=version, paused=paused, awaiting=awaiting, constraints_version=cs
    )


def test_a_version_is_complete_when_its_clock_and_constraints_are_in_and_no_feedback_is_pending():
    f = LockstepFollower()
    assert not f.version_complete(1, 0)  # no clock yet
    f.on_clock(clock(1, cs=2), now=0.0)
    assert not f.version_complete(2, 2)  # statuses of version 2 came, its clock not yet
    assert not f.version_complete(1, 1)  # the clock names constraints v2
    assert f.version_complete(1, 2)
    f.on_clock(clock(1, awaiting="feedback", cs=2), now=0.1)
    assert not f.version_complete(1, 2)


def test_a_plan_is_awaited_until_one_answers_the_version_and_constraints():
    f = LockstepFollower()
    f.on_clock(clock(3, cs=1), now=0.0)
    assert not f.plan_awaited(3, 0, None)  # its constraints version is not in
    assert f.plan_awaited(3, 1, None)
    assert not f.plan_awaited(4, 1, None)  # a newer version is known here: its clock will come
    answered = TeamPlan(plan_id=1, world_version=3, constraints_version=1)
    assert not f.plan_awaited(3, 1, answered)
    f.on_clock(clock(3, paused=False), now=0.2)
    assert not f.plan_awaited(3, 1, None)


def test_a_plan_is_repeated_every_repeat_after_while_paused_at_a_version_it_answers():
    f = LockstepFollower(repeat_after=2.0)
    plan = TeamPlan(plan_id=7, world_version=3)
    f.on_clock(clock(3), now=100.0)
    assert f.repeat_due(plan, 101.0) is None
    first = f.repeat_due(plan, 102.5)
    assert first is not None and first.first and first.world_version == 3 and first.paused_for == 2.5
    assert f.repeat_due(plan, 103.0) is None
    again = f.repeat_due(plan, 104.6)
    assert again is not None and not again.first
    assert f.repeat_due(TeamPlan(plan_id=6, world_version=2), 110.0) is None  # an older plan is not repeated
    f.on_clock(clock(3, paused=False), now=111.0)
    assert f.repeat_due(plan, 120.0) is None


def test_a_simulator_paused_for_a_plan_not_being_made_is_a_stall_with_what_to_do():
    """Paused for a plan newer than the one sent: after REPEAT_AFTER s a recovery step (fetch the
    constraints version the clock names when it is not held here), one every REPEAT_AFTER s, reported
    once past STALL_REPORT; never while the plan sent answers the clock, nor when it runs."""
    f = LockstepFollower(repeat_after=2.0)
    answered_v4 = TeamPlan(plan_id=1, world_version=4, constraints_version=1)
    f.on_clock(clock(5, cs=2), now=100.0)
    assert f.stall(answered_v4, 1, 101.9) is None  # not yet
    first = f.stall(answered_v4, 1, 102.0)
    assert first is not None and (first.world_version, first.constraints_version) == (5, 2)
    assert first.fetch_constraints and not first.report and first.paused_for == 2.0
    assert f.stall(answered_v4, 2, 103.0) is None  # one step every REPEAT_AFTER s
    late = f.stall(answered_v4, 2, 110.5)
    assert late is not None and late.report and not late.fetch_constraints
    words = late.describe(4, 2, ["world_version"], [])
    assert (
        "answering world v5" in words and "held here: world v4" in words and "pending news ['world_version']" in words
    )
    assert not f.stall(answered_v4, 2, 113.0).report  # reported once per pause
    assert f.stall(TeamPlan(plan_id=2, world_version=5, constraints_version=2), 2, 120.0) is None  # answered
    f.on_clock(clock(5, awaiting="feedback", cs=2), now=121.0)
    assert f.stall(answered_v4, 2, 130.0) is None  # waiting for the feedback's ack, not for a plan
    f.on_clock(clock(6, paused=False), now=131.0)
    assert f.stall(answered_v4, 2, 140.0) is None  # running


# ------------------------------------------------------------------ world cache


def test_the_cache_says_what_changed_and_builds_the_world_from_it():
    site = site_named("office")
    planner = planner_for("office")
    cache = WorldCache(site, planner.builder.beside_distance)
    assert cache.note_version(2) and not cache.note_version(2) and not cache.note_version(1)
    status = RobotStatus(robot="r0", state="idle", carrying=["o0", "not_an_object"])
    assert cache.set_status(status)
    assert not cache.set_status(RobotStatus(robot="r0", state="idle", carrying=["o0", "not_an_object"], progress=0.5))
    cache.set_pose_from("r0", [1.0, 2.0, "x"])  # malformed: ignored
    assert "r0" not in cache.poses
    cache.set_pose_from("r0", [1.0, 2.0, 0.5])
    assert cache.poses["r0"] == (1.0, 2.0, 0.5)
    door = next(d for d, o in site.openings.items() if o.human_operated)
    assert cache.set_door(DoorState(door=door, open=True, until=60.0))
    assert not cache.set_door(DoorState(door=door, open=True, until=61.0))
    world = cache.snapshot(50.0, {})
    assert world.robots["r0"].carrying == frozenset({"o0"}) and world.robots["r0"].pose == (1.0, 2.0, 0.5)
    assert world.open_doors == {door: 61.0 - site.params.door_hold_time}  # the latest state counts
    assert cache.missing() == [rid for rid in site.robots if rid != "r0"]  # r0 has a pose and a status


def test_a_load_under_way_is_in_progress_and_an_approached_opening_is_beside():
    site = site_named("office")
    cache = WorldCache(site, planner_for("office").builder.beside_distance)
    sent = {"r0": Dispatched(Action.LOAD, ("o0",), 4, 1, [])}
    cache.set_status(RobotStatus(robot="r0", state="loading", action="load", args=["o0"], action_id=4, progress=0.5))
    ip = cache.snapshot(10.0, sent).robots["r0"].in_progress
    assert ip is not None and ip.action == "load" and ip.until == 10.0 + 0.5 * site.params.load_time
    door = next(iter(site.openings))
    cache.set_status(RobotStatus(robot="r0", state="done", action="approach", args=[door], action_id=5))
    assert cache.snapshot(10.0, sent).robots["r0"].beside == door


# ------------------------------------------------------------------ readiness and off-track


def test_readiness_waits_for_a_running_mission_to_be_heard():
    r = Readiness(started_at=0.0, log=LOG, start_grace=1.5, state_wait=5.0)
    kw = {"clock_synced": True, "clock_version": 0, "world_version": 0}
    assert not r.ready(1.0, missing=["r0"], heard_any=False, **kw)  # maybe a mission not heard yet
    assert r.ready(1.6, missing=["r0"], heard_any=False, **kw)  # none: plan from the site's start
    assert not r.ready(2.0, missing=["r1"], heard_any=True, **kw)  # a mission under way, r1 not heard
    assert r.ready(7.1, missing=["r1"], heard_any=True, **kw)  # given up waiting for r1
    assert r.ready(8.0, missing=[], heard_any=True, **kw)
    assert not r.ready(9.0, missing=[], heard_any=True, clock_synced=False, clock_version=0, world_version=0)


def test_a_robot_off_track_is_noticed_once_per_cooldown_and_taken_once():
    w = OffTrackWatch(cooldown=2.0)
    assert not w.notice("r0", False, 0.0)
    assert w.notice("r0", True, 0.0) and not w.notice("r0", True, 1.0) and w.notice("r0", True, 2.5)
    assert w.sweep(["r0", "r1", "r2"], lambda r: r != "r2") == 1  # r0 is marked already
    assert w.take() == {"r0", "r1"} and not w.force


# ------------------------------------------------------------------ continuation


def team(steps: tuple[Step, ...]) -> TeamResult:
    return TeamResult(method="iidp", base=100, hold=10, plans={"r0": RobotPlan("r0", steps, steps[-1].end, ())})


def test_a_plan_is_continued_past_an_action_that_ended_in_time_and_shifted_to_the_new_base():
    kept = team((Step("load", ("o0",), 0, 10), Step("unload", ("o0",), 10, 30)))
    sent = {"r0": Dispatched("load", ("o0",), 4, 1, [])}
    args = {"sent": sent, "front_index": {"r0": 0}, "existing": lambda base: frozenset()}
    news = [ActionEnded("r0"), StatusChanged("r0", "done"), NewWorldVersion()]
    out = continued(kept, news, finished={"r0"}, force=set(), now=108.5, **args)
    assert out is not None and out.base == 108
    assert [(s.action, out.absolute(s.start), out.absolute(s.end)) for s in out.plans["r0"].steps] == [
        ("unload", 110, 130)
    ]
    # too late, a failure, a robot to re-command, news that is not routine: solved anew
    assert continued(kept, news, finished={"r0"}, force=set(), now=110 + CONTINUE_TOLERANCE + 1, **args) is None
    assert continued(kept, [ActionEnded("r0", failed=True)], finished={"r0"}, force=set(), now=108, **args) is None
    assert continued(kept, news, finished={"r0"}, force={"r0"}, now=108, **args) is None
    assert continued(kept, [*news, DoorChanged("d", True)], finished={"r0"}, force=set(), now=108, **args) is None
    assert continued(kept, [ActionEnded("r0")], finished=set(), force=set(), now=108, **args) is None
