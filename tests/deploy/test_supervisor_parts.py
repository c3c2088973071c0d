"""The supervisor's parts on their own: restart policy, command lines, progress, output."""

from __future__ import annotations

import io
import re
import sys
from pathlib import Path

import pytest

from protocol.messages import Event, RobotStatus
from runtime.launch.catalog import (
    SERVICES,
    Launch,
    MissionOptions,
    parse_child,
    parse_services,
    router_argv,
    service_argv,
)
from runtime.launch.children import RestartPolicy, describe_exit
from services.supervisor.output import Output
from services.supervisor.progress import MissionProgress


def test_restart_delays_double_up_to_a_cap_and_reset_after_a_stable_run():
    policy = RestartPolicy(initial=0.5, factor=2.0, max_delay=3.0, max_per_minute=100, stable_after=30.0)
    delays = [policy.next_delay(now=float(i), ran_for=0.2) for i in range(5)]
    assert delays == [0.5, 1.0, 2.0, 3.0, 3.0]
    assert policy.next_delay(now=5.0, ran_for=45.0) == 0.5  # it had run a while: a fresh series


def test_restarts_are_capped_per_minute():
    policy = RestartPolicy(max_per_minute=3)
    assert all(policy.next_delay(now=t, ran_for=0.1) is not None for t in (0.0, 1.0, 2.0))
    assert policy.next_delay(now=3.0, ran_for=0.1) is None  # a fourth within the minute: give up
    assert policy.next_delay(now=61.5, ran_for=0.1) is not None  # the first two have aged out


def test_exit_descriptions():
    assert describe_exit(-9) == "was killed by SIGKILL"
    assert describe_exit(3) == "exited with code 3"


def test_each_service_gets_the_router_namespace_and_only_the_options_it_takes(tmp_path: Path):
    launch = Launch(
        namespace="trial7",
        connect=["tcp/127.0.0.1:7555"],
        site="lab.toml",
        log_level="DEBUG",
        mission=MissionOptions(method="no-comm", mode="lockstep", seed=4),
        run_dir=tmp_path,
    )
    sim = service_argv(SERVICES["sim"], launch)
    assert sim[:3] == [sys.executable, "-m", "services.cli"] and sim[3] == "sim"
    for pair in (
        ["--namespace", "trial7"],
        ["--connect", "tcp/127.0.0.1:7555"],
        ["--site", "lab.toml"],
        ["--method", "no-comm"],
        ["--mode", "lockstep"],
        ["--seed", "4"],
        ["--log-level", "DEBUG"],
    ):
        assert " ".join(pair) in " ".join(sim), pair
    ar = service_argv(SERVICES["ar"], launch)
    assert "--method" not in ar and "--seed" not in ar
    restrictor = service_argv(SERVICES["restrictor"], launch)
    assert restrictor[restrictor.index("--state-dir") + 1] == str(tmp_path / "state")


def test_a_config_directory_replaces_the_endpoint_with_per_role_files(tmp_path: Path):
    launch = Launch(namespace="n", connect=[], zenoh_config_dir=tmp_path)
    planner = service_argv(SERVICES["planner"], launch)
    assert (
        planner[planner.index("--zenoh-config") + 1] == str(tmp_path / "planner.json5") and "--connect" not in planner
    )
    assert router_argv(launch, None)[-2:] == ["--zenoh-config", str(tmp_path / "router.json5")]
    assert launch.zenoh_env() == {"ARROCH_NAMESPACE": "n"}  # extra children read the files' router, not an env override


def test_service_lists_and_extra_children():
    assert [s.name for s in parse_services(None)] == ["planner", "restrictor", "sim", "ar"]
    assert parse_services("") == []
    with pytest.raises(ValueError, match="listed twice"):
        parse_services("sim,sim")
    launch = Launch(namespace="n1", connect=["tcp/127.0.0.1:1"])
    name, argv = parse_child("rec={python} -m tool --ns {namespace} --to '{connect}'", launch)
    assert name == "rec" and argv == [sys.executable, "-m", "tool", "--ns", "n1", "--to", "tcp/127.0.0.1:1"]


def test_progress_counts_each_delivery_once_whether_heard_from_status_or_event():
    progress = MissionProgress({"r0": 2, "r1": 1})
    progress.on_status(RobotStatus(robot="r0", state="moving", delivered=["o0"], stamp=12.0))
    progress.on_event(Event(kind="delivered", robot="r0", object="o0", stamp=12.5))  # the same delivery
    progress.on_event(Event(kind="door_opened", door="d1", stamp=20.0, data={"by": "robot"}))
    progress.on_status(RobotStatus(robot="r1", state="waiting_at_door", waiting_door="d1", stamp=21.0))
    assert progress.delivered() == (1, 3)
    line = progress.line()
    assert "t=21.0s delivered 1/3" in line and "r0 1/2 moving" in line and "r1 0/1 waiting at d1" in line
    assert "door openings 1 (by the human 0)" in line
    assert progress.bar(width=6).startswith("[##....] 1/3 delivered")
    progress.on_event(Event(kind="mission_done", data={"reason": "stopped by hand"}))
    assert progress.done and "other figures:\n  reason: stopped by hand" in progress.metrics_text()


def test_on_a_terminal_a_log_line_goes_above_the_progress_bar():
    stream = io.StringIO()
    out = Output(stream, bar=True)
    out.progress("[###] 1/3")
    out.line("sim", "hello")
    out.end_progress()
    erase = "\r\x1b[K"
    assert stream.getvalue() == f"{erase}[###] 1/3{erase}[sim] hello\n[###] 1/3\n"


def test_the_final_metrics_are_a_rounded_table_with_units_and_meanings():
    from services.supervisor.metrics_table import metrics_table

    metrics = {
        "completed": True,
        "time": 690.4499999999999,
        "team_completion_time": 690.4499999999999,
        "agent_completion_times": {"r0": 413.35, "human": 690.4499999999999},
        "human_door_openings": 4,
        "door_openings": {"d_lab": {"robot": 14}, "d_storage": {"human": 4}},
        "feedback": {"sent": 2, "accepted": 1, "refused": 1, "unanswered": 0},
        "robots": {"r0": {"wait_time": 229.85}},
        "robot_overlaps": 6,
        "robot_overlaps_by_place": {"storage": 4, "corridor": 2},
        "robot_overlaps_by_pair": {"r1-r2": 5, "r0-r1": 1},
        "params": {"site": "office", "method": "arroch", "seed": 1, "human": {"task_mean": 600.0}},
        "makespan": 1.23456,
    }
    table = metrics_table(metrics)
    assert "690.4499" not in table and "task_mean" not in table  # rounded; the params summed up in one line
    rows = {re.split(r"\s{2,}", line.strip())[0]: line for line in table.splitlines()}
    assert re.match(r"team completion time +690\.4  s +the slowest agent's", rows["team completion time"])
    assert re.match(r"human door openings +4  count +doors the human", rows["human door openings"])
    assert "14 by robots (automatic doors) + 4 by the human" in rows["door openings, all"]
    assert "1 accepted, 1 refused, 0 unanswered" in rows["feedback sent"]
    assert "waited 229.8 s at doors" in rows["r0 completion time"]
    assert re.match(r"robot-robot contacts +6  count +times two robots' discs", rows["robot-robot contacts"])
    assert "where: corridor 2, storage 4; between: r0-r1 1, r1-r2 5" in rows["robot-robot contacts"]
    assert "robot_overlaps" not in table  # shown in the table, not among the other figures
    assert "run: site office, method arroch, seed 1" in table
    assert "other figures:\n  makespan: 1.235" in table  # what the table does not know is still shown
    assert metrics_table({}) == "(no metrics)"
    # Figures in shapes the table does not expect are listed as they are, never a crash.
    odd = metrics_table({"door_openings": 3, "robots": ["r0"], "time": "late", "feedback": {"sent": "x"}})
    assert "  door_openings: 3" in odd and "  robots: ['r0']" in odd and "  time: late" in odd


def test_the_demo_lingers_only_for_a_terminal_unless_told():
    import argparse

    from services.demo import lingers

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    assert lingers(argparse.Namespace(linger=None), Terminal()) is True
    assert lingers(argparse.Namespace(linger=None), io.StringIO()) is False
    assert lingers(argparse.Namespace(linger=False), Terminal()) is False
    assert lingers(argparse.Namespace(linger=True), io.StringIO()) is True
