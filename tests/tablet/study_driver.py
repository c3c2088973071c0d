"""A scripted participant on the study page (``arroch tablet --study-trial``), in headless Chromium.

:class:`StudyPageDriver` uses the page as a person does: it reads what the page shows and touches
elements at their centres (clicks, and a touch held for a while on the door's control). It
solves the puzzle by looking — each piece's pixels against the picture to make, both as the page
draws them — never by asking the page where a piece belongs. It waits for the page's answer after
each step, so a test (or a whole scripted study) can chain the steps:

    driver = StudyPageDriver(browser)
    driver.open(url)
    driver.consent()
    driver.solve_puzzle(max_moves=3)
    driver.switch("robots"); driver.switch("puzzle")
    driver.go_to_door("d_storage"); driver.wait_at_door(); driver.hold_open()
    driver.solve_puzzle()
    driver.wait_for_questionnaire()
    driver.answer_questionnaire({"arroch-q": {"Q1": 5, "Q2": 4, "Q3": 4, "Q4": 3, "Q5": 5}})

Every wait raises :class:`~tests.tablet.browser.BrowserError` with the page's last state
when it times out.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from playwright.sync_api import Page

from tests.tablet.browser import Browser, BrowserError

#: Seconds a person waits for the puzzle to be unlocked before calling it locked.
LOCK_PATIENCE = 10.0

#: Blocks a side when a piece is compared with the picture (mean colour per block).
GRID = 6

#: Reads every piece and the picture to make from the page's canvases: [rows, cols, tiles, picture],
#: tiles[s] = the GRID×GRID mean colours of the piece shown in slot s, picture[s] = those of the
#: picture's part s. Means over whole blocks of real pixels (no resampling), so a piece and its
#: part of the picture read alike whatever the canvas sizes.
_READ_PUZZLE = """(() => {
  const G = GRID;
  const means = (ctx, x0, y0, w, h) => {
    const data = ctx.getImageData(Math.round(x0), Math.round(y0), Math.round(w), Math.round(h)).data;
    const W = Math.round(w), H = Math.round(h), out = [];
    for (let by = 0; by < G; by++) for (let bx = 0; bx < G; bx++) {
      let r = 0, g = 0, b = 0, n = 0;
      for (let y = Math.floor(by * H / G); y < Math.floor((by + 1) * H / G); y++)
        for (let x = Math.floor(bx * W / G); x < Math.floor((bx + 1) * W / G); x++) {
          const i = 4 * (y * W + x); r += data[i]; g += data[i + 1]; b += data[i + 2]; n++;
        }
      out.push(r / n, g / n, b / n);
    }
    return out;
  };
  const board = document.getElementById('puzzle-board');
  const rows = Number(getComputedStyle(board).getPropertyValue('--rows'));
  const cols = Number(getComputedStyle(board).getPropertyValue('--cols'));
  const ref = document.getElementById('puzzle-ref');
  if (!ref.width || !rows || !cols) return null;
  const rctx = ref.getContext('2d', { willReadFrequently: true });
  const pw = ref.width / cols, ph = ref.height / rows;
  const picture = [];
  for (let s = 0; s < rows * cols; s++) picture.push(means(rctx, (s % cols) * pw, Math.floor(s / cols) * ph, pw, ph));
  const tiles = Array.from(board.querySelectorAll('.tile canvas')).map((c) =>
    c.width ? means(c.getContext('2d', { willReadFrequently: true }), 0, 0, c.width, c.height) : null);
  return [rows, cols, tiles, picture];
})()""".replace("GRID", str(GRID))


class StudyPageDriver:
    """Drives one study page in ``browser`` (a :class:`Browser` already started)."""

    def __init__(self, browser: Browser, *, timeout: float = 20.0) -> None:
        self.browser = browser
        self.timeout = timeout

    # ------------------------------------------------------------------ reading the page

    def state(self) -> dict[str, Any]:
        """The page's own account of the study (``window.arroch.study()``)."""
        return self.browser.evaluate("window.arroch && window.arroch.study && window.arroch.study()") or {}

    def wait(self, expression: str, timeout: float | None = None) -> Any:
        """Poll a JavaScript expression (``s`` is the page's study state) until it is truthy."""
        js = (
            "(() => { const s = window.arroch && window.arroch.study && window.arroch.study();"
            f" return s && ({expression}); }})()"
        )
        return self.browser.wait_for(js, timeout=timeout or self.timeout)

    def text(self, selector: str) -> str:
        return self.browser.evaluate(
            f"(() => {{ const n = document.querySelector({json.dumps(selector)});"
            " return n ? n.textContent : null; })()"
        )

    def visible(self, selector: str) -> bool:
        """The element is laid out on screen (not display:none, not hidden, has a size)."""
        return bool(
            self.browser.evaluate(
                f"(() => {{ const n = document.querySelector({json.dumps(selector)}); if (!n) return false;"
                " const r = n.getBoundingClientRect(); return r.width > 0 && r.height > 0"
                " && getComputedStyle(n).visibility !== 'hidden'; })()"
            )
        )

    # ------------------------------------------------------------------ touching it

    def tap(self, selector: str) -> None:
        """Bring the element into view and touch its centre (a click)."""
        # A click (press and release), not a touch tap: the page's buttons act on "click", which
        # Chromium makes of a touch only when it ends within its long-press time, and on a loaded
        # machine the two dispatches of a tap can be further apart than that (a long press: no click).
        self.browser.click(selector)

    def press(self, selector: str, seconds: float) -> None:
        """Touch the element's centre, keep the finger there ``seconds``, lift it."""
        self.browser.hold_touch(selector, seconds)

    # ------------------------------------------------------------------ the steps of a trial

    def open(self, url: str) -> dict[str, Any]:
        self.browser.navigate(url)
        return self.wait("s.screen !== undefined && s")

    def consent(self, agree: bool = True) -> bool:
        """Answer the consent screen ("I agree" or "I do not agree"); False when the page asks none
        (the trial requires no consent on the page, or it was answered before a reload)."""
        state = self.wait("s.screen !== undefined && s")
        if state["screen"] != "consent":
            return False
        self.tap("#consent-agree" if agree else "#consent-refuse")
        self.wait("s.consent === 'given'" if agree else "s.screen === 'declined'")
        return True

    def switch(self, view: str) -> bool:
        """Tap the tab of ``view``: ``puzzle``, or ``robots`` (also accepted: ``ar``, ``map``). False
        when the trial ended first (the questionnaire replaces the tabs), as it may at any moment."""
        tab = "puzzle" if view == "puzzle" else "robots"
        # A person taps again when a tap did nothing: the page's layout can move between measuring
        # the tab and the click landing (a status line redrawn as the world starts), and the click
        # then lands beside the tab.
        for attempt in range(3):
            if self.state().get("screen") == "questionnaire":
                return False
            try:
                self.tap(f"#tab-{tab}")  # (gone from the page if the trial has just ended)
                self.wait(f"s.tab === '{tab}' || s.screen === 'questionnaire'", timeout=10 if attempt < 2 else None)
                return self.state().get("tab") == tab
            except BrowserError:
                if attempt == 2:
                    raise
        return False

    def read_puzzle(self) -> list[int]:
        """For each slot, the slot its piece belongs in, as a person sees it: the piece's picture
        matched with the closest part of the picture to make."""
        data = self.browser.wait_for(
            f"(() => {{ const r = {_READ_PUZZLE}; return r && r[2].every((t) => t) && r; }})()", timeout=self.timeout
        )
        _rows, _cols, tiles, picture = data
        tiles_arr, picture_arr = np.array(tiles, dtype=float), np.array(picture, dtype=float)
        distances = np.linalg.norm(tiles_arr[:, None, :] - picture_arr[None, :, :], axis=2)
        return [int(k) for k in distances.argmin(axis=1)]

    def swap(self, a: int, b: int) -> dict[str, Any]:
        """Tap the piece in slot ``a``, then the one in slot ``b``; the puzzle state after the server answered."""
        before = self.wait("s.puzzle && !s.puzzle.pending && s.puzzle.picture && s.puzzle")
        refusals = len(self.state()["refusals"])
        moved = f"s.puzzle.moves > {before['moves']} || s.refusals.length > {refusals}"
        # A person taps again when a tap did nothing: the board can move between measuring a piece and
        # the click landing (the view just switched), and a second tap on the first piece unselects it.
        for attempt in range(3):
            timeout = 10 if attempt < 2 else None
            try:
                if self.state()["puzzle"].get("selected") != a:
                    self.tap(f'#puzzle-board .tile[data-slot="{a}"]')
                    self.wait(f"s.puzzle.selected === {a}", timeout=timeout)
                self.tap(f'#puzzle-board .tile[data-slot="{b}"]')
                return self.wait(f"!s.puzzle.pending && ({moved}) && s.puzzle", timeout=timeout)
            except BrowserError:
                if attempt == 2:
                    raise
        raise AssertionError("unreachable")

    def solve_puzzle(self, max_moves: int | None = None) -> int:
        """Put pieces where they belong, one swap at a time (each sends the piece home), until the
        puzzle is complete or ``max_moves`` were made; the number of moves made."""
        made = 0
        while max_moves is None or made < max_moves:
            puzzle = self.wait("s.puzzle && s.puzzle.picture && !s.puzzle.pending && s.puzzle")
            if puzzle["done"]:
                break
            if puzzle["locked"] and self.state().get("screen") == "questionnaire":
                break  # the trial has just ended
            if puzzle["locked"]:
                # a person waits a moment for a lock to be lifted: a world that took a late pause takes
                # the resume said after it a moment later (services/study/trial.py)
                try:
                    self.wait("!s.puzzle.locked || s.screen === 'questionnaire'", timeout=LOCK_PATIENCE)
                except BrowserError:
                    raise BrowserError(f"the puzzle is locked: {puzzle['locked']}") from None
                continue
            home = self.read_puzzle()
            wrong = [s for s, h in enumerate(home) if h != s]
            if not wrong:
                raise BrowserError(f"every piece looks in place but the page says {puzzle}")
            slot = wrong[0]
            source = home.index(slot)  # where the piece that belongs in `slot` lies: pick it up, put it there
            after = self.swap(source, slot)
            if after["moves"] == puzzle["moves"]:
                raise BrowserError(f"the move was refused: {self.state()['refusals'][-1:]}")
            made += 1
        return made

    def go_to_door(self, door: str) -> None:
        self.wait(f"s.doors && s.doors.buttons.includes('go-{door}')")
        self.tap(f"#go-{door}")
        self.wait("s.human && s.human.place !== 'desk'")

    def wait_at_door(self) -> None:
        self.wait("s.human && s.human.place === 'at_door' && s.doors.buttons.includes('hold-open')")

    def hold_open(self, seconds: float | None = None, *, release_early: bool = False) -> float:
        """Press and hold "Hold to open the door": long enough (what the page asks, plus a margin) or,
        with ``release_early``, ``seconds`` (default a third of what it asks) and let go. The seconds held."""
        self.wait_at_door()
        need = float(self.state()["doors"]["need_s"])
        if seconds is None:
            seconds = need / 3 if release_early else need + 0.4
        self.press("#hold-open", seconds)
        if not release_early:
            self.wait("s.doors.pending === 'open_door' || (s.human && s.human.place !== 'at_door')")
        return seconds

    def turn_back(self) -> None:
        self.wait("s.doors.buttons.includes('turn-back')")
        self.tap("#turn-back")
        self.wait("s.human && (s.human.place === 'back' || s.human.place === 'desk')")

    def hide_page(self) -> Page:
        """Another tab comes in front (she leaves the page for another app): the page is hidden.
        Returns that tab, for :meth:`show_page`."""
        other = self.browser.context.new_page()
        self.browser.wait_for("document.visibilityState === 'hidden'")
        return other

    def show_page(self, other: Page) -> None:
        """Close the tab :meth:`hide_page` opened: the page is in front again."""
        other.close()
        self.browser.wait_for("document.visibilityState === 'visible'")

    def send_feedback(self, kind: str, **params: Any) -> dict[str, Any]:
        """Choose the parameters on the card of ``kind`` in the feedback panel (a native drop-down
        cannot be touched in headless Chromium: its value is set and its change event fired), tap
        Send; the restrictor's answer as the page shows it."""
        self.browser.wait_for(
            f"document.getElementById('send-{kind}') && !document.getElementById('send-{kind}').disabled",
            timeout=self.timeout,
        )
        for name, value in params.items():
            self.browser.evaluate(
                f"(() => {{ const s = document.getElementById('param-{kind}-{name}');"
                f" s.value = {json.dumps(str(value))}; s.dispatchEvent(new Event('change')); return s.value; }})()"
            )
        acks = len(self.browser.evaluate("window.arroch.state().acks"))
        self.tap(f"#send-{kind}")
        return self.browser.wait_for(
            f"window.arroch.state().acks.length > {acks} && window.arroch.state().acks.slice(-1)[0]", timeout=15
        )

    def wait_for_questionnaire(self, timeout: float | None = None) -> None:
        self.wait("s.screen === 'questionnaire'", timeout)

    def answer_questionnaire(self, answers: dict[str, dict[str, int]], *, submit: bool = True) -> None:
        """Tap each answer (instrument → item → value) and Submit; waits for the thank-you."""
        self.wait_for_questionnaire()
        for instrument, items in answers.items():
            for item, value in items.items():
                selector = f'label.opt[data-item="{instrument}:{item}"][data-value="{value}"]'
                self.tap(selector)
                self.wait(f"s.questionnaire.answers[{json.dumps(instrument)}][{json.dumps(item)}] === {int(value)}")
        if submit:
            self.tap("#q-submit")
            self.wait("s.screen === 'thanks'")
