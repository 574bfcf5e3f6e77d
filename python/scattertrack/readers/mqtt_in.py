"""A worker's live run: its shard's reads in over MQTT, a journal and a causal track out.

Scale-out (docs/live.md, "Many readers, many workers"): one ``live``
process reads the reader and publishes every read to its tag's shard
topic (``--publish-reads HOST:PORT --shards N``); N workers
``live --mqtt-in HOST:PORT --shard K/N`` each subscribe to
``scattertrack/reads/<K>`` (:class:`scattertrack.io.mqtt.MqttReadsSubscriber`)
and track their tags. Every tag's reads reach exactly one worker
(:func:`scattertrack.io.mqtt.shard_of`), so its track is that of one
causal tracker, and the workers' tracks together are the tracks of all tags.

:class:`MqttReadsSession` is a :class:`~scattertrack.readers.live.LiveSession`
whose reads come from the broker instead of a reader: the same journal,
de-duplication (QoS 1 may deliver a message twice), tracking and outputs.
A message that is not a read, or a read of another shard, is declined and
counted, never dropped silently.
"""

from __future__ import annotations

import asyncio
import queue

from scattertrack.io.mqtt import MqttReadsSubscriber, parse_read, shard_of
from scattertrack.readers.live import LiveSession

POLL_S = 0.005
"""How often the session looks for messages when none are waiting."""


class MqttReadsSession(LiveSession):
    """A live run on shard ``shard`` of ``shards`` (see the module docstring)."""

    def __init__(self, scene, host: str, port: int, shard: int, shards: int, journal_path, track_path, tracker, **options) -> None:
        if not 0 <= shard < shards:
            raise ValueError(f"shard {shard} of {shards}: expected 0 <= K < N")
        super().__init__(scene, host, port, journal_path, track_path, tracker, **options)
        self.shard, self.shards = shard, shards
        self._messages: queue.SimpleQueue = queue.SimpleQueue()
        # Subscribes now: a broker that is not there fails before anything runs.
        self.subscriber = MqttReadsSubscriber(host, port, shard, shards, self._messages.put)
        self.summary.connections = 1
        self.summary.reader = f"MQTT broker {host}:{port}, topic {self.subscriber.topic} (shard {shard} of {shards})"

    def receive(self, payload: bytes) -> None:
        """One message: a read of this shard is accepted, anything else declined."""
        read = parse_read(payload)
        if isinstance(read, str):
            self.summary.declined[f"a message that is not a read: {read}"] += 1
            return
        if shard_of(read["epc"], self.shards) != self.shard:
            self.summary.declined["a read of another shard (its publisher counts shards differently?)"] += 1
            return
        key = (read["time_s"], read["epc"], read["antenna"], read["channel_index"], round(read["phase_rad"] * 1e6))
        self.accept(read["time_s"], read["epc"], read["antenna"], read["frequency_hz"], read["phase_rad"],
                    read["rssi_dbm"], read["doppler_hz"], read["channel_index"], key)

    async def _run_forever(self) -> None:
        while True:
            try:
                payload = self._messages.get_nowait()
            except queue.Empty:
                await asyncio.sleep(POLL_S)
                continue
            self.receive(payload)

    async def run(self, stop: asyncio.Event | None = None):
        # What arrives after the end is not lost: the broker keeps it for the next run (persistent session).
        try:
            return await super().run(stop)
        finally:
            self.subscriber.close()
