"""Real robot-side components on loopback for the live-output tests: the
Debian ``mosquitto`` broker and a Foxglove WebSocket client.

Both are bounded in time and stopped by the fixture or context manager
that started them. Without ``mosquitto`` a test is skipped, with the
reason, only outside CI: in CI (``CI`` set) ``.ci/run`` installs it and
its absence is a failure.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

import pytest

MOSQUITTO = shutil.which("mosquitto") or next((p for p in ("/usr/sbin/mosquitto",) if os.path.exists(p)), None)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def mosquitto_broker(folder: Path):
    """A broker on 127.0.0.1 and a free port, its own config; yields the port."""
    if MOSQUITTO is None:
        if os.environ.get("CI"):
            pytest.fail("mosquitto is not installed (.ci/run installs it before make test)")
        pytest.skip("mosquitto is not installed (apt-get install -y mosquitto); CI installs it and runs this test")
    port = free_port()
    config = folder / "mosquitto.conf"
    config.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    process = subprocess.Popen([MOSQUITTO, "-c", str(config)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 10.0
        while True:
            assert process.poll() is None, process.communicate()[0]
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert time.monotonic() < deadline, "mosquitto did not start listening"
            time.sleep(0.02)
        yield port
    finally:
        process.terminate()
        try:
            process.wait(5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


class Subscriber:
    """An MQTT subscriber (paho) on ``topic``, keeping every message it gets."""

    def __init__(self, port: int, topic: str = "scattertrack/tags/+/estimate") -> None:
        import paho.mqtt.client as mqtt

        self.messages: list = []
        self._subscribed = threading.Event()
        self._client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        self._client.on_message = lambda client, userdata, message: self.messages.append((message.topic, json.loads(message.payload)))
        self._client.on_subscribe = lambda *args: self._subscribed.set()
        self._client.on_connect = lambda client, *args: client.subscribe(topic, qos=1)
        self._client.connect("127.0.0.1", port)
        self._client.loop_start()
        assert self._subscribed.wait(10.0), "the subscriber was not subscribed"

    def wait_for(self, count: int, timeout_s: float = 10.0) -> list:
        deadline = time.monotonic() + timeout_s
        while len(self.messages) < count and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.2)  # and nothing more than that arrives
        return self.messages

    def close(self) -> None:
        self._client.disconnect()
        self._client.loop_stop()


class FoxgloveClient:
    """A client of the Foxglove WebSocket protocol (``foxglove.sdk.v1``) in a
    thread: subscribes to every channel as it is advertised and keeps
    ``topic -> [(log_time_ns, payload bytes)]``, plus each channel's schema."""

    def __init__(self, port: int) -> None:
        self.channels: dict = {}
        self.received: dict = {}
        self._by_subscription: dict = {}
        self._next = 1
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, args=(port,), daemon=True)
        self._thread.start()
        assert self._ready.wait(10.0), "the Foxglove client did not connect"

    def _loop(self, port: int) -> None:
        from websockets.sync.client import connect

        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], open_timeout=10) as socket_:
            self._ready.set()
            while not self._stop.is_set():
                try:
                    frame = socket_.recv(timeout=0.05)
                except TimeoutError:
                    continue
                except Exception:  # noqa: BLE001 - the server went away: the test reads what came
                    return
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message.get("op") == "advertise":
                        subscriptions = []
                        for channel in message["channels"]:
                            self.channels[channel["topic"]] = channel
                            self._by_subscription[self._next] = channel["topic"]
                            subscriptions.append({"id": self._next, "channelId": channel["id"]})
                            self._next += 1
                        socket_.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                elif frame[0] == 0x01:  # MessageData: op, subscription id u32, log time u64, payload
                    subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                    self.received.setdefault(self._by_subscription[subscription], []).append((log_time, bytes(frame[13:])))

    def count(self) -> int:
        return sum(len(v) for v in self.received.values())

    def wait_for(self, predicate, timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            time.sleep(0.02)
        return predicate()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
