"""ROS 2 link figures: CDR cost per message type, and what ``arroch robot --ros2`` does in time.

Prints one JSON object on stdout (progress on stderr):

- ``codec``: ``rosbags`` serialise / deserialise µs (median of timed loops) of the messages ARROCH
  sends or reads: Twist, Odometry, a one-transform TFMessage, a 200-pose Path, the office site's
  MarkerArray;
- ``control``: through ``arroch router`` (loopback TCP), a real driver process against a stand-in
  base (:class:`tests.ros2.harness.FakeBase`, odometry at 20 Hz): the wall time from an odometry
  message to the Twist that answers it while the robot drives (p50/p90/p99);
- ``stops``: site seconds from the event to the first zero Twist, ``--repeats`` times each, for a
  stale pose (odometry stops) and a refused command (median and max; the safety tests' bound is 0.5).

``python benchmarks/ros2.py [--repeats N]``

``python benchmarks/ros2.py --mission [--key-format F]`` instead runs the default mission with every
robot a ROS 2 base (``arroch sim --ros2-bases``) driven by its own ``arroch robot --ros2``, under
``arroch up`` in lockstep, and prints ``mission``: objects delivered, failed actions, the
simulator's robot contacts and, from the bases' own odometry (read as a ROS 2 node would, every
pair at every instant all bases reported), the closest two bases came and the instants with two
discs overlapping; the wall time. About 2 minutes on two cores.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
import timeit
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from protocol.site import load_site  # noqa: E402
from runtime.ros2 import types as ros  # noqa: E402
from runtime.ros2.config import Ros2Config  # noqa: E402
from runtime.transport import free_tcp_port  # noqa: E402
from tests.conftest import TestClient  # noqa: E402
from tests.procs import Proc, arroch  # noqa: E402
from tests.ros2.harness import FakeBase, OdometryWatch, ros2_mission, straight_command  # noqa: E402


def micro(fn, number: int = 200) -> float:  # noqa: ANN001
    return statistics.median(timeit.repeat(fn, number=number, repeat=7)) / number * 1e6


def codec_figures() -> dict:
    from runtime.ros2.markers import SiteState, site_markers

    site = load_site()
    PoseStamped = ros.t("geometry_msgs/msg/PoseStamped")
    messages = {
        "Twist": (ros.TWIST, ros.twist(0.4, -0.2)),
        "Odometry": (ros.ODOMETRY, ros.odometry(1.0, "odom", "base_link", 1, 2, 0.3, 0.4, 0.1)),
        "TFMessage_1": (
            ros.TF_MESSAGE,
            ros.t(ros.TF_MESSAGE)(transforms=[ros.transform_stamped(1.0, "map", "r0/base_link", 1, 2, 0.3)]),
        ),
        "Path_200": (
            ros.PATH,
            ros.t(ros.PATH)(
                header=ros.header(1.0, "map"),
                poses=[PoseStamped(header=ros.header(i, "map"), pose=ros.pose(i * 0.1, 1, 0)) for i in range(200)],
            ),
        ),
        "MarkerArray_office": (ros.MARKER_ARRAY, site_markers(site, SiteState(), 1.0)),
    }
    out = {}
    for name, (typename, msg) in messages.items():
        payload = ros.serialize(msg, typename)
        n = 20 if "Marker" in name or "Path" in name else 200
        out[name] = {
            "bytes": len(payload),
            "encode_us": round(micro(lambda msg=msg, typename=typename: ros.serialize(msg, typename), n), 1),
            "decode_us": round(
                micro(lambda payload=payload, typename=typename: ros.deserialize(payload, typename), n), 1
            ),
        }
    return out


def pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


MISSION_TIMEOUT = 900.0  # wall s


def mission_figures(key_format: str) -> dict:
    """The default mission through ROS 2 (see the module docstring)."""
    site = load_site()
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    namespace = f"b{uuid.uuid4().hex[:8]}"
    router = Proc(arroch("router", "--listen", endpoint), name="router")
    client = None
    up = None
    with tempfile.TemporaryDirectory(prefix="arroch-ros2-mission-") as tmp:
        try:
            router.wait_for("router ready", timeout=20)
            client = TestClient(namespace, endpoint)
            client.open()
            odometry = OdometryWatch(client, site, Ros2Config(key_format=key_format, domain=7).naming)
            started = time.monotonic()
            up = Proc(
                ros2_mission(
                    list(site.robots),
                    key_format,
                    connect=endpoint,
                    namespace=namespace,
                    run_dir=tmp,
                    timeout=MISSION_TIMEOUT,
                ),
                name="up",
            )
            while up.alive() and time.monotonic() - started < MISSION_TIMEOUT + 30:
                time.sleep(0.5)
            wall = time.monotonic() - started
            (run,) = [p for p in Path(tmp).iterdir() if p.is_dir()]
            metrics = json.loads((run / "metrics.json").read_text())
        finally:
            if up is not None:
                up.stop()
            if client is not None:
                client.close()
            router.stop()
    return {
        "key_format": key_format,
        "completed": metrics["completed"],
        "delivered": sum(len(r["delivered"]) for r in metrics["robots"].values()),
        "objects": len(site.objects),
        "team_completion_time_s": metrics.get("team_completion_time"),
        "actions_failed": metrics["actions"]["failed"],
        "sim_robot_contacts": metrics["robot_overlaps"],
        "wall_contacts": metrics.get("wall_contacts"),
        "odometry": {
            "closest_m": round(odometry.closest, 4),
            "closest_pair": list(odometry.closest_pair),
            "instants": odometry.samples,
            "instants_in_contact": odometry.contacts,
        },
        "wall_s": round(wall, 1),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--mission", action="store_true", help="only the default mission through ROS 2 (~2 min)")
    parser.add_argument("--key-format", choices=("rmw_zenoh", "ros2dds"), default="rmw_zenoh")
    args = parser.parse_args()
    if args.mission:
        result = {"mission": mission_figures(args.key_format), "machine_load_1min": round(os.getloadavg()[0], 2)}
        print(json.dumps(result, indent=2))
        return 0 if result["mission"]["completed"] else 1
    result: dict = {"codec": codec_figures()}
    print("codec done", file=sys.stderr)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    namespace = f"b{uuid.uuid4().hex[:8]}"
    site = load_site()
    start = site.robots["r0"].start
    router = Proc(arroch("router", "--listen", endpoint), name="router")
    procs = [router]
    client = None
    base = None
    try:
        router.wait_for("router ready", timeout=20)
        client = TestClient(namespace, endpoint)
        client.open()
        base = FakeBase(client, "r0", start, Ros2Config())
        driver = Proc(
            arroch("robot", "--ros2", "--robot", "r0", "--connect", endpoint, "--namespace", namespace), name="robot"
        )
        procs.append(driver)
        driver.wait_for("robot robot-r0-", timeout=20)
        base.first_zero_after(0.0, timeout=10)
        stale, refused, answers = [], [], []
        action = 0
        for i in range(args.repeats):
            for kind in ("stale", "refused"):
                action += 1
                base.odometry_on = True
                client.publish(
                    client.keys.robot_command("r0"), straight_command("r0", base.map_pose(), 6.0, action_id=action)
                )
                moving = (
                    base.wait_moving()
                    if action == 1
                    else base._wait(lambda tw: not tw.zero, base.now(), 15, "motion").site_time
                )
                time.sleep(1.0)
                with base._lock:
                    twists = [tw.site_time for tw in base.twists if tw.site_time > moving]
                sent = [t for t in base.odometry_sent if twists and moving < t < twists[-1]]
                # Each odometry's answer: the first Twist after it (before the next odometry).
                for a, b in zip(sent, sent[1:] + [float("inf")], strict=True):
                    reply = next((tw for tw in twists if tw > a), None)
                    if reply is not None and reply < b:
                        answers.append(reply - a)
                t = base.now()
                if kind == "stale":
                    base.odometry_on = False
                else:
                    action += 1
                    client.publish(
                        client.keys.robot_command("r0"),
                        straight_command("r0", base.map_pose(), 6.0, action_id=action, offset=3.0),
                    )
                stop = base.first_zero_after(t)
                (stale if kind == "stale" else refused).append(stop.site_time - t)
                base.odometry_on = True
                time.sleep(0.3)
            print(f"round {i + 1}/{args.repeats}", file=sys.stderr)
        result["control"] = {
            "odometry_to_twist_ms_p50": round(pct(answers, 0.5) * 1e3, 2),
            "p90": round(pct(answers, 0.9) * 1e3, 2),
            "p99": round(pct(answers, 0.99) * 1e3, 2),
            "samples": len(answers),
        }
        result["stops"] = {
            name: {"median_s": round(statistics.median(v), 3), "max_s": round(max(v), 3), "runs": len(v)}
            for name, v in (("stale_pose", stale), ("refused_command", refused))
        }
    finally:
        if base is not None:
            base.close()
        if client is not None:
            client.close()
        for proc in reversed(procs):
            proc.stop()
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
