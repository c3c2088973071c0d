"""A peer that tries to drive a robot it has no right to, run inside a test "host" (network namespace).

    python -m tests.deploy.peer --configs DIR --namespace NS --try nocert,foreign,intruder,ar --control planner

For each identity in ``--try`` (a rendered ``DIR/<name>.json5``) it joins the secure router, or
records why it could not, and publishes a RobotCommand on ``robot/r0/command`` whose ``robot`` field
names that identity — a command the simulator refuses and counts (``commands_refused``) and logs
("command for robot '<name>' arrived on 'r0''s key") if it ever receives one. Then the ``--control``
identity, which may command robots, publishes the same kind of command: the sim must count exactly
those. The sim's counters are read from its ``stats`` queryable (as the supervisor identity),
first waiting for a sim to answer, and one JSON line is printed:

    {"attempts": {"nocert": "cannot connect: ...", "intruder": "published", ...},
     "control": "published", "repeats": 3, "sim_stats": {...}}

Each identity publishes its command ``REPEATS`` times.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import zenoh

from protocol.codec import encode
from protocol.messages import Event, RobotCommand
from tests.deploy.secure import RoleClient

MATCH_WAIT = 2.0  # s a member's publisher gets to learn of the sim's subscriber (an intruder's never does)
REPEATS = 3  # puts per identity: the sim counts each one it receives
GRACE = 1.0  # s the refused commands get to show up after the control's has been counted


def command_from(label: str) -> bytes:
    return encode(RobotCommand(robot=label.replace("-", "_"), plan_id=1, action_id=1, action="stop"))


def publish_as(client: RoleClient, label: str) -> str:
    """Publish the marked command once the publisher matches (or after MATCH_WAIT); say how it went."""
    publisher = client.session.declare_publisher(client.keys.robot_command("r0"))
    deadline = time.monotonic() + MATCH_WAIT
    while not publisher.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.02)
    matched = publisher.matching_status.matching
    for _ in range(REPEATS):
        publisher.put(command_from(label))
    return "published" if matched else "published (no subscriber known)"


def sim_stats(watcher: RoleClient) -> dict | None:
    replies = watcher.query(watcher.keys.stats("sim"), Event, timeout=2.0)
    return dict(replies[0].data) if replies else None


def wait_for_sim(watcher: RoleClient, timeout: float) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        stats = sim_stats(watcher)
        if stats is not None:
            return stats
        time.sleep(0.2)
    raise SystemExit(f"no sim answered on stats/sim/* within {timeout:.0f} s")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configs", required=True, type=Path)
    parser.add_argument("--namespace", required=True)
    parser.add_argument("--try", dest="identities", required=True, help="comma-separated config names")
    parser.add_argument("--control", required=True, help="config name of an identity that may command robots")
    parser.add_argument("--watcher", default="supervisor", help="config name used to read the sim's counters")
    parser.add_argument("--sim-timeout", type=float, default=60.0)
    args = parser.parse_args()

    def join(name: str) -> RoleClient:
        return RoleClient(args.namespace, args.configs / f"{name}.json5", name).open()

    watcher = join(args.watcher)
    opened: list[RoleClient] = [watcher]
    try:
        wait_for_sim(watcher, args.sim_timeout)
        attempts: dict[str, str] = {}
        for name in args.identities.split(","):
            try:
                client = join(name)
            except zenoh.ZError as exc:
                attempts[name] = f"cannot connect: {exc}"
                continue
            opened.append(client)
            attempts[name] = publish_as(client, name)
        control = join(args.control)
        opened.append(control)
        control_result = publish_as(control, "control")
        deadline = time.monotonic() + 10.0
        stats = sim_stats(watcher) or {}
        while stats.get("commands_refused", 0) < REPEATS and time.monotonic() < deadline:
            time.sleep(0.1)
            stats = sim_stats(watcher) or {}
        time.sleep(GRACE)
        stats = sim_stats(watcher) or stats
        print(
            json.dumps({"attempts": attempts, "control": control_result, "repeats": REPEATS, "sim_stats": stats}),
            flush=True,
        )
        return 0
    finally:
        for client in reversed(opened):
            client.close()


if __name__ == "__main__":
    sys.exit(main())
