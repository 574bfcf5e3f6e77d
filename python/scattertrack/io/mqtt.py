"""Estimates out, and reads between processes, over MQTT (docs/formats.md section 11), with paho-mqtt.

**Estimates**: one message per track row on ``scattertrack/tags/<EPC>/estimate``: a JSON
object with the ``track.csv`` columns as that file's row says them
(``time_s``, ``epc``, ``x`` ``y`` ``z`` m, ``vx`` ``vy`` ``vz`` m/s,
``sx`` ``sy`` ``sz`` m; the 6-decimal cells as numbers, ``nan`` as
``null``, which JSON has instead), so a subscriber and the file agree
to the digit.

QoS 1 (at least once): a robot must not miss a fix because the broker
was briefly busy. paho's network thread does the sending, so a slow
broker never stalls the tracker; :meth:`close` waits (bounded) for the
messages still in flight. The client reconnects on its own after a lost
connection; what is published meanwhile is queued.

**Reads, sharded by tag** (scale-out: one process reads the reader, N
workers track): one message per journaled read on
``scattertrack/reads/<K>``, K = CRC-32 of the upper-case EPC mod N
(:func:`shard_of`: the same in every process and on every machine, so a
tag's reads always reach the same worker; an MQTT shared subscription
would split them). The payload is the read's ``reads.csv`` row as a JSON
object (:func:`read_payload`: ``time_s``, ``epc``, ``antenna``,
``frequency_hz``, ``phase_rad``, ``rssi_dbm``, ``doppler_hz``,
``channel_index``; missing values ``null``), the values as the journal
wrote them.
"""

from __future__ import annotations

import json
import math
import time
import zlib

TOPIC = "scattertrack/tags/{epc}/estimate"
READS_TOPIC = "scattertrack/reads/{shard}"
READ_FIELDS = ("time_s", "epc", "antenna", "frequency_hz", "phase_rad", "rssi_dbm", "doppler_hz", "channel_index")
"""A read message's keys, in ``reads.csv``'s column order."""
QOS = 1
CONNECT_TIMEOUT_S = 5.0
DRAIN_TIMEOUT_S = 5.0
"""At the end, how long the messages still in flight get to reach the broker."""


def payload(header: list[str], cells: list[str]) -> bytes:
    """The JSON object of one ``track.csv`` row (header and cells)."""
    row = {}
    for name, cell in zip(header, cells):
        if name == "epc":
            row[name] = cell.strip('"')
        else:
            value = float(cell) if cell else math.nan
            row[name] = None if math.isnan(value) else value
    return json.dumps(row, separators=(",", ":")).encode()


def shard_of(epc: str, shards: int) -> int:
    """The shard (0 … shards − 1) of a tag: CRC-32 of its upper-case EPC, mod ``shards``."""
    return zlib.crc32(epc.upper().encode("ascii", "replace")) % shards


def read_payload(read: dict) -> bytes:
    """The JSON object of one read (``READ_FIELDS``; NaN and None as ``null``)."""
    row = {}
    for name in READ_FIELDS:
        value = read.get(name)
        if isinstance(value, float) and math.isnan(value):
            value = None
        row[name] = value
    return json.dumps(row, separators=(",", ":")).encode()


def parse_read(payload: bytes) -> dict | str:
    """A read message's fields, or why it is not one (text)."""
    try:
        row = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        return f"not JSON ({error.msg if hasattr(error, 'msg') else error})"
    if not isinstance(row, dict):
        return "not a JSON object"
    missing = [name for name in ("time_s", "epc", "antenna", "frequency_hz", "phase_rad") if row.get(name) is None]
    if missing:
        return f"no {', '.join(missing)}"
    try:
        read = {
            "time_s": float(row["time_s"]),
            "epc": str(row["epc"]),
            "antenna": int(row["antenna"]),
            "frequency_hz": float(row["frequency_hz"]),
            "phase_rad": float(row["phase_rad"]),
            "rssi_dbm": math.nan if row.get("rssi_dbm") is None else float(row["rssi_dbm"]),
            "doppler_hz": math.nan if row.get("doppler_hz") is None else float(row["doppler_hz"]),
            "channel_index": None if row.get("channel_index") is None else int(row["channel_index"]),
        }
    except (TypeError, ValueError) as error:
        return f"a field of the wrong type ({error})"
    if not all(math.isfinite(read[k]) for k in ("time_s", "frequency_hz", "phase_rad")):
        return "a time, frequency or phase that is not finite"
    return read


class MqttPublisher:
    """A connection to one broker; :meth:`publish` one row at a time."""

    def __init__(self, host: str, port: int, client_id: str = "") -> None:
        import paho.mqtt.client as mqtt

        self.published = 0
        self._client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
        self._client.max_queued_messages_set(0)  # unbounded: nothing is dropped while reconnecting
        self._client.reconnect_delay_set(0.1, 5.0)
        self._infos = []
        # A broker that is not there fails here, before the reader is touched.
        self._client.connect(host, port, keepalive=30)
        self._client.loop_start()
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not self._client.is_connected():
            if time.monotonic() > deadline:
                self._client.loop_stop()
                raise ConnectionError(f"MQTT broker {host}:{port}: no CONNACK within {CONNECT_TIMEOUT_S:g} s")
            time.sleep(0.01)

    def publish(self, epc: str, header: list[str], cells: list[str]) -> None:
        self.publish_to(TOPIC.format(epc=epc), payload(header, cells))

    def publish_read(self, read: dict, shards: int) -> None:
        """One read to its tag's shard topic (:func:`shard_of`)."""
        self.publish_to(READS_TOPIC.format(shard=shard_of(read["epc"], shards)), read_payload(read))

    def publish_to(self, topic: str, message: bytes) -> None:
        info = self._client.publish(topic, message, qos=QOS)
        self._infos.append(info)
        self.published += 1
        if len(self._infos) > 1000:  # keep only what may still be in flight
            self._infos = [i for i in self._infos if not i.is_published()]

    def close(self) -> None:
        deadline = time.monotonic() + DRAIN_TIMEOUT_S
        for info in self._infos:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                info.wait_for_publish(remaining)
            except (RuntimeError, ValueError):  # never queued (no connection): nothing to wait for
                pass
        self._client.disconnect()
        self._client.loop_stop()


class MqttReadsSubscriber:
    """A worker's subscription to its shard's reads (``scattertrack/reads/<K>``).

    A persistent session (clean start off, one client id per shard and
    count: ``scattertrack-reads-<K>-of-<N>``) at QoS 1: once subscribed,
    the broker keeps the shard's reads for the worker while it is away and
    delivers them when it is back, so a restarted worker misses nothing
    that came after its first subscription. Messages arrive on paho's
    network thread; ``on_message(payload)`` is called there."""

    def __init__(self, host: str, port: int, shard: int, shards: int, on_message) -> None:
        import paho.mqtt.client as mqtt

        self.topic = READS_TOPIC.format(shard=shard)
        self.subscribed = False
        self._client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"scattertrack-reads-{shard}-of-{shards}", clean_session=False)
        self._client.reconnect_delay_set(0.1, 5.0)
        self._client.on_connect = lambda client, userdata, flags, reason, properties: client.subscribe(self.topic, qos=QOS)
        self._client.on_subscribe = lambda *args: setattr(self, "subscribed", True)
        self._client.on_message = lambda client, userdata, message: on_message(message.payload)
        self._client.connect(host, port, keepalive=30)
        self._client.loop_start()
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not self.subscribed:
            if time.monotonic() > deadline:
                self._client.loop_stop()
                raise ConnectionError(f"MQTT broker {host}:{port}: not subscribed to {self.topic} within {CONNECT_TIMEOUT_S:g} s")
            time.sleep(0.01)

    def close(self) -> None:
        self._client.disconnect()
        self._client.loop_stop()

