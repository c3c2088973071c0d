"""The secure profile on localhost, by experiment: a real router process with the rendered config
(TLS, mutual authentication, access control) and clients holding the rendered per-role configs.

Every "never arrives" below has a control in the same test: a permitted message on the same key
to the same subscriber does arrive, and a denied publisher has heard of the subscriber (its
publisher matches) before it publishes, so its message was sent and the router dropped it.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import zenoh

from protocol.messages import ConstraintSet, Feedback, RobotCommand, RobotStatus
from runtime.transport import ZenohOptions, open_session
from services.supervisor.deployment import acl
from services.supervisor.deployment.render import Request, render
from tests.conftest import wait_for_message
from tests.deploy.secure import INTRUDER, RoleClient

GRACE = 0.7  # seconds a denied message gets to show up after the permitted ones arrived


class Inbox:
    """Raw payloads heard on one key by one session, from Zenoh's thread."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.items: list[str] = []
        self._cond = threading.Condition()
        self.sub = session.declare_subscriber(key, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.items.append(sample.payload.to_string())
            self._cond.notify_all()

    def wait_for(self, item: str, timeout: float = 10.0) -> None:
        with self._cond:
            if not self._cond.wait_for(lambda: item in self.items, timeout):
                raise AssertionError(f"{item!r} never arrived (got {self.items})")


def wait_matching(publisher: zenoh.Publisher, timeout: float = 10.0) -> bool:
    """True once the publisher knows of a matching subscriber (so its puts are really sent)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if publisher.matching_status.matching:
            return True
        time.sleep(0.02)
    return False


def concrete(key: str) -> str:
    return key.replace("*", "x1")


def test_roles_exchange_their_messages_over_tls(join):
    planner, restrictor, sim, ar, supervisor = (join(r) for r in ("planner", "restrictor", "sim", "ar", "supervisor"))
    commands = sim.collect(sim.keys.robot_command("*"), RobotCommand)
    feedback = restrictor.collect(restrictor.keys.feedback(), Feedback)
    constraints = ar.collect(ar.keys.constraints(), ConstraintSet)
    statuses = supervisor.collect(supervisor.keys.robot_status("*"), RobotStatus)
    time.sleep(0.5)  # subscriptions reach the router

    planner.publish(planner.keys.robot_command("r0"), RobotCommand(robot="r0", plan_id=1, action_id=1, action="stop"))
    ar.publish(ar.keys.feedback(), Feedback(kind="door_unavailable", params={"door": "d_storage", "minutes": 5}))
    sim.publish(sim.keys.feedback(), Feedback(kind="door_available_now", params={"door": "d_storage"}))
    restrictor.publish(restrictor.keys.constraints(), ConstraintSet(version=3))
    sim.publish(sim.keys.robot_status("r0"), RobotStatus(robot="r0", state="moving"))

    assert wait_for_message(commands).src == planner.src
    assert {wait_for_message(feedback).src, wait_for_message(feedback).src} == {ar.src, sim.src}
    assert wait_for_message(constraints).version == 3
    assert wait_for_message(statuses).state == "moving"


@pytest.mark.parametrize(
    "config, why",
    [
        ("nocert", "presents no client certificate"),
        ("foreign", "presents a certificate from another authority"),
    ],
)
def test_client_without_valid_credentials_cannot_connect(
    secure_router, secure_configs: Path, namespace: str, config: str, why: str
):
    client = RoleClient(namespace, secure_configs / f"{config}.json5", config)
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        client.open()
    assert client._session is None, f"a client that {why} got a session"


def test_plain_tcp_is_refused(secure_router, router_port: int):
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        open_session(ZenohOptions(mode="client", connect=[f"tcp/127.0.0.1:{router_port}"])).close()


def test_publish_guards_hold_for_every_key(join):
    """For every guarded key: its owners' messages arrive, every other role's and the intruder's do not."""
    sessions = {role: join(role) for role in acl.ROLES}
    sessions[INTRUDER] = join(INTRUDER)
    # Readers have sessions of their own: a session hears its own puts locally, without the router.
    readers = {role: join(role) for role in {(g.readers or ("supervisor",))[0] for g in acl.GUARDS}}
    ns = sessions["planner"].keys.prefix
    inboxes: dict[str, Inbox] = {}
    for guard in acl.GUARDS:
        reader = (guard.readers or ("supervisor",))[0]
        inboxes[guard.key] = Inbox(readers[reader].session, f"{ns}/{concrete(guard.key)}")
    publishers = []
    for guard in acl.GUARDS:
        key = f"{ns}/{concrete(guard.key)}"
        for who, client in sessions.items():
            publisher = client.session.declare_publisher(key)
            publishers.append(publisher)
            if who != INTRUDER:
                # A member hears of the subscriber, so its put is really sent: the router must drop it.
                assert wait_matching(publisher), f"{who} never learnt of the subscriber on {key}"
            verdict = "allowed" if who in guard.publishers else "denied"
            publisher.put(f"{verdict}:{who}")
    for guard in acl.GUARDS:
        for who in guard.publishers:
            inboxes[guard.key].wait_for(f"allowed:{who}")
    time.sleep(GRACE)
    leaked = {key: [item for item in inbox.items if item.startswith("denied")] for key, inbox in inboxes.items()}
    assert not any(leaked.values()), f"denied publications arrived: {leaked}"
    for publisher in publishers:
        publisher.undeclare()


def test_only_robots_read_commands_and_the_intruder_reads_nothing(join):
    planner, sim, ar, supervisor, intruder = (join(r) for r in ("planner", "sim", "ar", "supervisor", INTRUDER))
    everything = f"{planner.keys.prefix}/**"
    seen = {
        who: Inbox(client.session, everything)
        for who, client in (("sim", sim), ("ar", ar), ("supervisor", supervisor), (INTRUDER, intruder))
    }
    command = planner.session.declare_publisher(planner.keys.robot_command("r0"))
    plan = planner.session.declare_publisher(planner.keys.plan())
    assert wait_matching(command) and wait_matching(plan)
    command.put("command")
    plan.put("plan")
    seen["sim"].wait_for("command")
    for who in ("ar", "supervisor", "sim"):
        seen[who].wait_for("plan")  # they do hear the planner: only commands are withheld
    time.sleep(GRACE)
    assert "command" not in seen["ar"].items and "command" not in seen["supervisor"].items
    assert seen[INTRUDER].items == [], f"the intruder heard {seen[INTRUDER].items}"


def test_feedback_queries_only_from_the_human_side_and_plan_served_only_by_the_planner(join):
    restrictor, planner, ar, sim, supervisor = (join(r) for r in ("restrictor", "planner", "ar", "sim", "supervisor"))
    feedback_key, plan_key = restrictor.keys.feedback(), planner.keys.plan()
    acks = restrictor.session.declare_queryable(feedback_key, lambda q: q.reply(feedback_key, "ack"))
    real = planner.session.declare_queryable(plan_key, lambda q: q.reply(plan_key, "real plan"))
    fake = ar.session.declare_queryable(plan_key, lambda q: q.reply(plan_key, "fake plan"))
    time.sleep(0.5)

    def answers(client: RoleClient, key: str) -> list[str]:
        return [r.ok.payload.to_string() for r in client.session.get(key, timeout=1.5) if r.ok is not None]

    assert answers(ar, feedback_key) == ["ack"]
    assert answers(sim, feedback_key) == ["ack"]
    assert answers(planner, feedback_key) == [], "the planner's query (a feedback) reached the restrictor"
    assert answers(supervisor, plan_key) == ["real plan"], "an AR client served a plan"
    for queryable in (acks, real, fake):
        queryable.undeclare()


def test_a_peer_with_the_secure_peer_profile_joins_through_the_router(
    join, pki, router_port: int, namespace: str, tmp_path: Path
):
    certs, _ = pki
    config = tmp_path / "sim-peer.json5"
    config.write_text(
        render(Request("secure", "sim", kind="peer", certs=certs, connect=[f"tls/127.0.0.1:{router_port}"]))
    )
    supervisor = join("supervisor")
    statuses = supervisor.collect(supervisor.keys.robot_status("*"), RobotStatus)
    peer = RoleClient(namespace, config, "sim-peer").open()
    try:
        publisher = peer.session.declare_publisher(peer.keys.robot_status("r3"))
        assert wait_matching(publisher)
        peer.publish(peer.keys.robot_status("r3"), RobotStatus(robot="r3", state="idle"))
        assert wait_for_message(statuses).robot == "r3"
        publisher.undeclare()
    finally:
        peer.close()
