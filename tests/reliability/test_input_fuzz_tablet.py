"""Bad input to the tablet page's WebSocket: hypothesis (derandomized) draws connections — the right
token or not, odd modes — and what they send: random JSON of every shape, feedback-shaped objects with
random kinds and parameters (ASP injections among them), pings, random text and bytes, frames with
a real JPEG cut or corrupted, oversized messages. Against a real ``arroch tablet`` process with a
real restrictor behind it.

For every connection: a refused handshake is a 403 (token) or 400 (mode); an accepted one either gets
its answers (a pong to the closing probe, an ack for each feedback) or is closed by the server with a
protocol close code, never left hanging. Feedback carrying an injection is never accepted, and the
restrictor's set never holds anything but what was accepted. After every connection a fresh one gets
its hello, and at the end a good frame still gets its overlay: the server keeps serving.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.messages import ConstraintSet
from services.ar_client.web import wire
from services.sim.camera import encode_jpeg
from tests.procs import restrictor_argv
from tests.restrictor.test_validate import INJECTIONS
from tests.tablet.helpers import insecure, snapshots, start_tablet, write_calibration

pytestmark = [pytest.mark.integration]

CLOSE_CODES = {wire.CLOSE_UNSUPPORTED, wire.CLOSE_BAD_DATA, wire.CLOSE_POLICY, wire.CLOSE_TOO_BIG, 1006}
ANSWER = 10.0  # s for the server to answer or close
PROBE = 424242  # the closing ping's value
SHORT_INJECTIONS = [i for i in INJECTIONS if 0 < len(i) <= wire.MAX_STRING]
JPEG = encode_jpeg(snapshots(1).frames[0])

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**60), 2**60) | st.floats() | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)
params = st.dictionaries(
    st.sampled_from(["door", "room", "minutes", "constraint_id", "x", "t0", ""]),
    st.one_of(
        st.sampled_from(SHORT_INJECTIONS),
        st.sampled_from(["d_storage", "lab", "storage", "c1"]),
        st.integers(-5, 10**6),
        st.floats(allow_nan=False, allow_infinity=False),
    ),
    max_size=3,
)
feedback = st.fixed_dictionaries(
    {
        "type": st.just("feedback"),
        "id": st.integers(0, 2**53 - 1),
        "kind": st.sampled_from(["door_unavailable", "forbid_room", "door_available_now", "cancel", *SHORT_INJECTIONS]),
        "params": params,
    }
)


@st.composite
def frames(draw: Any) -> bytes:
    """A frame message: the real JPEG cut, corrupted or not, behind the right magic or another."""
    jpeg = bytearray(JPEG)
    how = draw(st.sampled_from(["whole", "cut", "flip", "header", "empty"]))
    if how == "cut":
        jpeg = jpeg[: draw(st.integers(0, len(jpeg)))]
    elif how == "flip":
        for _ in range(draw(st.integers(1, 8))):
            jpeg[draw(st.integers(0, len(jpeg) - 1))] ^= 0xFF
    elif how == "header":
        at = draw(st.integers(0, 40))
        jpeg[at : at + 4] = draw(st.binary(min_size=4, max_size=4))
    elif how == "empty":
        jpeg = bytearray()
    magic = draw(st.sampled_from([wire.FRAME_MAGIC, wire.FRAME_MAGIC, wire.VIEWER_MAGIC, b"ARF2"]))
    return wire.HEADER.pack(magic, draw(st.integers(0, 2**32 - 1))) + bytes(jpeg)


messages = st.one_of(
    json_values.map(json.dumps),
    st.fixed_dictionaries(
        {"type": st.sampled_from(["ping", "feedback", "frame", "hello", "ack", ""])},
        optional={"t": json_values, "id": json_values, "kind": json_values, "params": json_values},
    ).map(json.dumps),
    feedback.map(json.dumps),
    st.text(max_size=60),
    st.binary(max_size=64),
    frames(),
    st.sampled_from(["x" * (wire.MAX_TEXT_BYTES + 1), json.dumps({"type": "ping", "t": "x" * wire.MAX_TEXT_BYTES})]),
)
connections = st.fixed_dictionaries(
    {
        "token": st.sampled_from(["right"] * 8 + ["wrong", ""]),
        "mode": st.sampled_from(["ar", "ar", "viewer", "", "bogus"]),
        # Anything at all, or feedback only (which the server passes on to the restrictor).
        "messages": st.lists(messages, min_size=1, max_size=5)
        | st.lists(feedback.map(json.dumps), min_size=1, max_size=3),
    }
)


def injected(feedback: dict) -> bool:
    """Whether a feedback request carries an injection (in its kind or a parameter value)."""
    values = [feedback.get("kind"), *(feedback["params"].values() if isinstance(feedback.get("params"), dict) else [])]
    return any(isinstance(v, str) and v in SHORT_INJECTIONS for v in values)


async def exchange(base: str, token: str, connection: dict) -> list[str]:
    """One connection as drawn; the answers it got (or the handshake's refusal). Fails the test when the
    server neither answers nor closes."""
    use = token if connection["token"] == "right" else connection["token"]
    query = f"token={use}" + (f"&mode={connection['mode']}" if connection["mode"] else "")
    async with aiohttp.ClientSession(connector=insecure()) as http:
        try:
            ws = await http.ws_connect(f"{base}/ws?{query}", headers={"Origin": base}, max_msg_size=0)
        except aiohttp.WSServerHandshakeError as exc:
            expected = 403 if use != token else 400
            assert exc.status == expected and (use != token or connection["mode"] not in ("", "ar", "viewer")), (
                connection,
                exc.status,
            )
            return [f"refused {exc.status}"]
        assert use == token and connection["mode"] in ("", "ar", "viewer"), connection
        hello = await ws.receive_json(timeout=ANSWER)
        assert hello["type"] == "hello"
        feedback_ids: set[int] = set()
        smuggling: set[int] = set()
        for message in connection["messages"]:
            if isinstance(message, str) and (data := _feedback_of(message)) is not None:
                feedback_ids.add(data["id"])
                if injected(data):
                    smuggling.add(data["id"])
            try:
                await (ws.send_str(message) if isinstance(message, str) else ws.send_bytes(message))
            except (ConnectionError, RuntimeError):
                break  # the server closed already
        try:
            await ws.send_str(json.dumps({"type": "ping", "t": PROBE}))
        except (ConnectionError, RuntimeError):
            pass
        answers: list[str] = []
        pong = False
        while not (pong and not feedback_ids):
            msg = await asyncio.wait_for(ws.receive(), ANSWER)
            if msg.type in (
                aiohttp.WSMsgType.CLOSE,
                aiohttp.WSMsgType.CLOSING,
                aiohttp.WSMsgType.CLOSED,
                aiohttp.WSMsgType.ERROR,
            ):
                assert ws.close_code in CLOSE_CODES, (connection, ws.close_code)
                answers.append(f"closed {ws.close_code}")
                return answers
            data = json.loads(msg.data) if msg.type == aiohttp.WSMsgType.TEXT else {"type": "binary"}
            if data["type"] == "pong" and data.get("t") == PROBE:
                pong = True
            elif data["type"] == "ack":
                feedback_ids.discard(data["id"])
                assert not (data["id"] in smuggling and data["status"] == "accepted"), (connection, data)
                answers.append(f"ack {data['status']}")
        await ws.close()
        return answers


def _feedback_of(message: str) -> dict | None:
    try:
        data = json.loads(message)
    except ValueError:
        return None
    ok = (
        isinstance(data, dict)
        and data.get("type") == "feedback"
        and isinstance(data.get("id"), int)
        and not isinstance(data["id"], bool)
    )
    return data if ok else None


async def hello(base: str, token: str) -> None:
    async with aiohttp.ClientSession(connector=insecure()) as http:
        ws = await http.ws_connect(f"{base}/ws?token={token}", headers={"Origin": base})
        assert (await ws.receive_json(timeout=ANSWER))["type"] == "hello"
        await ws.close()


async def good_frame(base: str, token: str) -> dict:
    async with aiohttp.ClientSession(connector=insecure()) as http:
        ws = await http.ws_connect(f"{base}/ws?token={token}", headers={"Origin": base})
        await ws.receive_json(timeout=ANSWER)
        await ws.send_bytes(wire.pack_frame(7, JPEG))
        while True:
            data = await ws.receive_json(timeout=30)
            if data["type"] == "overlay":
                await ws.close()
                return data


def test_the_tablet_socket_answers_or_closes_and_keeps_serving(
    router, namespace, client, spawn, tmp_path: Path
) -> None:
    restrictor = spawn(
        restrictor_argv(namespace, router, tmp_path / "restrictor"),
        name="restrictor",
    )
    calibration = write_calibration(tmp_path / "intrinsics.json", snapshots(1))
    server = start_tablet(spawn, router, namespace, tmp_path / "state", "--no-qr", "--intrinsics", str(calibration))
    restrictor.wait_for("up on namespace", timeout=30)
    outcomes: list[str] = []

    @settings(
        max_examples=150,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )
    @given(connection=connections)
    def check(connection: dict) -> None:
        outcomes.extend(asyncio.run(exchange(server.base, server.token, connection)))
        asyncio.run(hello(server.base, server.token))  # the next page still gets in
        assert server.proc.alive()

    check()
    assert any(o.startswith("closed") for o in outcomes) and any(o.startswith("refused") for o in outcomes), outcomes
    assert any(o.startswith("ack") for o in outcomes), outcomes
    assert asyncio.run(good_frame(server.base, server.token))["seq"] == 7
    # Whatever was accepted came from the library's own kinds and the site's names: no injected text.
    [current] = client.query(client.keys.constraints(), ConstraintSet, timeout=5.0)
    for constraint in current.constraints:
        assert constraint.kind in ("door_unavailable", "forbid_room", "door_available_now"), constraint
        assert not any(str(v) in SHORT_INJECTIONS for v in constraint.params.values()), constraint
    assert restrictor.alive() and server.proc.alive()
