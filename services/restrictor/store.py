"""Persistence of the restrictor's state in SQLite, so a restart restores exactly the active set.

Stored in ``<state dir>/restrictor.sqlite3`` (one directory per namespace; see
:func:`default_state_dir`):

- ``meta``: schema version, site name, the ConstraintSet ``version``, the next constraint number;
- ``constraints``: the active constraints (each a JSON ``Constraint``, in the order added);
- ``acks``: the latest answers per (sender, seq), so duplicate feedback is answered the same way
  after a restart too (the newest ``max_acks``, default :data:`MAX_ACKS`, are kept).

Each change (a feedback applied, constraints expired) is one transaction: a crash leaves either
the state before or the state after. A lock file (``restrictor.lock``, ``flock``) keeps a second
restrictor off the same directory; the kernel releases it when the process dies.
"""

from __future__ import annotations

import fcntl
import json
import os
import sqlite3
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from protocol.asp_vocabulary import UnsafeProgram
from protocol.errors import ProtocolError
from protocol.messages import Constraint
from protocol.schema import record_from_wire, record_to_wire
from runtime.asp_check import read_program

SCHEMA = 1
MAX_ACKS = 10_000
DB_NAME = "restrictor.sqlite3"
LOCK_NAME = "restrictor.lock"


class StoreError(ValueError):
    """The state directory or database cannot be used; the message names the path."""


@dataclass(frozen=True)
class AckRecord:
    """The answer given to one feedback (the FeedbackAck fields a duplicate gets again)."""

    src: str
    seq: int
    fingerprint: str
    accepted: bool
    reason: str
    constraint_id: str
    constraints_version: int


@dataclass
class StoredState:
    version: int = 0
    next_number: int = 1
    constraints: list[Constraint] = field(default_factory=list)
    acks: list[AckRecord] = field(default_factory=list)  # oldest first


def default_state_dir(namespace: str) -> Path:
    """``$XDG_STATE_HOME/arroch/<namespace>`` (default ``~/.local/state/arroch/<namespace>``)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "arroch" / namespace


class StateStore:
    """The SQLite database of one restrictor; ``directory=None`` keeps it in memory (not persisted)."""

    def __init__(self, directory: str | Path | None, site_name: str, *, max_acks: int = MAX_ACKS) -> None:
        self.path: Path | None = None
        self.max_acks = max_acks
        self._lock_fd: int | None = None
        self._db: sqlite3.Connection | None = None
        if directory is None:
            target = ":memory:"
        else:
            directory = Path(directory).expanduser()
            try:
                directory.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise StoreError(f"cannot create the state directory {directory}: {exc}") from None
            self._lock(directory)
            self.path = directory / DB_NAME
            target = str(self.path)
        try:
            self._db = sqlite3.connect(target, isolation_level=None)  # explicit transactions below
            self._db.executescript(
                """
                CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
                CREATE TABLE IF NOT EXISTS constraints (ord INTEGER PRIMARY KEY AUTOINCREMENT,
                    id TEXT UNIQUE NOT NULL, body TEXT NOT NULL);
                CREATE TABLE IF NOT EXISTS acks (ord INTEGER PRIMARY KEY AUTOINCREMENT,
                    src TEXT NOT NULL, seq INTEGER NOT NULL, body TEXT NOT NULL, UNIQUE (src, seq));
                """
            )
            self._check_meta(site_name)
        except sqlite3.Error as exc:
            self.close()
            raise StoreError(f"state database {self.where}: {exc}") from None
        except BaseException:
            self.close()  # release the lock: a refused start must not block the next one
            raise

    @property
    def where(self) -> str:
        return str(self.path) if self.path else "(in memory)"

    def _lock(self, directory: Path) -> None:
        fd = os.open(directory / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise StoreError(f"another restrictor is using the state directory {directory}") from None
        self._lock_fd = fd

    def _check_meta(self, site_name: str) -> None:
        meta = dict(self._db.execute("SELECT key, value FROM meta").fetchall())
        if not meta:
            with self._transaction():
                self._db.executemany(
                    "INSERT INTO meta (key, value) VALUES (?, ?)",
                    [("schema", str(SCHEMA)), ("site", site_name), ("version", "0"), ("next_number", "1")],
                )
            return
        if meta.get("schema") != str(SCHEMA):
            raise StoreError(
                f"state database {self.where} has schema {meta.get('schema')!r}, this restrictor reads {SCHEMA}"
            )
        if meta.get("site") != site_name:
            raise StoreError(
                f"state database {self.where} belongs to site {meta.get('site')!r}, not {site_name!r}; "
                "use another --state-dir"
            )

    def _transaction(self) -> Any:
        return _Transaction(self._db)

    # ------------------------------------------------------------------ reading

    def load(self) -> StoredState:
        """The stored state; raises :class:`StoreError` if a row is not a valid constraint."""
        try:
            meta = dict(self._db.execute("SELECT key, value FROM meta").fetchall())
            rows = self._db.execute("SELECT ord, body FROM constraints ORDER BY ord").fetchall()
            ack_rows = self._db.execute("SELECT body FROM acks ORDER BY ord").fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"state database {self.where}: {exc}") from None
        state = StoredState(version=int(meta["version"]), next_number=int(meta["next_number"]))
        for ord_, body in rows:
            try:
                constraint = record_from_wire(Constraint, json.loads(body))
                _, terms = read_program(constraint.asp)
                if constraint.terms is None:  # stored before constraints carried their terms
                    constraint.terms = terms
            except (ValueError, ProtocolError, UnsafeProgram) as exc:
                raise StoreError(
                    f"state database {self.where}: constraints row {ord_} is not a valid constraint: {exc}"
                ) from None
            state.constraints.append(constraint)
        for (body,) in ack_rows:
            try:
                state.acks.append(AckRecord(**json.loads(body)))
            except (ValueError, TypeError):
                continue  # an unreadable old answer only costs dedup of that one feedback
        return state

    # ------------------------------------------------------------------ writing

    def commit(
        self,
        *,
        version: int,
        next_number: int,
        add: list[Constraint] = (),
        remove: list[str] = (),
        ack: AckRecord | None = None,
    ) -> None:
        """Apply one change atomically. Raises ``sqlite3.Error`` (nothing written) on failure."""
        with self._transaction():
            self._db.executemany(
                "UPDATE meta SET value = ? WHERE key = ?",
                [(str(version), "version"), (str(next_number), "next_number")],
            )
            if remove:
                self._db.executemany("DELETE FROM constraints WHERE id = ?", [(cid,) for cid in remove])
            for constraint in add:
                self._db.execute(
                    "INSERT INTO constraints (id, body) VALUES (?, ?)",
                    (constraint.id, json.dumps(record_to_wire(constraint))),
                )
            if ack is not None:
                self._insert_ack(ack)

    def clear(self) -> None:
        """Forget the active constraints and the answers, as for a new mission (``--fresh``).

        The version goes on (+1) rather than back to 0, so listeners that ignore older versions
        take the empty set; constraint numbers go on too, so no id is ever given out twice."""
        with self._transaction():
            self._db.execute("DELETE FROM constraints")
            self._db.execute("DELETE FROM acks")
            self._db.execute("UPDATE meta SET value = CAST(value AS INTEGER) + 1 WHERE key = 'version'")

    def record_ack(self, ack: AckRecord) -> None:
        """Remember an answer that changed nothing (a refusal)."""
        with self._transaction():
            self._insert_ack(ack)

    def _insert_ack(self, ack: AckRecord) -> None:
        self._db.execute(
            "INSERT OR REPLACE INTO acks (src, seq, body) VALUES (?, ?, ?)", (ack.src, ack.seq, json.dumps(asdict(ack)))
        )
        self._db.execute("DELETE FROM acks WHERE ord <= (SELECT MAX(ord) FROM acks) - ?", (self.max_acks,))

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT, or ROLLBACK on any exception."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self._db = db

    def __enter__(self) -> None:
        self._db.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type: Any, *_: Any) -> None:
        if exc_type is None:
            self._db.execute("COMMIT")
        else:
            self._db.execute("ROLLBACK")
