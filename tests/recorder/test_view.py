"""``arroch view``: the recorder's channels live on the Foxglove WebSocket protocol, checked with a
plain WebSocket client that subscribes to every advertised channel and decodes what comes (protobuf
with the advertised schemas, JSON), while the recorded mission is replayed into the namespace."""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import sys
import time

import aiohttp
import pytest
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

from protocol.messages import Event
from runtime.transport import free_tcp_port
from services.recorder.reading import channel_stats
from tests.procs import ROOT, arroch

pytestmark = [pytest.mark.integration, pytest.mark.slow]

SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk's name for the Foxglove WebSocket protocol
MESSAGE_DATA = 0x01  # binary opcode: subscription id (u32), log time (u64), payload
EVENTS, PLAN = "/arroch/event", "/arroch/plan"  # the messages as JSON
# s without a message, after the replay ended, that ends the watch: a viewer's channels are not sent
# in one order (mission_done may come before the last plans), so the end is when nothing more comes
QUIET = 2.0


async def watch(url: str, replay_argv: list[str]) -> tuple[dict[str, list], dict[str, dict], int]:
    """Subscribe to everything advertised, run the replay, return decoded messages per topic."""
    factory = DecoderFactory()
    channels: dict[int, dict] = {}
    subscriptions: dict[int, dict] = {}
    received: dict[str, list] = {}
    async with aiohttp.ClientSession() as http, http.ws_connect(url, protocols=(SUBPROTOCOL,)) as ws:
        assert ws.protocol == SUBPROTOCOL
        replay = None
        loop = asyncio.get_running_loop()
        replay_ended: float | None = None  # loop time the replay process was seen to have exited
        last_message = loop.time()
        deadline = loop.time() + 120
        while loop.time() < deadline:
            if replay is not None and replay.returncode is not None and replay_ended is None:
                replay_ended = loop.time()
                deadline = min(deadline, replay_ended + 10.0)  # what the viewer still has on its way
            if replay_ended is not None and loop.time() - last_message > QUIET:
                break  # nothing more for QUIET s after the replay ended: the viewer has sent it all
            try:
                frame = await ws.receive(timeout=0.5)
            except TimeoutError:
                continue
            last_message = loop.time()
            if frame.type == aiohttp.WSMsgType.TEXT:
                op = json.loads(frame.data)
                if op["op"] == "advertise":
                    subs = []
                    for channel in op["channels"]:
                        sid = len(subscriptions) + 1
                        channels[channel["id"]] = channel
                        subscriptions[sid] = channel
                        if channel["encoding"] == "protobuf":
                            schema = Schema(
                                id=channel["id"],
                                name=channel["schemaName"],
                                encoding="protobuf",
                                data=base64.b64decode(channel["schema"]),
                            )
                            channel["decode"] = factory.decoder_for("protobuf", schema)
                        subs.append({"id": sid, "channelId": channel["id"]})
                    await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": subs}))
                    if replay is None:  # the fixed channels are advertised from the start: now the mission
                        await asyncio.sleep(0.5)
                        replay = await asyncio.create_subprocess_exec(
                            *replay_argv, cwd=ROOT, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL
                        )
            elif frame.type == aiohttp.WSMsgType.BINARY and frame.data[0] == MESSAGE_DATA:
                sid, _log_time = struct.unpack_from("<IQ", frame.data, 1)
                channel = subscriptions[sid]
                payload = frame.data[13:]
                decoded = (
                    channel["decode"](payload)
                    if "decode" in channel
                    else json.loads(payload)
                    if channel["encoding"] == "json"
                    else payload
                )
                received.setdefault(channel["topic"], []).append(decoded)
            elif frame.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                break
        code = await replay.wait() if replay is not None else -1
    return received, {c["topic"]: c for c in channels.values()}, code


def test_the_live_view_serves_decodable_channels_to_a_websocket_client(mission, spawn, router, namespace, client):
    port = free_tcp_port()
    view = spawn(arroch("view", "--port", str(port), "--namespace", namespace, "--connect", router), name="view")
    view.wait_for("Foxglove WebSocket server", timeout=60)
    replay = [
        sys.executable,
        "-m",
        "services.cli",
        "replay",
        str(mission.recording),
        "--rate",
        "100",
        "--namespace",
        namespace,
        "--connect",
        router,
        "--delay",
        "1.0",
    ]
    received, channels, code = asyncio.run(watch(f"ws://127.0.0.1:{port}", replay))
    assert code == 0, code
    assert "/site" in channels, (sorted(channels), {k: len(v) for k, v in received.items()})
    assert channels["/site"]["schemaName"] == "foxglove.SceneUpdate"
    scene_ids = {e.id for msg in received["/site"] for e in msg.entities}
    assert {"walls", "door/d_storage", "robot/r0"} <= scene_ids  # sent again when the client subscribed
    frames = {t.child_frame_id for msg in received["/tf"] for t in msg.transforms}
    assert {"r0/base_link", "r1/base_link", "r2/base_link", "tablet/camera_optical_frame"} <= frames
    assert {c["encoding"] for c in channels.values()} == {"json", "protobuf"}  # all a viewer decodes
    plans = next(c.messages for c in channel_stats(mission.recording) if c.topic == PLAN)
    assert all("plan_id" in plan for plan in received[PLAN]) and len(received[PLAN]) == plans  # every plan
    assert any(len(msg.entities) and len(msg.entities[0].lines) for msg in received["/paths"])
    images = received["/camera/tablet/image"]
    assert images and all(img.format == "jpeg" and img.data[:2] == b"\xff\xd8" for img in images)
    assert received["/camera/tablet/calibration"][0].width > 0
    assert any(event["kind"] == "mission_done" for event in received[EVENTS])
    assert received["/progress"][-1]["delivered"] == 9

    # Garbage on a recorded key is dropped and counted; the recorder goes on.
    for payload in (b"\x00garbage", b"\x81\xa4type\xa9RobotPose"):
        client.session.put(client.keys.robot_pose("r0"), payload)
    deadline = time.monotonic() + 10
    bad = 0
    while bad < 2 and time.monotonic() < deadline:
        replies = client.query(client.keys.stats("recorder", "*"), Event, timeout=2.0)
        bad = replies[0].data.get("bad_messages", 0) if replies else 0
    assert bad == 2 and view.alive()
