"""The constraint library as the running restrictor serves it (queryable ``constraints/library``).

Feedback buttons (the AR client's panel, the tablet page) are built from this answer, never from a
library file loaded in the client's own process, so they always offer what the restrictor that
will judge the feedback accepts.

Wire form: the message :class:`~protocol.messages.ConstraintLibrary` (envelope, ``site``,
``entries``) through the codec (:mod:`protocol.codec`) like every other message; ``entries`` is the
library with the site's choices resolved, one :class:`~protocol.messages.LibraryEntry` each (see
docs/services/restrictor.md, "Library file"). Decoding checks shape and limits and raises
:class:`~protocol.errors.ProtocolError` naming the field; fields it does not know are ignored (a
newer minor revision may add some).
"""

from __future__ import annotations

from typing import Any

from .codec import decode, encode
from .messages import (
    LIBRARY_MAX_ENTRIES as MAX_ENTRIES,
)
from .messages import (
    LIBRARY_MAX_HELP as MAX_HELP,
)
from .messages import (
    LIBRARY_MAX_LABEL as MAX_LABEL,
)
from .messages import (
    LIBRARY_MAX_PARAMS as MAX_PARAMS,
)
from .messages import (
    ConstraintLibrary,
    LibraryEntry,
    LibraryParam,
    LibraryWindow,
)
from .schema import record_to_wire

MAX_SIZE = ConstraintLibrary.MAX_SIZE

__all__ = [
    "MAX_ENTRIES",
    "MAX_HELP",
    "MAX_LABEL",
    "MAX_PARAMS",
    "MAX_SIZE",
    "ConstraintLibrary",
    "LibraryEntry",
    "LibraryParam",
    "LibraryWindow",
    "decode_library",
    "encode_library",
    "entries_to_wire",
]


def encode_library(src: str, site: str, entries: list[LibraryEntry]) -> bytes:
    """The reply payload for ``entries`` (as ``library_for_site`` gives them), checked before it goes out."""
    payload = encode(ConstraintLibrary(src=src, site=site, entries=entries))
    decode_library(payload)  # a restrictor never serves what its clients would refuse
    return payload


def decode_library(payload: bytes) -> ConstraintLibrary:
    """The library in ``payload``; :class:`~protocol.errors.ProtocolError` naming the first field that is wrong."""
    return decode(payload, ConstraintLibrary)


def entries_to_wire(entries: list[LibraryEntry]) -> list[dict[str, Any]]:
    """The entries as plain JSON-ready maps (what a page's script reads)."""
    return [record_to_wire(entry) for entry in entries]
