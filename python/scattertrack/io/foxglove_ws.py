"""Live ROS 2 messages over a Foxglove WebSocket (the ``foxglove-sdk`` server).

The same topics, schemas and CDR bytes as the MCAP and bag files
(:mod:`scattertrack.io.ros2`): each channel is advertised with its
``ros2msg`` schema and ``cdr`` encoding, so Foxglove (and any client of
the Foxglove WebSocket protocol) decodes them as it decodes the files.
A channel is created on a tag's first estimate. The server keeps no
history: a client sees what is published after it subscribes, and a slow
client loses its oldest messages (the SDK's per-client backlog), never
slowing the tracker. The antennas' markers are re-sent to every client
that subscribes to them, since they are published only once.
"""

from __future__ import annotations

import time

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
DRAIN_S = 0.3
"""At the end, how long the server keeps sending what is queued for its
clients (stopping it drops that; the SDK cannot say when a queue is empty)."""


class FoxgloveServer:
    """A Foxglove WebSocket server on ``host:port`` (0: a free port) with its own context."""

    def __init__(self, builder, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "scattertrack", on_channel=None) -> None:
        import foxglove

        self.builder = builder
        self.on_channel = on_channel
        """Called with each new channel before its first message (tests wait there for a subscription)."""
        self.published = 0
        self._foxglove = foxglove
        # An own context: two servers in one process (tests, live and stream) never share channels.
        self._context = foxglove.Context()
        self._channels: dict = {}
        self._latched: dict = {}
        server = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                latched = server._latched.get(channel.topic)
                if latched is not None:
                    server._channels[channel.topic].log(latched[1], log_time=latched[0], sink_id=client.id)

        self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context, server_listener=Listener())
        self.port = self._server.port

    def _channel(self, name: str, msgtype: str):
        channel = self._channels.get(name)
        if channel is None:
            schema = self._foxglove.Schema(name=msgtype, encoding="ros2msg", data=self.builder.schema(msgtype).encode())
            channel = self._foxglove.Channel(name, schema=schema, message_encoding="cdr", context=self._context)
            self._channels[name] = channel
            if self.on_channel is not None:
                self.on_channel(channel)
        return channel

    def write(self, name: str, msgtype: str, stamp: int, data: bytes, latch: bool = False) -> None:
        """Publish one CDR message (``latch``: also to clients that subscribe later)."""
        channel = self._channel(name, msgtype)
        if latch:
            self._latched[name] = (stamp, data)
        channel.log(data, log_time=stamp)
        self.published += 1

    def close(self) -> None:
        if self.published:
            time.sleep(DRAIN_S)
        for channel in self._channels.values():
            channel.close()
        self._server.stop()
