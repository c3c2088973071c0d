"""Shared pieces of the reliability fuzz tests: who subscribes to what, seeded bad payloads, and a
client that sends them and reads the services' counters.

- :data:`SUBSCRIPTIONS`: every key each service of a mission subscribes to, with its message type
  (the services' ``setup()``; docs/architecture.md, "Keys");
- :class:`Mutator`: seeded bad payloads for a message type — random bytes, truncated and bit-flipped
  valid encodings, wrong field types, NaN/inf, out-of-range and oversized values, wrong ``v``, wrong
  ``type``, missing fields, other messages — each checked against the codec, so the caller knows
  it is invalid before sending it;
- :func:`hostile_feedback`: Feedback that decodes but tries to smuggle ASP through every parameter,
  the kind and the parameter names (the restrictor tests' injection corpus);
- :class:`FuzzClient`: a Zenoh client (wall clock, so it hears no clock of its own) with blocking
  publishers, and :func:`counted`, the sum of a service's per-key counters under a key expression;
- files: :func:`mutate` (hypothesis-drawn edits of a parsed TOML document) with :func:`dump_toml`,
  and :func:`mutate_bytes` (flips, insertions, deletions, truncation of the raw file);
- :func:`contained`: running an ``arroch`` command in-process, bounded in time, leaving no trace.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import random
import signal
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
import zenoh
from hypothesis import strategies as st

from protocol.codec import decode
from protocol.errors import ProtocolError
from protocol.messages import (
    ALL_MESSAGES,
    CameraFrame,
    Clock,
    ConstraintSet,
    DoorState,
    Event,
    Feedback,
    Intent,
    Message,
    RobotCommand,
    RobotPose,
    RobotStatus,
    TeamPlan,
)
from runtime.clock import WallClock
from runtime.service import Service
from runtime.transport import ZenohOptions
from services.restrictor.library import Library
from tests.conftest import TestClient
from tests.protocol.strategies import fields_of, is_required, minimal_wire, oversized_value, pack, wrong_type_value
from tests.restrictor.helpers import valid_params

# Key expressions (relative to arroch/<namespace>/) and the message type each carries.
KEY_TYPES: dict[str, type[Message]] = {
    "clock": Clock,
    "robot/*/pose": RobotPose,
    "robot/*/status": RobotStatus,
    "robot/*/command": RobotCommand,
    "door/*/state": DoorState,
    "plan": TeamPlan,
    "intent/*": Intent,
    "constraints": ConstraintSet,
    "feedback": Feedback,
    "event": Event,
    "camera/tablet/frame": CameraFrame,
}

# What each service of `arroch up --services planner,restrictor,sim,ar` (and `up` itself) subscribes
# to, one entry per subscription: each decodes (and counts) a payload on its own. A sim clock
# (`--clock sim`, the default) adds `clock` to every service but the sim, whose clock is its own
# engine; the planner also follows the clock itself (world versions), so it has two.
SUBSCRIPTIONS: dict[str, tuple[str, ...]] = {
    "planner": ("clock", "clock", "robot/*/pose", "robot/*/status", "door/*/state", "constraints", "event"),
    "restrictor": ("clock", "feedback"),
    "sim": ("robot/*/command", "plan"),
    "ar": ("clock", "robot/*/pose", "robot/*/status", "intent/*", "door/*/state", "constraints", "camera/tablet/frame"),
    "supervisor": ("clock", "event", "robot/*/status"),
}


def pattern_of(key: str) -> str:
    """The key expression of :data:`KEY_TYPES` a concrete relative key falls under."""
    for pattern in KEY_TYPES:
        if zenoh.KeyExpr(pattern).includes(zenoh.KeyExpr(key)):
            return pattern
    raise KeyError(f"no subscribed key expression covers {key!r}")


def receivers(key: str) -> list[str]:
    """The services that must decode a payload put on the relative ``key``, once per subscription."""
    pattern = pattern_of(key)
    return [service for service, patterns in SUBSCRIPTIONS.items() for p in patterns if p == pattern]


def counted(stats: dict[str, Any], name: str, prefix: str, pattern: str) -> int:
    """A service's ``name:<key>`` counters summed over the keys under ``prefix/pattern`` (the
    concrete keys, and the key expression itself, where per-key counts beyond the service's bound go)."""
    expr = zenoh.KeyExpr(f"{prefix}/{pattern}")
    total = 0
    for counter, value in stats.items():
        head, _, key = counter.partition(":")
        if head == name and key and expr.includes(zenoh.KeyExpr(key)):
            total += int(value)
    return total


# ---------------------------------------------------------------------------- bad payloads


def is_valid(payload: bytes, msg_type: type[Message]) -> bool:
    """Whether the codec accepts ``payload`` as ``msg_type``. Anything but a ProtocolError escaping
    the codec is a bug in it, and propagates."""
    try:
        decode(payload, msg_type)
    except ProtocolError:
        return False
    return True


_BAD_V = (2, 99, 0, -1, "1", None, True, 1.5, 2**40)
_OTHER_TYPES = ("", "Nope", "robotpose", 5, None, ["RobotPose"])
_NOT_A_MAP = ([1, 2, 3], 7, "RobotPose", None, b"\x00\x01", 1.5, True)
_BAD_FLOATS = (math.nan, math.inf, -math.inf)
_MAX_OVERSIZED_FIELD = 256 * 1024  # bigger oversized fields are left to the whole-payload case


class Mutator:
    """Seeded bad payloads for message types (the same seed gives the same payloads)."""

    KINDS = (
        "random_bytes",
        "truncated",
        "bit_flips",
        "wrong_field_type",
        "non_finite",
        "out_of_range",
        "oversized_field",
        "wrong_v",
        "wrong_type",
        "missing_field",
        "not_a_map",
        "other_message",
        "deep_nesting",
    )

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self._encoded: dict[type[Message], bytes] = {}
        self._fields: dict[type[Message], list[tuple[Any, Any]]] = {}
        self._oversized: dict[type[Message], list[bytes]] = {}

    def _wire(self, cls: type[Message]) -> dict[str, Any]:
        """A fresh valid wire map of ``cls`` (a deep copy of its minimal one, through msgpack)."""
        encoded = self._encoded.get(cls)
        if encoded is None:
            encoded = self._encoded[cls] = pack(minimal_wire(cls))
        return msgpack.unpackb(encoded, raw=False)

    def _fields_of(self, cls: type[Message]) -> list[tuple[Any, Any]]:
        fields = self._fields.get(cls)
        if fields is None:
            fields = self._fields[cls] = fields_of(cls)
        return fields

    def invalid(self, cls: type[Message]) -> tuple[str, bytes]:
        """(kind, payload) with a payload the codec refuses as ``cls``."""
        for _ in range(100):
            kind = self.rng.choice(self.KINDS)
            payload = getattr(self, f"_{kind}")(cls)
            if payload is not None and not is_valid(payload, cls):
                return kind, payload
        raise AssertionError(f"no invalid {cls.TYPE} payload in 100 tries")

    def oversized_payload(self, cls: type[Message]) -> bytes:
        """A valid message padded (with a field receivers would ignore) just past its size limit."""
        data = self._wire(cls)
        data["pad"] = b""
        data["pad"] = b"\x00" * (cls.MAX_SIZE + 1 - len(pack(data)) + 8)
        return pack(data)

    # Each case returns bytes (or None when the type has nothing to mutate that way).

    def _random_bytes(self, cls: type[Message]) -> bytes:
        return self.rng.randbytes(self.rng.choice((0, 1, 2, 5, 16, 64, 300)))

    def _truncated(self, cls: type[Message]) -> bytes:
        encoded = pack(self._wire(cls))
        return encoded[: self.rng.randrange(0, len(encoded))]

    def _bit_flips(self, cls: type[Message]) -> bytes:
        encoded = bytearray(pack(self._wire(cls)))
        for _ in range(self.rng.randint(1, 4)):
            encoded[self.rng.randrange(len(encoded))] ^= 1 << self.rng.randrange(8)
        return bytes(encoded)

    def _field(self, cls: type[Message], want: Callable[[Any, Any], bool] = lambda f, h: True):
        options = [(f, h) for f, h in self._fields_of(cls) if want(f, h)]
        return self.rng.choice(options) if options else (None, None)

    def _wrong_field_type(self, cls: type[Message]) -> bytes:
        f, hint = self._field(cls)
        data = self._wire(cls)
        data[f.name] = wrong_type_value(hint)
        return pack(data)

    def _non_finite(self, cls: type[Message]) -> bytes | None:
        f, _ = self._field(cls, lambda f, h: h is float)
        if f is None:
            return None
        data = self._wire(cls)
        data[f.name] = self.rng.choice(_BAD_FLOATS)
        return pack(data)

    def _out_of_range(self, cls: type[Message]) -> bytes | None:
        f, hint = self._field(
            cls,
            lambda f, h: h in (int, float) and (f.metadata.get("lo") is not None or f.metadata.get("hi") is not None),
        )
        if f is None:
            return None
        lo, hi = f.metadata.get("lo"), f.metadata.get("hi")
        above = hi is not None and (lo is None or self.rng.random() < 0.5)
        value = hi + 1 if above else lo - 1
        data = self._wire(cls)
        data[f.name] = float(value) if hint is float else int(value)
        return pack(data)

    def _oversized_field(self, cls: type[Message]) -> bytes | None:
        # One payload per field, built once: a value one element past the limit is large to make.
        options = self._oversized.get(cls)
        if options is None:
            options = self._oversized[cls] = []
            for f, hint in self._fields_of(cls):
                value = oversized_value(hint, f.metadata)
                if value is not None:
                    data = self._wire(cls)
                    data[f.name] = value
                    payload = pack(data)
                    if len(payload) <= _MAX_OVERSIZED_FIELD:
                        options.append(payload)
        return self.rng.choice(options) if options else None

    def _wrong_v(self, cls: type[Message]) -> bytes:
        data = self._wire(cls)
        data["v"] = self.rng.choice((cls.VERSION + 1, *_BAD_V))
        return pack(data)

    def _wrong_type(self, cls: type[Message]) -> bytes:
        data = self._wire(cls)
        data["type"] = self.rng.choice((*[c.TYPE for c in ALL_MESSAGES if c is not cls], *_OTHER_TYPES))
        return pack(data)

    def _missing_field(self, cls: type[Message]) -> bytes:
        names = ["v", "type", "src", "seq", "stamp", *[f.name for f, _ in self._fields_of(cls) if is_required(f)]]
        data = self._wire(cls)
        del data[self.rng.choice(names)]
        return pack(data)

    def _not_a_map(self, cls: type[Message]) -> bytes:
        return pack(self.rng.choice(_NOT_A_MAP))

    def _other_message(self, cls: type[Message]) -> bytes:
        return pack(self._wire(self.rng.choice([c for c in ALL_MESSAGES if c is not cls])))

    def _deep_nesting(self, cls: type[Message]) -> bytes:
        f, _ = self._field(cls)
        data = self._wire(cls)
        value: Any = data[f.name]
        for _ in range(self.rng.randint(8, 40)):
            value = [value] if self.rng.random() < 0.5 else {"k": value}
        data[f.name] = value
        return pack(data)


def bad_frames(rng: random.Random, valid_jpeg: bytes) -> Iterator[tuple[str, dict[str, Any]]]:
    """CameraFrame fields that decode but describe no usable picture (the AR client's ``bad_frames``)."""
    cases: list[tuple[str, dict[str, Any]]] = [
        ("garbage jpeg", {"jpeg": rng.randbytes(200)}),
        ("empty jpeg", {"jpeg": b""}),
        ("truncated jpeg", {"jpeg": valid_jpeg[: len(valid_jpeg) // 3]}),
        ("zero focal length", {"intrinsics": [0.0, 0.0, 320.0, 240.0]}),
        ("negative focal length", {"intrinsics": [-500.0, 500.0, 320.0, 240.0]}),
    ]
    while True:
        yield rng.choice(cases)


# ---------------------------------------------------------------------------- smuggled ASP


def hostile_feedback(
    library: Library, site: Any, injections: list[str], numbers: list[Any], names: list[str]
) -> list[tuple[str, dict[str, Any]]]:
    """(kind, params) pairs, each an entry's valid choice with one thing replaced by an injection: every
    parameter of every entry (numbers for integer ones), the kind, and extra parameter names.
    ``cancel`` names a constraint that is never active, so not one of them can be accepted."""
    from services.restrictor.library import INT

    out: list[tuple[str, dict[str, Any]]] = []
    for entry in library.entries.values():
        base = valid_params(entry, site, active_ids=("c999999",))
        for param in entry.params:
            for bad in [*injections, *(numbers if param.type == INT else [])]:
                out.append((entry.id, {**base, param.name: bad}))
        for name in names:
            out.append((entry.id, {**base, name: "d_storage"}))
    first = next(iter(library.entries.values()))
    for bad in injections:
        out.append((bad, valid_params(first, site, active_ids=("c999999",))))
    return out


# ---------------------------------------------------------------------------- the client


MAX_PUBLISHERS = 64


class FuzzClient(TestClient):
    """A test client on the wall clock (so it does not subscribe to, nor count, the fuzzed ``clock``),
    publishing raw payloads through blocking publishers (a fuzz payload is never dropped on the way)."""

    def __init__(self, namespace: str, endpoint: str, *, instance: str | None = None) -> None:
        # TestClient's constructor would give it a sim clock, i.e. a subscription to `clock`.
        Service.__init__(
            self,
            "fuzzer",
            namespace,
            ZenohOptions(mode="client", connect=[endpoint]),
            instance=instance or f"fuzzer-{uuid.uuid4().hex[:6]}",
            clock=WallClock(),
        )
        self.queues = {}
        self.sent: Counter[str] = Counter()  # relative key -> payloads put
        self._raw: dict[str, zenoh.Publisher] = {}

    def put_raw(self, key: str, payload: bytes) -> None:
        """Put ``payload`` on the relative ``key`` (blocking congestion control, batched). The first
        keys get a declared publisher; keys beyond them (fuzzed key chunks, thousands of them) are put
        through the session, as declaring a publisher per key would cost more than the puts."""
        publisher = self._raw.get(key)
        if publisher is None and len(self._raw) < MAX_PUBLISHERS:
            publisher = self._raw[key] = self.session.declare_publisher(
                f"{self.keys.prefix}/{key}", congestion_control=zenoh.CongestionControl.BLOCK, express=False
            )
            self._declared.append(publisher)
        if publisher is not None:
            publisher.put(payload)
        else:
            self.session.put(
                f"{self.keys.prefix}/{key}", payload, congestion_control=zenoh.CongestionControl.BLOCK, express=False
            )
        self.sent[key] += 1

    def stats(self, timeout: float = 3.0) -> dict[str, dict[str, Any]]:
        """Every service's counters (``stats/**``), by service name; the newest reply per name."""
        out: dict[str, dict[str, Any]] = {}
        for event in self.query(self.keys.stats("*", "*"), Event, timeout=timeout):
            data = dict(event.data or {})
            if data.get("service") != self.name:
                out[data["service"]] = data
        return out


# ---------------------------------------------------------------------------- TOML documents


def toml_value(value: Any) -> str:
    """A TOML value for anything a mutated document holds (non-finite floats and inline tables too,
    which the project's own site writer rightly refuses)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML for {type(value).__name__}")


def dump_toml(doc: dict[str, Any]) -> str:
    """TOML text of a (mutated) document: top-level values, then ``[tables]``, then ``[[arrays]]``."""
    head, tables = [], []
    for key, value in doc.items():
        name = json.dumps(str(key))
        if isinstance(value, dict):
            tables += ["", f"[{name}]", *(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items())]
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for entry in value:
                tables += ["", f"[[{name}]]", *(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in entry.items())]
        else:
            head.append(f"{name} = {toml_value(value)}")
    return "\n".join([*head, *tables]) + "\n"


def node_paths(node: Any, path: tuple = ()) -> list[tuple]:
    """Every path to a node of a document (tables, arrays, their entries and values), the root excluded."""
    out = []
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, child in children:
        out.append((*path, key))
        out += node_paths(child, (*path, key))
    return out


def scalar_values() -> Any:
    return st.one_of(
        st.integers(-(2**63), 2**63 - 1),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=20),
        st.booleans(),
        st.sampled_from(["", "x", "storage", "d_storage", "r0", "door", "int", "${door}", "-1"]),
    )


def toml_values() -> Any:
    """Values a mutation may put anywhere in a document."""
    scalars = scalar_values()
    return st.one_of(
        scalars,
        st.lists(scalars, max_size=4),
        st.dictionaries(st.text("abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8), scalars, max_size=3),
        st.just([]),
        st.just({}),
    )


MUTATIONS = ("replace", "delete", "duplicate", "add_key", "negate")


def mutations() -> Any:
    """(operation, which node, value) triples for :func:`mutate`."""
    return st.lists(
        st.tuples(st.sampled_from(MUTATIONS), st.integers(0, 10_000), toml_values()), min_size=1, max_size=4
    )


def mutate(doc: dict[str, Any], ops: list[tuple[str, int, Any]]) -> dict[str, Any]:
    """A deep copy of ``doc`` with the operations applied, each to the node its index picks."""
    doc = json.loads(json.dumps(doc))
    for op, index, value in ops:
        paths = node_paths(doc)
        if not paths:
            return doc
        *parent_path, key = paths[index % len(paths)]
        parent: Any = doc
        for step in parent_path:
            parent = parent[step]
        if op == "replace":
            parent[key] = value
        elif op == "delete":
            del parent[key]
        elif op == "duplicate" and isinstance(parent, list):
            parent.append(json.loads(json.dumps(parent[key])))
        elif op == "add_key":
            target = parent[key] if isinstance(parent[key], dict) else parent
            if isinstance(target, dict):
                target[f"extra_{index}"] = value
        elif op == "negate" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
            parent[key] = -parent[key] if parent[key] else -1
    return doc


def byte_mutations() -> Any:
    """(operation, position, bytes) triples for :func:`mutate_bytes`."""
    return st.lists(
        st.tuples(
            st.sampled_from(("flip", "insert", "delete", "truncate")),
            st.integers(0, 1_000_000),
            st.binary(min_size=1, max_size=8),
        ),
        min_size=1,
        max_size=5,
    )


def mutate_bytes(data: bytes, ops: list[tuple[str, int, bytes]]) -> bytes:
    buf = bytearray(data)
    for op, pos, chunk in ops:
        if not buf:
            break
        at = pos % len(buf)
        if op == "flip":
            buf[at] ^= chunk[0] or 1
        elif op == "insert":
            buf[at:at] = chunk
        elif op == "delete":
            del buf[at : at + len(chunk)]
        else:
            del buf[at:]
    return bytes(buf)


# ---------------------------------------------------------------------------- the command line in-process


class Overran(BaseException):
    """A run outlived its time limit (BaseException: no command's ``except Exception`` swallows it)."""


@contextlib.contextmanager
def contained(folder: Path, limit: float) -> Iterator[tuple[io.StringIO, io.StringIO]]:
    """Run an ``arroch`` command in-process in ``folder``: output captured, :class:`Overran` raised
    after ``limit`` seconds, and the signal handlers and logging set-up it changes (services install
    their own) restored afterwards."""
    out, err = io.StringIO(), io.StringIO()
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level

    def overran(_signum: int, _frame: Any) -> None:
        raise Overran()

    signal.signal(signal.SIGALRM, overran)
    signal.setitimer(signal.ITIMER_REAL, limit)
    try:
        with contextlib.chdir(folder), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            yield out, err
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, handler in saved.items():
            signal.signal(sig, handler)
        root.handlers[:] = handlers
        root.setLevel(level)
