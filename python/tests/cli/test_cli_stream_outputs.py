"""``scattertrack stream --foxglove --mqtt-out``: a helper recording's rows
served to a real Foxglove client and a real mosquitto broker on loopback."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from robots import FoxgloveClient, Subscriber, free_port, mosquitto_broker
from scattertrack.cli import main
from scattertrack.io import read_track, ros2


@pytest.fixture(scope="module")
def iq_session(tmp_path_factory) -> Path:
    """0.1 s of the thesis arm at IQ level (30 replies), SigMF + calibration."""
    folder = tmp_path_factory.mktemp("iq")
    assert main(["simulate", "--scenario", "turbotrack-3d-arm", "--iq", "--duration", "0.1", "--out", str(folder)]) == 0
    return folder


def test_stream_serves_its_rows_on_foxglove_and_mqtt(capsys, iq_session, tmp_path, monkeypatch):
    from scattertrack.io import foxglove_ws

    port = free_port()
    clients = []
    started = foxglove_ws.FoxgloveServer.__init__

    def with_a_client(self, *args, **kwargs):
        # The client connects as soon as the server is up, before the run, as a robot would.
        started(self, *args, **kwargs)
        clients.append(FoxgloveClient(self.port))
        self.on_channel = lambda channel: clients[0].wait_for(channel.has_sinks)

    stopped = foxglove_ws.FoxgloveServer.close

    def once_received(self):
        # The whole track is published at the end: stop once the client has it all.
        clients[0].wait_for(lambda: clients[0].count() >= self.published)
        stopped(self)

    monkeypatch.setattr(foxglove_ws.FoxgloveServer, "__init__", with_a_client)
    monkeypatch.setattr(foxglove_ws.FoxgloveServer, "close", once_received)
    with mosquitto_broker(tmp_path) as broker:
        subscriber = Subscriber(broker)
        try:
            code = main([
                "stream", "--scene", str(iq_session / "scene.toml"), "--sigmf", str(iq_session / "recording.sigmf-meta"),
                "--calibration", str(iq_session / "calibration.sigmf-meta"), "--fast", "--out", str(tmp_path / "track.csv"),
                "--foxglove", f"127.0.0.1:{port}", "--mqtt-out", f"127.0.0.1:{broker}", "--frame-id", "arm",
            ])
            out = capsys.readouterr().out
            result = read_track(tmp_path / "track.csv")
            messages = subscriber.wait_for(len(result))
        finally:
            subscriber.close()
            for client in clients:
                client.close()
    assert code == 0
    assert len(result) > 20 and len(messages) == len(result)
    assert f"published {len(result)} estimates to the MQTT broker" in out and f"Foxglove WebSocket on ws://127.0.0.1:{port}" in out
    order = np.argsort(result.time_s, kind="stable")
    for (topic, payload), i in zip(messages, order):
        assert topic == f"scattertrack/tags/{result.epc[i]}/estimate"
        assert [payload[k] for k in ("x", "y", "z")] == result.position[i].tolist()
        assert all(payload[k] is None or math.isfinite(payload[k]) for k in payload if k != "epc")
    store = ros2.Builder().store
    epc = str(result.epc[0])
    received = clients[0].received[ros2.topic(epc, "pose")]
    assert len(received) == int(np.sum(result.epc == epc))
    pose = store.deserialize_cdr(received[-1][1], ros2.POSE)
    assert pose.header.frame_id == "arm"
    assert np.abs(np.array([pose.pose.pose.position.x, pose.pose.pose.position.y, pose.pose.pose.position.z]) - result.position[result.epc == epc][-1]).max() <= 1e-6
