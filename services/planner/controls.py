"""clingo Controls made ahead and freed behind, on a helper thread: a program's fixed costs off the
planner's path.

Every clingo program is a fresh Control (:mod:`.solver`). Making one and adding the encoding (about
1 ms) and freeing it after its solves (0.2-3 ms, more for larger programs) do not depend on the
program's facts, so a helper thread does both while the planner writes facts, grounds, solves or
decodes: :meth:`ControlShop.take` hands out a Control made ahead for the same options and encoding
parts (or makes one in place when none is ready) and orders the next one; :meth:`ControlShop.give_back`
leaves a used one to be freed there. A Control made ahead is the one that would be made in place -
the same options, then the same statements in the same order - so programs and what they give are
unchanged. clingo releases the GIL in these calls, so the helper runs on the other core.

Each thread adds statements parsed in that thread (clingo's AST nodes count their references without
atomics, so none is shared between threads).
"""

from __future__ import annotations

import atexit
import os
import queue
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import clingo
import clingo.ast as ast

Key = tuple[tuple[str, ...], tuple[str, ...]]  # (options, encoding parts)
Statements = Callable[[str], Sequence[ast.AST]]  # encoding part -> its statements, parsed in the calling thread
KEPT_KEYS = 4  # kinds of Control kept ready (a planner uses one or two at a time)
ONLY_HERE = 3  # sys.getrefcount of a list item that nothing else refers to, inside a comprehension
FREE_POLL = 0.005  # s between looks at Controls given back while their callers still hold them
CLOSE_WAIT = 10.0  # s the process waits at exit for the helper to finish the Control it is making


def make(key: Key, statements: Statements) -> clingo.Control:
    """A Control with the options and encoding parts of ``key``, made here."""
    args, parts = key
    ctl = clingo.Control(list(args))
    with ast.ProgramBuilder(ctl) as builder:
        for part in parts:
            for statement in statements(part):
                builder.add(statement)
    return ctl


class ControlShop:
    """Controls made ahead (one spare per kind) and freed behind, on one daemon thread."""

    def __init__(self, statements: Statements) -> None:
        self._statements = statements
        self._lock = threading.Lock()
        self._ready: dict[Key, clingo.Control] = {}  # insertion order: the oldest kind first
        self._orders: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self.made_ahead = 0  # Controls handed out ready (for tests and figures)
        self.made_in_place = 0
        self._closed = False  # at exit: no more Controls made
        self._making = False  # the helper is making a Control (its parsing calls back into Python)

    def take(self, args: Sequence[str], parts: Sequence[str]) -> clingo.Control:
        key: Key = (tuple(args), tuple(parts))
        with self._lock:
            ctl = self._ready.pop(key, None)
        if ctl is None:
            self.made_in_place += 1
            ctl = make(key, self._statements)
        else:
            self.made_ahead += 1
        self._send(key)
        return ctl

    def give_back(self, ctl: clingo.Control) -> None:
        """``ctl`` is done with: freed on the helper thread (the caller keeps no reference)."""
        self._send(ctl)

    def _send(self, item: Any) -> None:
        if self._thread is None or not self._thread.is_alive():
            self._thread = threading.Thread(target=self._run, name="clingo-controls", daemon=True)
            self._thread.start()
        self._orders.put(item)

    def close(self) -> None:
        """Take no more orders, and wait while the helper is making a Control (run at exit).

        A daemon thread inside one of clingo's callbacks into Python (parsing an encoding part) when
        the interpreter finalizes is ended by a forced unwind that clingo's C++ catches: the process
        aborts ("FATAL: exception not rethrown", exit -6) after its work is done. Elsewhere (waiting
        for orders, freeing a Control) it is ended harmlessly, so only that window is waited for."""
        with self._lock:
            self._closed = True
        deadline = time.monotonic() + CLOSE_WAIT
        while self._making and time.monotonic() < deadline:
            time.sleep(FREE_POLL)

    def _run(self) -> None:
        used: list[clingo.Control] = []  # given back, freed once nobody else holds them
        while True:
            try:
                item = self._orders.get(timeout=FREE_POLL if used else None)
            except queue.Empty:
                item = None
            # Free only a Control the caller no longer holds (only the list, the loop variable and the
            # argument refer to it): the last reference dropped is where clingo frees it, here.
            used = [c for c in used if sys.getrefcount(c) > ONLY_HERE]
            if item is None:
                continue
            if isinstance(item, clingo.Control):
                used.append(item)
                del item
                continue
            with self._lock:
                if self._closed:
                    return
                if item in self._ready:
                    continue
                self._making = True
            try:
                ctl = make(item, self._statements)
            finally:
                self._making = False
            with self._lock:
                self._ready[item] = ctl
                stale = list(self._ready)[:-KEPT_KEYS]
                dropped = [self._ready.pop(k) for k in stale]
            del ctl, dropped  # kinds no longer asked for are freed here too

    def _after_fork(self) -> None:
        """A forked child has no helper thread: start afresh (Controls made before are the parent's)."""
        self._lock = threading.Lock()
        self._ready = {}
        self._orders = queue.SimpleQueue()
        self._thread = None
        self._closed = self._making = False


def shop(statements: Statements) -> ControlShop:
    """The process's shop (reset in a forked child)."""
    made = ControlShop(statements)
    atexit.register(made.close)
    if hasattr(os, "register_at_fork"):
        os.register_at_fork(after_in_child=made._after_fork)
    return made
