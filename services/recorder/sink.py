"""Where Foxglove channels go: an MCAP file, the Foxglove WebSocket server, or both (one SDK context).

Channels are created on first use, one per topic. Foxglove-schema messages are logged as themselves
(protobuf, their schemas from ``foxglove-sdk``); JSON channels carry a JSON Schema; raw ARROCH
messages keep their msgpack bytes with the message type's JSON Schema for reference.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import foxglove
import foxglove.channels
from foxglove import Channel, Context, Schema
from foxglove.websocket import ServerListener

from .topics import RAW_ENCODING, RAW_SCHEMA_PREFIX

log = logging.getLogger("arroch.record")
# Messages queued per viewer before the oldest are dropped (the SDK's default is 1024): a lockstep
# mission publishes in bursts of hundreds, which a viewer on a slow link should still get whole.
VIEWER_BACKLOG = 16384


def ns(t: float) -> int:
    """Site-clock seconds → MCAP log time (nanoseconds, never negative)."""
    return max(int(round(t * 1e9)), 0)


class FoxgloveSink:
    """One SDK context with its sinks; ``close()`` finishes the MCAP file (summary and index)."""

    def __init__(
        self,
        mcap_path: Path | None = None,
        *,
        serve: tuple[str, int] | None = None,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.context = Context()
        self._channels: dict[str, Any] = {}
        self._writer = None
        self.server = None
        self.path = mcap_path
        # Called with a topic when a viewer subscribes to it (on the SDK's thread): state sent once
        # (the site scene) is sent again for it.
        self.on_subscribe: Callable[[str], None] | None = None
        if serve is not None:  # first: a port that cannot be had must not leave a file behind
            host, port = serve
            try:
                self.server = foxglove.start_server(
                    name="arroch",
                    host=host,
                    port=port,
                    context=self.context,
                    server_listener=_Listener(self),
                    message_backlog_size=VIEWER_BACKLOG,
                )
            except Exception as exc:
                raise ValueError(f"cannot serve the live view on {host}:{port}: {exc}") from None
            log.info(
                "Foxglove WebSocket server on ws://%s:%d (open it in Foxglove: Open connection)", host, self.server.port
            )
        if mcap_path is not None:
            mcap_path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = foxglove.open_mcap(mcap_path, allow_overwrite=False, context=self.context)
            if metadata:
                self._writer.write_metadata("arroch", metadata)

    @property
    def port(self) -> int | None:
        return None if self.server is None else self.server.port

    def _channel(self, topic: str, make: Callable[[], Any]) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = make()
        return channel

    def message(self, topic: str, msg: Any, t: float) -> None:
        """A ``foxglove.messages`` message on its typed channel."""
        self.declare(topic, type(msg)).log(msg, log_time=ns(t))

    def json(self, topic: str, schema: dict[str, Any], data: Any, t: float) -> None:
        self.declare_json(topic, schema).log(
            json.dumps(data, separators=(",", ":"), default=_jsonable).encode(), log_time=ns(t)
        )

    def declare(self, topic: str, message_type: type) -> Any:
        """The typed channel of ``topic`` (made now if new: a viewer sees it advertised from then on)."""
        typed = getattr(foxglove.channels, f"{message_type.__name__}Channel")
        return self._channel(topic, lambda: typed(topic, context=self.context))

    def declare_json(self, topic: str, schema: dict[str, Any]) -> Channel:
        def make() -> Channel:
            name = schema.get("title") or topic.strip("/")
            return Channel(
                topic,
                message_encoding="json",
                context=self.context,
                schema=Schema(name=f"arroch.{name}", encoding="jsonschema", data=json.dumps(schema).encode()),
            )

        return self._channel(topic, make)

    def raw(self, topic: str, type_name: str, schema: dict[str, Any], payload: bytes, t: float) -> None:
        def make() -> Channel:
            return Channel(
                topic,
                message_encoding=RAW_ENCODING,
                context=self.context,
                schema=Schema(
                    name=RAW_SCHEMA_PREFIX + type_name, encoding="jsonschema", data=json.dumps(schema).encode()
                ),
            )

        self._channel(topic, make).log(payload, log_time=ns(t))

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self.server is not None:
            self.server.stop()
            self.server = None


class _Listener(ServerListener):
    def __init__(self, sink: FoxgloveSink) -> None:
        self.sink = sink

    def on_subscribe(self, client: Any, channel: Any) -> None:
        if self.sink.on_subscribe is not None:
            self.sink.on_subscribe(channel.topic)


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    if isinstance(value, (set, tuple)):
        return list(value)
    return repr(value)
