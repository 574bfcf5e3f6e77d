"""Estimates out over MQTT (docs/formats.md section 11), with paho-mqtt.

One message per track row on ``scattertrack/tags/<EPC>/estimate``: a JSON
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
"""

from __future__ import annotations

import json
import math
import time

TOPIC = "scattertrack/tags/{epc}/estimate"
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
        info = self._client.publish(TOPIC.format(epc=epc), payload(header, cells), qos=QOS)
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
