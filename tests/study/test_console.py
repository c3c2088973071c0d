"""The experimenter's console: who may open it, what it serves, and that its buttons reach the world
(over real Zenoh, through a running ``study run`` and its stand-in world)."""

from __future__ import annotations

import asyncio
import concurrent.futures
import json
import re
import sys
import time
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from services.study.console import STATIC, Console
from services.study.layout import StudyFolder, read_json, read_jsonl, write_json
from services.study.trial import CommandRefused
from tests.study.test_run import FAKE_UP, make_study


class Recorder:
    """Stands in for the trial: answers commands at once, remembering them."""

    def __init__(self) -> None:
        self.commands: list[tuple[str, dict[str, Any]]] = []

    def submit(self, kind: str, **args: Any) -> concurrent.futures.Future:
        self.commands.append((kind, args))
        future: concurrent.futures.Future = concurrent.futures.Future()
        if kind == "abort" and not args.get("reason"):
            future.set_exception(CommandRefused("reason: say why"))
        else:
            future.set_result({"done": kind})
        return future


@pytest.fixture
def console() -> Iterator[tuple[Console, Recorder]]:
    recorder = Recorder()
    server = Console(lambda: {"participant": "P01", "trial": "P01-T1-arroch"}, recorder.submit)
    server.start()
    yield server, recorder
    server.stop()


def fetch(calls: list[tuple[str, str, dict[str, Any]]], *, jar: bool = True) -> list[tuple[int, dict, str, dict]]:
    """Run HTTP calls (method, url, options) in order with one client (its cookies kept): status,
    headers, text and the cookies it then holds."""

    async def go() -> list[tuple[int, dict, str, dict]]:
        out = []
        cookies = aiohttp.CookieJar(unsafe=True) if jar else aiohttp.DummyCookieJar()  # unsafe: an IP host
        async with aiohttp.ClientSession(cookie_jar=cookies) as session:
            for method, url, options in calls:
                async with session.request(method, url, **options) as response:
                    text = await response.text()
                    held = {c.key: c for c in session.cookie_jar}
                    out.append((response.status, dict(response.headers), text, held))
        return out

    return asyncio.run(go())


def test_the_page_needs_the_token_and_sets_it_as_a_strict_cookie(console: tuple[Console, Recorder]) -> None:
    server, _ = console
    base = f"http://127.0.0.1:{server.port}"
    results = fetch(
        [
            ("GET", base + "/", {}),
            ("GET", base + "/?token=wrong", {}),
            ("GET", base + "/static/console.js", {}),
            ("GET", base + f"/?token={server.token}", {}),
            ("GET", base + "/static/console.js", {}),  # the cookie now
            ("GET", base + "/static/console.css", {}),
            ("GET", base + "/static/console.html", {}),
            ("GET", base + "/static/../run.py", {}),
            ("GET", base + "/api/state", {}),
        ]
    )
    statuses = [r[0] for r in results]
    assert statuses == [403, 403, 403, 200, 200, 200, 404, 404, 200]
    page_status, headers, html, cookies = results[3]
    assert "<title>ARROCH study console</title>" in html
    csp = headers["Content-Security-Policy"]
    assert "default-src 'none'" in csp and "script-src 'self';" in csp and "unsafe-inline" not in csp
    assert results[0][1]["Content-Security-Policy"] == csp  # refusals carry it too
    cookie = cookies[f"arroch_console_{server.port}"]
    assert cookie.value == server.token and cookie["httponly"] and cookie["samesite"] == "Strict"
    assert results[4][1]["Content-Type"].startswith("text/javascript")
    assert results[-1][2] == '{"participant": "P01", "trial": "P01-T1-arroch"}'
    assert server.refused == 3


def test_commands_need_the_token_json_and_the_consoles_own_origin(console: tuple[Console, Recorder]) -> None:
    server, recorder = console
    base = f"http://127.0.0.1:{server.port}/api"
    token = {"X-Console-Token": server.token}
    results = fetch(
        [
            ("POST", base + "/mark", {"json": {"note": "no token"}}),
            ("POST", base + "/mark", {"data": "note=x", "headers": {**token, "Content-Type": "text/plain"}}),
            ("POST", base + "/mark", {"json": {"note": "x"}, "headers": {**token, "Origin": "http://evil.example"}}),
            ("POST", base + "/mark", {"data": "{nope", "headers": {**token, "Content-Type": "application/json"}}),
            ("POST", base + "/mark", {"json": ["a list"], "headers": token}),
            ("POST", base + "/explode", {"json": {}, "headers": token}),
            ("POST", base + "/mark", {"json": {"note": "she laughs", "extra": 1}, "headers": token}),
            ("POST", base + "/abort", {"json": {"reason": ""}, "headers": token}),
            ("POST", base + "/door", {"json": {"door": "d1", "open": True}, "headers": token}),
        ],
        jar=False,
    )
    assert [r[0] for r in results] == [403, 415, 403, 400, 400, 404, 200, 409, 200]
    assert results[6][2] == '{"ok": true, "done": "mark"}'
    assert '"error": "reason: say why"' in results[7][2]
    assert recorder.commands == [
        ("mark", {"note": "she laughs"}),
        ("abort", {"reason": ""}),
        ("door", {"door": "d1", "open": True}),
    ]


def test_the_console_page_has_no_inline_script_or_style() -> None:
    class Scan(HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.problems: list[str] = []
            self.scripts: list[str] = []
            self._in_script = False

        def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
            named = dict(attrs)
            self.problems += [f"{tag} {k}" for k in named if k.startswith("on") or k == "style"]
            if tag == "style":
                self.problems.append("style element")
            if tag == "script":
                self._in_script = True
                self.scripts.append(named.get("src") or "")

        def handle_endtag(self, tag: str) -> None:
            self._in_script = self._in_script and tag != "script"

        def handle_data(self, data: str) -> None:
            if self._in_script and data.strip():
                self.problems.append("inline script")

    scan = Scan()
    scan.feed((STATIC / "console.html").read_text())
    assert scan.problems == [] and scan.scripts == ["/static/console.js"]
    script = (STATIC / "console.js").read_text()
    assert "innerHTML" not in script and "eval(" not in script  # shown as text only


def test_the_console_is_shipped_with_the_package() -> None:
    pyproject = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    assert '"services.study" = ["static/*"]' in pyproject
    assert {p.name for p in STATIC.iterdir()} >= {"console.html", "console.js", "console.css"}


def test_a_taken_port_is_said_not_crashed_on(console: tuple[Console, Recorder]) -> None:
    server, recorder = console
    other = Console(lambda: {}, recorder.submit, port=server.port)
    with pytest.raises(OSError, match=f"cannot listen on 127.0.0.1:{server.port}"):
        other.start()


# ---------------------------------------------------------------------------- through a running trial


@pytest.mark.integration
def test_the_consoles_buttons_reach_the_world_and_abort_ends_the_trial(tmp_path: Path, spawn) -> None:  # noqa: ANN001
    folder: StudyFolder = make_study(tmp_path)
    write_json(folder.consent_file("P01"), {"participant": "P01", "consented": True, "wall": 1.0, "form_sha256": "x"})
    argv = [sys.executable, "-m", "services.study.run", str(tmp_path), "--participant", "P01", "--up-command", FAKE_UP]
    runner = spawn(argv + ["--stop-timeout", "5"], env={"FAKE_UP_SCENARIO": "hang"})
    url = re.search(r"console: (http://\S+)", runner.wait_for("console: http://", timeout=30)).group(1)
    runner.wait_for("tablet page", timeout=30)
    base = url.split("/?", 1)[0]
    deadline = time.monotonic() + 20
    while not fetch([("GET", url, {}), ("GET", base + "/api/state", {})])[1][2].count('"place": "desk"'):
        assert time.monotonic() < deadline, runner.output  # until the world's HumanState has come
        time.sleep(0.2)
    results = fetch(
        [
            ("GET", base + "/api/state", {}),  # no token yet: refused
            ("GET", url, {}),
            ("POST", base + "/api/mark", {"json": {"note": "she looks at the robot"}}),
            ("POST", base + "/api/pause", {"json": {}}),
            ("POST", base + "/api/resume", {"json": {}}),
            ("POST", base + "/api/door", {"json": {"door": "d1", "open": True}}),  # a virtual world: hers to open
            ("GET", base + "/api/state", {}),
            ("POST", base + "/api/abort", {"json": {"reason": "the fire alarm went off"}}),
        ]
    )
    assert [r[0] for r in results] == [403, 200, 200, 200, 200, 409, 200, 200], [r[2] for r in results]
    state = json.loads(results[6][2])
    assert (state["participant"], state["trial"], state["condition"], state["marks"]) == (
        "P01",
        "P01-T1-arroch",
        "arroch",
        1,
    )
    assert state["human"]["place"] == "desk" and state["tablet_urls"] == ["https://127.0.0.1:9/?token=fake-token_123"]
    assert runner.wait(30) == 1, runner.output

    trial = read_json(folder.trial_dir("P01", "P01-T1-arroch") / "trial.json")
    assert (trial["status"], trial["reason"]) == ("incomplete", "aborted by the experimenter: the fire alarm went off")
    run = folder.latest_run("P01", "P01-T1-arroch")
    heard = list(read_jsonl(run / "heard.jsonl"))
    marks = [h for h in heard if h.get("act") == "mark"]
    assert len(marks) == 1 and marks[0]["note"] == "she looks at the robot" and marks[0]["src"].startswith("study-")
    controls = [(h["control"], h["reason"]) for h in heard if h["type"] == "StudyControl"]
    controls = [c for i, c in enumerate(controls) if i == 0 or controls[i - 1] != c]  # repeated until seen
    assert controls == [
        ("pause", "paused by the experimenter"),
        ("resume", ""),
        ("abort", "aborted by the experimenter: the fire alarm went off"),
    ]
    assert not any(h.get("key", "").startswith("door/") for h in heard)
    lines = list(read_jsonl(folder.log_file("P01", "P01-T1-arroch")))
    assert [line["note"] for line in lines if line.get("act") == "mark"] == ["she looks at the robot"]
    done = [line for line in lines if line.get("kind") == "mission_done"]
    assert done and done[0]["data"]["reason"] == "aborted by the experimenter: the fire alarm went off"


# ---------------------------------------------------------------------------- in a real browser


@pytest.mark.integration
def test_the_console_renders_the_trial_and_its_buttons_send_commands_in_chromium() -> None:
    from protocol.messages import HumanState, ParticipantAction, RobotStatus
    from services.study.progress import TrialProgress
    from tests.tablet.browser import Browser, chromium_path

    if chromium_path() is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium)")
    progress = TrialProgress(
        participant="P01",
        trial="P01-T1-arroch",
        condition="arroch",
        attempt=2,
        world="real",
        questionnaires=["arroch-q"],
    )
    progress.set(phase="running", consent="given")
    progress.on_status(RobotStatus(robot="r0", state="waiting_at_door", delivered=["o1", "o2"], waiting_door="d1"))
    progress.on_human(HumanState(mode="participant", place="at_door", door="d1", doors=["d1"]))
    progress.on_action(ParticipantAction(participant="P01", act="puzzle_move", placed=7, total=16), from_page=True)
    sneaky = '<img src=x onerror="document.title=1">'  # what a page sends is shown as text, never as markup
    progress.on_action(ParticipantAction(participant="P01", act="feedback", door="d1", note=sneaky), from_page=True)
    recorder = Recorder()
    server = Console(progress.snapshot, recorder.submit)
    url = server.start()
    try:
        with Browser() as browser:
            browser.navigate(url)
            browser.wait_for("document.getElementById('participant').textContent === 'P01'", timeout=20)
            assert browser.evaluate("document.getElementById('robots').textContent").startswith("r0waiting_at_door2")
            assert browser.evaluate("document.getElementById('puzzle').textContent").startswith("7/16 placed")
            assert sneaky in browser.evaluate("document.getElementById('feedback').textContent")
            assert browser.evaluate("document.querySelectorAll('img').length") == 0
            assert browser.evaluate("document.getElementById('door-controls').hidden") is False  # a real world
            assert browser.evaluate("getComputedStyle(document.getElementById('paused')).display") == "none"
            browser.evaluate("document.getElementById('mark-note').value = 'she stands up'")
            browser.click("#mark-form button")
            browser.wait_for("document.getElementById('answer').textContent === 'mark: done'", timeout=10)
            browser.click("#door-controls button")
            browser.wait_for("document.getElementById('answer').textContent === 'door: done'", timeout=10)
            browser.click("#pause")
            browser.wait_for("document.getElementById('answer').textContent === 'pause: done'", timeout=10)
    finally:
        server.stop()
    assert recorder.commands == [
        ("mark", {"note": "she stands up"}),
        ("door", {"door": "d1", "open": True}),
        ("pause", {}),
    ]
