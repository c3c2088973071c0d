"""The one error type the protocol layer raises for anything that came off the wire."""

from __future__ import annotations


class ProtocolError(ValueError):
    """A payload could not be decoded into a valid message.

    ``field`` is the dotted path of the offending field (``"trajectory[3][1]"``), or ``""``
    when the payload as a whole is the problem (not msgpack, not a map, too large).
    The message always starts with that path so logs say where to look.
    """

    def __init__(self, field: str, problem: str, msg_type: str = "") -> None:
        self.field = field
        self.problem = problem
        self.msg_type = msg_type
        where = f"{msg_type}." if msg_type and field else (f"{msg_type}: " if msg_type else "")
        text = f"{where}{field}: {problem}" if field else f"{where}{problem}"
        super().__init__(text)
