"""The feedback panel: the constraint library's entries as on-screen buttons, and sending a press.

The panel shows one button per usable entry of the constraint library the running restrictor serves
(``constraints/library``, :mod:`protocol.constraint_library`; until one answers, a line saying the
panel waits for it) with a chip per parameter under it (``Door: d_storage >``). Tapping a chip cycles the parameter
through its choices (the site's doors/rooms, a few durations between the entry's min and max, the
live constraint ids for "cancel"); tapping the entry's button sends a ``Feedback`` with the shown
values. The answer — accepted, refused with the restrictor's reason, or no answer — stays on the
panel's status line.

Sending goes through the restrictor's client contract (``runtime.feedback_client.send_feedback``):
the Feedback is stamped once and its bytes sent as a query on ``feedback`` (the reply is the
``FeedbackAck``), re-sent with the same ``src``/``seq`` until an ack arrives either as the reply or on
``feedback/ack/<src>``; the restrictor applies a repeated ``(src, seq)`` once. That call blocks, so a
press runs it on its own thread and the frame loop never waits.

The panel is drawn as Overlay primitives of layer ``ui`` (button backgrounds as translucent
polygons, labels as text), laid out for the frame size; :meth:`FeedbackPanel.press_at` hit-tests
a tap in the same pixel coordinates.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from protocol.messages import ConstraintSet, FeedbackAck, LibraryEntry, LibraryParam, Primitive
from runtime.feedback_client import send_feedback

from .draw import text_width

log = logging.getLogger("arroch.ar.feedback")

#: Durations offered for "int" parameters (minutes), clipped to the entry's [min, max].
INT_PRESETS = (5, 10, 15, 30, 60, 120, 240)
DEFAULT_INT = 15
RESULT_SHOWN_FOR = 8.0  # seconds an answer stays on the status line

# One opacity for every background, so the panel blends in one pass.
BG = [20, 20, 28, 190]
BG_PENDING = [70, 70, 20, 190]
BG_DISABLED = [45, 45, 45, 190]
FG = [240, 240, 240, 255]
FG_DIM = [150, 150, 150, 255]
OK = [90, 230, 90, 255]
BAD = [255, 90, 70, 255]

Sender = Callable[[str, dict[str, Any]], FeedbackAck | None]


@dataclass(frozen=True)
class Button:
    """A tappable rectangle (x0, y0, x1, y1) and what a tap does: ``("send", entry)`` or ``("cycle", entry, param)``."""

    rect: tuple[float, float, float, float]
    action: tuple[str, ...]

    def contains(self, u: float, v: float) -> bool:
        x0, y0, x1, y1 = self.rect
        return x0 <= u <= x1 and y0 <= v <= y1


@dataclass
class Result:
    entry: str
    params: dict[str, Any]
    status: str  # "pending" | "accepted" | "refused" | "no answer" | "error"
    reason: str = ""
    constraint_id: str = ""
    at: float = 0.0  # time.monotonic() of the last change


WAITING = "Feedback: waiting for the restrictor's library"


def restrictor_sender(service, timeout: float = 5.0) -> Sender:  # noqa: ANN001 (an open runtime.service.Service)
    """A sender that talks to the restrictor through ``service``'s Zenoh session."""

    def send(kind: str, params: dict[str, Any]) -> FeedbackAck | None:
        return send_feedback(service, kind, params, timeout=timeout)

    return send


class FeedbackPanel:
    """Library entries as buttons; presses become Feedback sent by ``sender`` on a worker thread.

    ``entries`` None: the library is not known yet (no restrictor has answered); the panel says so
    until :meth:`set_entries` gives it."""

    def __init__(self, entries: list[LibraryEntry] | None = None, sender: Sender | None = None) -> None:
        self.sender = sender
        self._lock = threading.Lock()
        self._constraint_ids: list[str] = []
        self.entries: list[LibraryEntry] = []
        self._values: dict[str, dict[str, Any]] = {}
        self.waiting = entries is None
        if entries is not None:
            self.set_entries(entries)
        self.result: Result | None = None
        self._thread: threading.Thread | None = None
        self._buttons: list[Button] = []

    def set_entries(self, entries: list[LibraryEntry]) -> None:
        """Show ``entries`` (the library as the restrictor serves it); values start at their defaults."""
        usable = [e for e in entries if e.usable]
        with self._lock:
            self.entries = usable
            self._values = {e.id: {p.name: self._default(p) for p in e.params} for e in usable}
            self.waiting = False

    # ------------------------------------------------------------------ parameters

    def _choices(self, param: LibraryParam) -> list[Any]:
        if param.type == "int":
            lo, hi = int(param.min or 1), int(param.max or 240)
            return sorted({min(max(v, lo), hi) for v in INT_PRESETS})
        if param.type == "constraint":
            return list(self._constraint_ids)
        return list(param.choices or [])

    def _default(self, param: LibraryParam) -> Any:
        choices = self._choices(param)
        if not choices:
            return None
        if param.type == "int":
            return min(choices, key=lambda v: abs(v - DEFAULT_INT))
        return choices[0]

    def values(self, entry_id: str) -> dict[str, Any]:
        with self._lock:
            return dict(self._values[entry_id])

    def set_value(self, entry_id: str, name: str, value: Any) -> None:
        with self._lock:
            self._values[entry_id][name] = value

    def cycle(self, entry_id: str, name: str) -> Any:
        """Advance a parameter to its next choice; returns the new value."""
        entry = self._entry(entry_id)
        param = next(p for p in entry.params if p.name == name)
        choices = self._choices(param)
        with self._lock:
            current = self._values[entry_id].get(name)
            nxt = (
                choices[(choices.index(current) + 1) % len(choices)]
                if current in choices
                else (choices[0] if choices else None)
            )
            self._values[entry_id][name] = nxt
            return nxt

    def on_constraints(self, msg: ConstraintSet, key: str = "") -> None:
        """Live constraint ids become the choices of "constraint" parameters (the cancel entry)."""
        ids = [c.id for c in msg.constraints]
        with self._lock:
            self._constraint_ids = ids
            for e in self.entries:
                for p in e.params:
                    if p.type == "constraint" and self._values[e.id].get(p.name) not in ids:
                        self._values[e.id][p.name] = ids[0] if ids else None

    def _entry(self, entry_id: str) -> LibraryEntry:
        for e in self.entries:
            if e.id == entry_id:
                return e
        raise KeyError(f"no usable library entry {entry_id!r}")

    def ready(self, entry_id: str) -> bool:
        """Every parameter of the entry has a value (e.g. "cancel" needs a live constraint)."""
        return all(v is not None for v in self.values(entry_id).values())

    # ------------------------------------------------------------------ pressing

    def press(self, entry_id: str, params: dict[str, Any] | None = None) -> bool:
        """Send the entry with its shown values (or ``params``); False when busy, not ready or no sender."""
        self._entry(entry_id)
        values = self.values(entry_id) if params is None else dict(params)
        if self.sender is None or any(v is None for v in values.values()):
            return False
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                return False  # one request at a time: the human sees each answer
            self.result = Result(entry_id, values, "pending", at=time.monotonic())
            self._thread = threading.Thread(
                target=self._send, args=(entry_id, values), name="feedback-send", daemon=True
            )
            self._thread.start()
        return True

    def _send(self, entry_id: str, values: dict[str, Any]) -> None:
        assert self.sender is not None
        try:
            ack = self.sender(entry_id, values)
        except Exception as exc:  # a closed session while sending, etc.: report it, never crash the client
            log.warning("sending feedback %s failed: %s", entry_id, exc)
            result = Result(entry_id, values, "error", reason=str(exc), at=time.monotonic())
        else:
            if ack is None:
                result = Result(entry_id, values, "no answer", reason="no restrictor answered", at=time.monotonic())
            else:
                status = "accepted" if ack.accepted else "refused"
                result = Result(
                    entry_id, values, status, reason=ack.reason, constraint_id=ack.constraint_id, at=time.monotonic()
                )
        log.info("feedback %s %s: %s %s", entry_id, values, result.status, result.reason)
        with self._lock:
            self.result = result

    def wait(self, timeout: float) -> Result | None:
        """Block until the current press is answered (for tools and tests)."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
        return self.result

    def press_at(self, u: float, v: float) -> tuple[str, ...] | None:
        """Apply a tap at pixel (u, v) of the last laid-out frame; returns the action taken, if any."""
        for button in self._buttons:
            if button.contains(u, v):
                if button.action[0] == "send":
                    self.press(button.action[1])
                else:
                    self.cycle(button.action[1], button.action[2])
                return button.action
        return None

    # ------------------------------------------------------------------ drawing

    def primitives(self, width: int, height: int) -> list[Primitive]:
        """The panel laid out for a ``width`` × ``height`` frame (right-hand side), layer ``ui``."""
        row = max(24.0, height / 20.0)
        text_px = row * 0.5
        pad = row * 0.2
        panel_w = min(0.42 * width, 30.0 * text_px)
        x0 = width - panel_w - pad
        y = pad
        prims: list[Primitive] = []
        buttons: list[Button] = []
        pending = self.result is not None and self.result.status == "pending"
        if self.waiting:
            rect = (x0, y, x0 + panel_w, y + row)
            prims += _box(rect, BG_DISABLED)
            prims.append(_label(rect, _fit(WAITING, panel_w - 2 * pad, text_px * 0.9), text_px * 0.9, FG_DIM))
        for e in self.entries:
            if y + 2 * row > height - 2 * row:
                break  # no room for more entries on a small frame
            ready = self.ready(e.id)
            bg = BG_PENDING if pending and self.result and self.result.entry == e.id else (BG if ready else BG_DISABLED)
            rect = (x0, y, x0 + panel_w, y + row)
            prims += _box(rect, bg)
            prims.append(_label(rect, _fit(e.label, panel_w - 2 * pad, text_px), text_px, FG if ready else FG_DIM))
            buttons.append(Button(rect, ("send", e.id)))
            y += row + pad * 0.5
            chips = e.params
            if chips:
                chip_w = (panel_w - pad * (len(chips) - 1)) / len(chips)
                values = self.values(e.id)
                for k, p in enumerate(chips):
                    cx0 = x0 + k * (chip_w + pad)
                    crect = (cx0, y, cx0 + chip_w, y + row * 0.85)
                    value = values.get(p.name)
                    text = f"{p.label}: {'-' if value is None else value} >"
                    prims += _box(crect, BG)
                    prims.append(_label(crect, _fit(text, chip_w - 2 * pad, text_px * 0.9), text_px * 0.9, FG))
                    buttons.append(Button(crect, ("cycle", e.id, p.name)))
                y += row * 0.85
            y += pad * 1.5
        if self.result is not None and (
            self.result.status == "pending" or time.monotonic() - self.result.at < RESULT_SHOWN_FOR
        ):
            r = self.result
            colour = OK if r.status == "accepted" else (FG if r.status == "pending" else BAD)
            text = f"{r.entry}: {r.status}" + (f" - {r.reason}" if r.reason else "")
            rect = (x0, y, x0 + panel_w, y + row)
            prims += _box(rect, BG)
            prims.append(_label(rect, _fit(text, panel_w - 2 * pad, text_px * 0.9), text_px * 0.9, colour))
        self._buttons = buttons
        return prims


def _box(rect: tuple[float, float, float, float], colour: list[int]) -> list[Primitive]:
    x0, y0, x1, y1 = rect
    return [Primitive(kind="polygon", points=[[x0, y0], [x1, y0], [x1, y1], [x0, y1]], color=list(colour), layer="ui")]


def _label(rect: tuple[float, float, float, float], text: str, size: float, colour: list[int]) -> Primitive:
    x0, y0, _x1, y1 = rect
    baseline = (y0 + y1) / 2.0 + size * 0.35
    return Primitive(
        kind="text", points=[[x0 + size * 0.4, baseline]], text=text, color=list(colour), radius=size, layer="ui"
    )


def _fit(text: str, max_px: float, size: float) -> str:
    """``text`` shortened with "..." to fit ``max_px`` at ``size`` (the drawing font is ASCII-only)."""
    return _fit_cached(text, round(max_px, 1), round(size, 1))


@lru_cache(maxsize=512)
def _fit_cached(text: str, max_px: float, size: float) -> str:
    text = text.encode("ascii", "replace").decode("ascii")
    if text_width(text, size) <= max_px:
        return text
    while len(text) > 1 and text_width(text + "...", size) > max_px:
        text = text[:-1]
    return text + "..."
