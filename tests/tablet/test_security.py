"""The tablet server against the wrong people and the wrong input, as a real process over HTTPS.

Token (page, assets, WebSocket), Origin, security headers; clients that send garbage are
disconnected with the right close code while a well-behaved client on the same server keeps
getting its overlays; the restrictor's refusal reaches the client; the certificate is made once
and reused, the token is new every run; clean exit on SIGTERM; bad configuration exits 2.
"""

from __future__ import annotations

import asyncio
import json
import signal
import ssl
import subprocess

import aiohttp
import pytest

from services.ar_client.web import wire
from services.sim.camera import encode_jpeg
from tests.procs import ROOT, arroch, restrictor_argv
from tests.tablet.helpers import insecure, run, snapshots, start_tablet, write_calibration

pytestmark = pytest.mark.integration


async def _open(http: aiohttp.ClientSession, base: str, token: str, *, origin: str | None = None, mode: str = "ar"):  # noqa: ANN202
    """A WebSocket as a page would open it (its Origin is the server's own), and its hello."""
    ws = await http.ws_connect(f"{base}/ws?token={token}&mode={mode}", headers={"Origin": origin or base})
    hello = await ws.receive_json(timeout=10)
    assert hello["type"] == "hello"
    return ws, hello


class _Inbox:
    """A client socket's JSON messages by type, so one can wait for a type without losing the others."""

    def __init__(self, ws) -> None:  # noqa: ANN001
        self.ws = ws
        self.kept: list[dict] = []

    async def next(self, kind: str, timeout: float = 15.0) -> dict:
        for i, data in enumerate(self.kept):
            if data["type"] == kind:
                return self.kept.pop(i)

        async def loop() -> dict:
            while True:
                msg = await self.ws.receive()
                if msg.type != aiohttp.WSMsgType.TEXT:
                    raise AssertionError(f"expected text, got {msg.type} {msg.data!r}")
                data = json.loads(msg.data)
                if data["type"] == kind:
                    return data
                self.kept.append(data)

        return await asyncio.wait_for(loop(), timeout)


async def _next(ws, kind: str, timeout: float = 15.0) -> dict:  # noqa: ANN001
    """The next JSON message of type ``kind`` (others skipped)."""
    return await _Inbox(ws).next(kind, timeout)


async def _closed_with(ws) -> int:  # noqa: ANN001
    """Read until the server closes the socket; its close code."""
    while True:
        msg = await asyncio.wait_for(ws.receive(), 10)
        if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSING, aiohttp.WSMsgType.CLOSED):
            return ws.close_code


def test_token_origin_and_headers(router, namespace, spawn, tmp_path):
    server = start_tablet(spawn, router, namespace, tmp_path / "state", "--no-qr")

    async def check() -> None:
        # unsafe=True: keep cookies of an IP-address host, as a browser does.
        async with aiohttp.ClientSession(connector=insecure(), cookie_jar=aiohttp.CookieJar(unsafe=True)) as http:
            for url in (
                f"{server.base}/",
                f"{server.base}/?token=wrong",
                f"{server.base}/static/app.js",
                f"{server.base}/ca.pem",
            ):
                async with http.get(url) as r:
                    assert r.status == 403, url
            async with http.get(f"{server.base}/?token={server.token}") as r:
                assert r.status == 200 and '<canvas id="overlay">' in await r.text()
                assert "script-src 'self'" in r.headers["Content-Security-Policy"]
                assert r.headers["Referrer-Policy"] == "no-referrer" and r.headers["Cache-Control"] == "no-store"
                cookie = r.cookies["arroch_tablet"]
                assert (
                    cookie.value == server.token
                    and cookie["httponly"]
                    and cookie["secure"]
                    and cookie["samesite"] == "Strict"
                )
            # The cookie now opens the assets (as for the page's own script tags), but not other files.
            async with http.get(f"{server.base}/static/app.js") as r:
                assert r.status == 200 and r.headers["Content-Type"].startswith("text/javascript")
            async with http.get(f"{server.base}/static/..%2f..%2fserver.py") as r:
                assert r.status == 404
            async with http.get(f"{server.base}/ca.pem") as r:
                assert r.status == 200 and "BEGIN CERTIFICATE" in await r.text()
        async with aiohttp.ClientSession(connector=insecure()) as http:  # no cookie
            for token, origin in ((server.token, "https://evil.example"), (server.token, None), ("wrong", server.base)):
                headers = {"Origin": origin} if origin else {}
                with pytest.raises(aiohttp.WSServerHandshakeError) as err:
                    await http.ws_connect(f"{server.base}/ws?token={token}", headers=headers)
                assert err.value.status == 403
            ws, hello = await _open(http, server.base, server.token)
            assert hello["mode"] == "ar" and hello["max_fps"] == 15 and hello["site"]["name"] == "office"
            assert hello["library"] is None  # no restrictor answers: the page waits for one
            await ws.close()

    run(check())
    assert server.proc.alive()


def _bad_messages() -> list[tuple[str, object, int | tuple[int, ...]]]:
    huge_sof = bytes.fromhex("ffd8ffc0000b08ea60ea6001011100") + b"\0" * 64  # a JPEG header claiming 60000x60000
    return [
        ("not a JPEG", wire.pack_frame(1, b"hello, not an image"), wire.CLOSE_UNSUPPORTED),
        ("no frame magic", b"\x00" * 64, wire.CLOSE_UNSUPPORTED),
        ("too short", b"AR", wire.CLOSE_UNSUPPORTED),
        ("huge picture", wire.pack_frame(2, huge_sof), wire.CLOSE_TOO_BIG),
        # The server closes as soon as the announced length is too big, before reading the rest: the
        # sender, still writing, may see the close frame (1009) or only the dropped connection (1006).
        (
            "oversized message",
            wire.pack_frame(3, b"\xff\xd8" + b"\0" * (wire.MAX_FRAME_BYTES + 1024)),
            (wire.CLOSE_TOO_BIG, 1006),
        ),
        ("malformed JSON", "{not json", wire.CLOSE_BAD_DATA),
        ("JSON not an object", "[1, 2, 3]", wire.CLOSE_POLICY),
        ("unknown type", json.dumps({"type": "launch_missiles"}), wire.CLOSE_POLICY),
        (
            "feedback with a nested value",
            json.dumps({"type": "feedback", "id": 1, "kind": "forbid_room", "params": {"room": {"x": 1}}}),
            wire.CLOSE_POLICY,
        ),
        (
            "feedback without an id",
            json.dumps({"type": "feedback", "kind": "forbid_room", "params": {}}),
            wire.CLOSE_POLICY,
        ),
        ("ping flood", [json.dumps({"type": "ping", "t": k}) for k in range(400)], wire.CLOSE_POLICY),
    ]


def test_garbage_disconnects_only_its_sender(router, namespace, spawn, tmp_path):
    shots = snapshots()  # sim snapshots of the storage room's tags, and their intrinsics as the calibration
    calibration = write_calibration(tmp_path / "intrinsics.json", shots)
    server = start_tablet(spawn, router, namespace, tmp_path / "state", "--no-qr", "--intrinsics", str(calibration))
    frame = encode_jpeg(shots.frames[0])

    async def check() -> None:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            good, _ = await _open(http, server.base, server.token)
            await good.send_bytes(wire.pack_frame(1, frame))
            first = await _next(good, "overlay")
            assert first["seq"] == 1 and first["ok"] and len(first["tags"]) >= 4
            for what, payload, code in _bad_messages():
                bad, _ = await _open(http, server.base, server.token)
                for item in payload if isinstance(payload, list) else [payload]:
                    try:
                        await (bad.send_str(item) if isinstance(item, str) else bad.send_bytes(item))
                    except (ConnectionError, RuntimeError):
                        break  # already closed by the server
                assert await _closed_with(bad) in (code if isinstance(code, tuple) else (code,)), what
                # The good client is still served, between every two attacks.
                await good.send_bytes(wire.pack_frame(100 + len(what), frame))
                answer = await _next(good, "overlay")
                assert answer["seq"] == 100 + len(what) and answer["ok"], what
            await good.close()

    run(check())
    assert server.proc.alive()
    assert "disconnecting it" in server.proc.output


def test_a_refusal_and_its_reason_reach_the_client(router, namespace, spawn, tmp_path):
    server = start_tablet(spawn, router, namespace, tmp_path / "state", "--no-qr")

    async def check() -> None:
        async with aiohttp.ClientSession(connector=insecure()) as http:
            ws, hello = await _open(http, server.base, server.token, mode="viewer")
            inbox = _Inbox(ws)
            # No restrictor yet: no buttons. Once one is up, its library reaches the open page.
            assert hello["library"] is None
            restrictor = spawn(
                restrictor_argv(namespace, router, tmp_path / "restrictor"),
                name="restrictor",
            )
            restrictor.wait_for("up on namespace", timeout=30)
            library = (await inbox.next("library"))["entries"]
            assert {e["id"] for e in library} >= {"door_unavailable", "forbid_room", "door_available_now", "cancel"}
            await ws.send_str(
                json.dumps(
                    {"type": "feedback", "id": 7, "kind": "forbid_room", "params": {"room": "ballroom", "minutes": 5}}
                )
            )
            ack = await inbox.next("ack")
            assert ack["id"] == 7 and ack["status"] == "refused" and "ballroom" in ack["reason"]
            await ws.send_str(
                json.dumps(
                    {"type": "feedback", "id": 8, "kind": "forbid_room", "params": {"room": "lab", "minutes": 5}}
                )
            )
            ack = await inbox.next("ack")
            assert ack["id"] == 8 and ack["status"] == "accepted" and ack["constraint_id"]
            update = await inbox.next("constraints")
            while not update["items"]:  # the restrictor's start-up publication (its empty set) may come first
                update = await inbox.next("constraints")
            assert [c["id"] for c in update["items"]] == [ack["constraint_id"]]
            # A viewer sends no frames: that is a protocol violation too.
            await ws.send_bytes(wire.pack_frame(1, encode_jpeg(snapshots().frames[0])))
            assert await _closed_with(ws) == wire.CLOSE_POLICY

    run(check())
    assert "no restrictor answers on" in server.proc.output and "answered: 4 library entries" in server.proc.output


def _served_certificate(port: int) -> bytes:
    return ssl.PEM_cert_to_DER_cert(ssl.get_server_certificate(("127.0.0.1", port)))


def test_certificate_reused_token_fresh_clean_exit(router, namespace, spawn, tmp_path):
    state = tmp_path / "state"
    first = start_tablet(spawn, router, namespace, state)
    first.proc.wait_for("▀▀▀▀▀▀▀▀", timeout=10)  # the QR code of the URL, after it
    port = int(first.base.rsplit(":", 1)[1])
    pem = (state / "tablet.pem").read_bytes()
    assert _served_certificate(port) == ssl.PEM_cert_to_DER_cert(pem.decode())
    assert oct((state / "tablet.key").stat().st_mode & 0o777) == "0o600"
    first.proc.signal(signal.SIGTERM)
    assert first.proc.wait(10) == 0
    assert "tablet" in first.proc.output and "stopped" in first.proc.output

    second = start_tablet(spawn, router, namespace, state, "--no-qr")
    assert (state / "tablet.pem").read_bytes() == pem  # made once, reused
    assert second.token != first.token  # a new key every run
    second.proc.signal(signal.SIGINT)
    assert second.proc.wait(10) == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--intrinsics", "/nonexistent/intrinsics.json"], "nonexistent"),
        (["--camera-source", "webcam"], "--camera-source"),
        (["--camera-source", "sim:bad/id"], "cannot be used in a key"),
        (["--fov", "300"], "--fov"),
    ],
)
def test_bad_configuration_exits_2(args, message, tmp_path):
    result = subprocess.run(
        arroch("tablet", "--state-dir", str(tmp_path), *args), cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2 and message in result.stderr, result.stderr


def test_help_documents_the_commands():
    out = subprocess.run(arroch("tablet", "--help"), cwd=ROOT, capture_output=True, text=True, timeout=60).stdout
    assert "--camera-source" in out and "--intrinsics" in out and "--site" in out
    out = subprocess.run(
        arroch("ar", "calibrate", "--help"), cwd=ROOT, capture_output=True, text=True, timeout=60
    ).stdout
    assert "chessboard:COLSxROWS:SQUARE" in out
