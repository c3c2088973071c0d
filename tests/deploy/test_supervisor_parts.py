"""The supervisor's parts on their own: restart policy, command lines, progress, output."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import pytest

from protocol.launch.catalog import (
    SERVICES,
    Launch,
    MissionOptions,
    parse_child,
    parse_services,
    router_argv,
    service_argv,
)
from protocol.launch.children import RestartPolicy, describe_exit
from protocol.messages import Event, RobotStatus
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
    progress.on_event(Event(kind="door_opened", door="d1", stamp=20.0))
    progress.on_status(RobotStatus(robot="r1", state="waiting_at_door", waiting_door="d1", stamp=21.0))
    assert progress.delivered() == (1, 3)
    line = progress.line()
    assert "t=21.0s delivered 1/3" in line and "r0 1/2 moving" in line and "r1 0/1 waiting at d1" in line
    assert "door openings 1" in line
    assert progress.bar(width=6).startswith("[##....] 1/3 delivered")
    progress.on_event(Event(kind="mission_done", data={"makespan": 99.25}))
    assert progress.done and "makespan  99.250" in progress.metrics_text()


def test_on_a_terminal_a_log_line_goes_above_the_progress_bar():
    stream = io.StringIO()
    out = Output(stream, bar=True)
    out.progress("[###] 1/3")
    out.line("sim", "hello")
    out.end_progress()
    erase = "\r\x1b[K"
    assert stream.getvalue() == f"{erase}[###] 1/3{erase}[sim] hello\n[###] 1/3\n"
