"""The constraint library as the restrictor serves it: what a client accepts and what it refuses.

``msgpack`` writes the payloads here (independently of :func:`encode_library`), so the reader is
checked against bytes it did not make. The library decodes through the codec like every message,
so its refusals are worded as the codec words them."""

from __future__ import annotations

import copy

import msgpack
import pytest

from protocol.constraint_library import MAX_SIZE, decode_library, encode_library, entries_to_wire
from protocol.errors import ProtocolError
from protocol.site import load_site
from services.restrictor.library import library_for_site

OFFICE = entries_to_wire(library_for_site(load_site()))


def _payload(**changes) -> dict:  # noqa: ANN003
    body = {"v": 1, "type": "ConstraintLibrary", "src": "restrictor-1", "seq": 0, "stamp": 0.0, "site": "office"}
    body["entries"] = OFFICE
    return {**copy.deepcopy(body), **changes}


def test_the_packaged_library_round_trips_and_unknown_fields_are_ignored():
    library = decode_library(encode_library("restrictor-1", "office", library_for_site(load_site())))
    assert library.src == "restrictor-1" and library.site == "office" and entries_to_wire(library.entries) == OFFICE
    newer = _payload(extra="a newer minor revision")
    newer["entries"][0]["colour"] = "red"
    assert entries_to_wire(decode_library(msgpack.packb(newer)).entries) == OFFICE


def _broken(field: str, value) -> bytes:  # noqa: ANN001
    body = _payload()
    target, *path = field.split(".")
    node = body
    if path:
        node = body["entries"][0]
        for step in path[:-1]:
            node = node[step] if not step.isdigit() else node[int(step)]
        node[path[-1]] = value
    else:
        body[target] = value
    return msgpack.packb(body)


@pytest.mark.parametrize(
    "payload, field, problem",
    [
        (b"\xc1", "", "not a valid msgpack document"),
        (msgpack.packb([1, 2]), "", "payload must be a map"),
        (b"\x00" * (MAX_SIZE + 1), "", "exceeds"),
        (_broken("type", "Feedback"), "type", "expected ConstraintLibrary, got Feedback"),
        (_broken("v", 2), "v", "newer"),
        (_broken("v", True), "v", "not an integer"),
        (_broken("entries", {"a": 1}), "entries", "expected list"),
        (_broken("entries", [{}] * 101), "entries", "exceeds the limit 100"),
        (_broken("site", 7), "site", "expected str"),
        (_broken("entries.effect", "delete"), "entries[0].effect", "is not one of add, cancel"),
        (_broken("entries.usable", "yes"), "entries[0].usable", "expected bool"),
        (_broken("entries.label", "x" * 81), "entries[0].label", "exceeds the limit 80"),
        (_broken("entries.window", "2 hours"), "entries[0].window", "expected map"),
        (_broken("entries.params.0.type", "float"), "entries[0].params[0].type", "is not one of"),
        (_broken("entries.params.0.choices", ["d_storage", 3]), "entries[0].params[0].choices[1]", "expected str"),
    ],
)
def test_a_malformed_library_is_refused_naming_the_field(payload: bytes, field: str, problem: str):
    with pytest.raises(ProtocolError) as err:
        decode_library(payload)
    assert err.value.field == field and problem in err.value.problem, str(err.value)
