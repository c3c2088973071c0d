"""The secure profile against the real services: a secure router (TLS, mutual authentication, access
control, as ``arroch deploy render`` writes them) with a real restrictor and a real simulator behind it.

Peers without the right identity try what matters most — driving a robot, telling the restrictor
what the human wants, listening to robot commands:

- no certificate, a certificate from another authority, plain TCP: no session at all;
- ``intruder`` (a valid certificate whose name is no role): its RobotCommand and Feedback never reach
  the services, its Feedback query gets no answer, it hears no command;
- members in the wrong role: the AR client's command and the planner's feedback are dropped too.

The services' own counters say what they received, and a permitted message from the right role on
each key, sent after the attacks, is the control: it arrives, and it is the only thing that did.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from protocol.codec import encode
from protocol.messages import Event, Feedback, RobotCommand
from runtime.transport import ZenohOptions, free_tcp_port, open_session
from tests.deploy.secure import INTRUDER, RoleClient, make_pki, render_configs, role_clients
from tests.procs import Proc, arroch

pytestmark = [pytest.mark.integration]

GRACE = 1.0  # s a dropped message gets to show up anyway


@pytest.fixture(scope="module")
def secure(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, int]]:
    """(rendered configs, router port) with ``arroch router`` running on the secure router config."""
    folder = tmp_path_factory.mktemp("secure")
    certs, foreign = make_pki(folder)
    port = free_tcp_port()
    configs = render_configs(
        certs, foreign, folder / "zenoh", router=f"tls/127.0.0.1:{port}", listen=f"tls/127.0.0.1:{port}"
    )
    router = Proc(arroch("router", "--zenoh-config", str(configs / "router.json5")), name="secure-router")
    try:
        router.wait_for("router ready", timeout=30)
        yield configs, port
    finally:
        router.stop()


@pytest.fixture
def join(secure: tuple[Path, int], namespace: str) -> Iterator[Callable[[str], RoleClient]]:
    configs, _ = secure
    with role_clients(namespace, configs) as join:
        yield join


def counters(reader: RoleClient, service: str) -> dict:
    """A service's counters, read through its stats queryable by an identity allowed to ask."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        replies = reader.query(reader.keys.stats(service, "*"), Event, timeout=2.0)
        if replies:
            return dict(replies[0].data)
        time.sleep(0.2)
    raise AssertionError(f"no stats from {service}")


def wait_until(check: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, f"{what} within {timeout} s"
        time.sleep(0.1)


def test_only_the_right_roles_reach_the_restrictor_and_the_robots(
    secure, join, spawn, namespace: str, tmp_path: Path
) -> None:
    configs, port = secure
    restrictor = spawn(
        arroch(
            "restrictor",
            "--namespace",
            namespace,
            "--zenoh-config",
            str(configs / "restrictor.json5"),
            "--clock",
            "wall",
            "--state-dir",
            str(tmp_path / "state"),
        ),
        name="restrictor",
    )
    sim = spawn(
        arroch("sim", "--namespace", namespace, "--zenoh-config", str(configs / "sim.json5"), "--mode", "lockstep"),
        name="sim",
    )
    restrictor.wait_for("up on namespace", timeout=30)
    sim.wait_for("up on namespace", timeout=60)

    # No identity, a foreign authority, plain TCP: no session to attack with.
    for config in ("nocert", "foreign"):
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_session(ZenohOptions(config_file=str(configs / f"{config}.json5"))).close()
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        open_session(ZenohOptions(mode="client", connect=[f"tcp/127.0.0.1:{port}"])).close()

    supervisor, intruder, ar, planner = (join(who) for who in ("supervisor", INTRUDER, "ar", "planner"))
    wait_until(lambda: counters(supervisor, "sim") and counters(supervisor, "restrictor"), "both services answer")
    before = {service: counters(supervisor, service) for service in ("sim", "restrictor")}

    # The intruder listens for commands all along.
    heard: list[str] = []
    lock = threading.Lock()

    def overheard(sample: zenoh.Sample) -> None:
        with lock:
            heard.append(str(sample.key_expr))

    # Remote only: a session hears its own puts locally, without the router.
    listener = intruder.session.declare_subscriber(
        intruder.keys.robot_command("*"), overheard, allowed_origin=zenoh.Locality.REMOTE
    )
    command = RobotCommand(robot="r0", plan_id=1, action_id=1, action="stop")
    feedback = Feedback(kind="door_unavailable", params={"door": "d_storage", "minutes": 5})

    # Attacks: the intruder and members in the wrong role, on commands and feedback.
    intruder.publish(intruder.keys.robot_command("r0"), command)
    intruder.publish(intruder.keys.feedback(), feedback)
    replies = [
        r
        for r in intruder.session.get(intruder.keys.feedback(), payload=encode(intruder.stamp(feedback)), timeout=2.0)
        if r.ok is not None
    ]
    assert replies == [], "the intruder's feedback query was answered"
    ar.publish(ar.keys.robot_command("r0"), command)
    planner.publish(planner.keys.feedback(), feedback)
    time.sleep(GRACE)
    for service in ("sim", "restrictor"):
        now = counters(supervisor, service)
        assert now.get("received", 0) == before[service].get("received", 0), (service, before[service], now)

    # Controls: the planner's command reaches the sim, the AR client's feedback the restrictor.
    planner.publish(planner.keys.robot_command("r0"), command)
    ar.publish(ar.keys.feedback(), feedback)
    wait_until(
        lambda: counters(supervisor, "sim").get("received", 0) == before["sim"].get("received", 0) + 1,
        "the planner's command",
    )
    wait_until(lambda: counters(supervisor, "restrictor").get("feedback_accepted", 0) == 1, "the AR client's feedback")
    time.sleep(GRACE)
    sim_now, restrictor_now = counters(supervisor, "sim"), counters(supervisor, "restrictor")
    assert sim_now["received"] == before["sim"].get("received", 0) + 1, sim_now  # exactly the control
    assert restrictor_now["received"] == before["restrictor"].get("received", 0) + 1, restrictor_now
    assert restrictor_now.get("feedback_refused", 0) == 0 and restrictor_now.get("bad_messages", 0) == 0, restrictor_now
    with lock:
        assert heard == [], f"the intruder heard robot commands: {heard}"
    listener.undeclare()
    assert restrictor.alive() and sim.alive()
