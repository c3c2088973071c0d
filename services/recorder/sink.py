"""Where Foxglove channels go: an MCAP file, the Foxglove WebSocket server, or both (one SDK context).

Channels are created on first use, one per topic. Foxglove-schema messages are logged as themselves
(protobuf, their schemas from ``foxglove-sdk``); JSON channels carry a JSON Schema. The file alone
also gets metadata records and attachments (the wire store, :mod:`.wire`). Log times are Unix
nanoseconds (:mod:`.timebase`).

The file is created by :meth:`FoxgloveSink.open_file`, once the recorder has joined Zenoh, so a
recorder that cannot start leaves nothing behind; :meth:`abort` removes it again.
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

log = logging.getLogger("arroch.record")
# Messages queued per viewer before the oldest are dropped (the SDK's default is 1024): a lockstep
# mission publishes in bursts of hundreds, which a viewer on a slow link should still get whole, and
# a replay at 100x sends a mission's ~58,000 messages in about 7 s. 16,384 lost 6 of 114 plans to a
# viewer beside the loaded test suite; most messages are poses and transforms of ~200 bytes, so the
# bound is tens of MB at most.
VIEWER_BACKLOG = 65536


class FoxgloveSink:
    """One SDK context with its sinks; ``close()`` finishes the MCAP file (summary and index)."""

    def __init__(self, mcap_path: Path | None = None, *, serve: tuple[str, int] | None = None) -> None:
        self.context = Context()
        self._channels: dict[str, Any] = {}
        self._writer = None
        self._created = False  # this sink made the file (only then may abort() remove it)
        self.server = None
        self.path = mcap_path
        # Called with a topic when a viewer subscribes to it (on the SDK's thread): state sent once
        # (the site scene) is sent again for it.
        self.on_subscribe: Callable[[str], None] | None = None
        if serve is not None:  # at once: a port that cannot be had is a configuration error
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

    @property
    def port(self) -> int | None:
        return None if self.server is None else self.server.port

    @property
    def writing(self) -> bool:
        return self._writer is not None

    def open_file(self) -> None:
        """Create the MCAP file (never over an existing one)."""
        if self.path is None or self._writer is not None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer = foxglove.open_mcap(self.path, allow_overwrite=False, context=self.context)
        self._created = True

    def write_metadata(self, name: str, metadata: dict[str, str]) -> None:
        if self._writer is not None:
            self._writer.write_metadata(name, metadata)

    def attach(self, name: str, log_time: int, create_time: int, data: bytes, media_type: str) -> None:
        if self._writer is not None:
            self._writer.attach(log_time=log_time, create_time=create_time, name=name, media_type=media_type, data=data)

    def message(self, topic: str, msg: Any, at: int) -> None:
        """A ``foxglove.messages`` message on its typed channel, logged at ``at`` (ns)."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = self.declare(topic, type(msg))
        channel.log(msg, log_time=at)

    def json(self, topic: str, schema: dict[str, Any], data: Any, at: int) -> None:
        """JSON (``bytes`` already encoded, or data to encode) on a channel with ``schema``."""
        payload = data if isinstance(data, bytes) else json.dumps(data, separators=(",", ":")).encode()
        channel = self._channels.get(topic)
        if channel is None:
            channel = self.declare_json(topic, schema)
        channel.log(payload, log_time=at)

    def declare(self, topic: str, message_type: type) -> Any:
        """The typed channel of ``topic`` (made now if new: a viewer sees it advertised from then on)."""
        channel = self._channels.get(topic)
        if channel is None:
            typed = getattr(foxglove.channels, f"{message_type.__name__}Channel")
            channel = self._channels[topic] = typed(topic, context=self.context)
        return channel

    def declare_json(self, topic: str, schema: dict[str, Any]) -> Channel:
        channel = self._channels.get(topic)
        if channel is None:
            name = schema.get("title") or topic.strip("/")
            channel = self._channels[topic] = Channel(
                topic,
                message_encoding="json",
                context=self.context,
                schema=Schema(name=f"arroch.{name}", encoding="jsonschema", data=json.dumps(schema).encode()),
            )
        return channel

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        if self.server is not None:
            self.server.stop()
            self.server = None

    def abort(self) -> None:
        """Close and remove the file: a recorder that failed to start leaves nothing behind."""
        self.close()
        if self.path is not None and self._created:
            self.path.unlink(missing_ok=True)


class _Listener(ServerListener):
    def __init__(self, sink: FoxgloveSink) -> None:
        self.sink = sink

    def on_subscribe(self, client: Any, channel: Any) -> None:
        if self.sink.on_subscribe is not None:
            self.sink.on_subscribe(channel.topic)
