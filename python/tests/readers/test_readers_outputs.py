"""A live run's outputs besides track.csv (scattertrack.readers.outputs):
ROS 2 files read back with independent readers, Parquet, a Foxglove client
and an MQTT broker, all real and on loopback, every run bounded in time."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from robots import FoxgloveClient, Subscriber, free_port, mosquitto_broker
from scattertrack import track
from scattertrack.track import parameters
from scattertrack.io import read_reads, read_track, ros2
from scattertrack.readers.live import LiveSession
from scattertrack.readers.outputs import LiveOutputs, OutputOptions

SPEED = 8.0  # simulated seconds per wall second: 6 s of reads in 0.75 s
COLUMNS = ["time_s", "epc", "x", "y", "z", "vx", "vy", "vz", "sx", "sy", "sz"]


def _live(sim, emulator, tmp_path, options: OutputOptions, before_run=None):
    outputs = LiveOutputs(options, sim.scene, tmp_path / "track.csv")
    if before_run is not None:
        before_run(outputs)
    session = LiveSession(sim.scene, "127.0.0.1", emulator.port, tmp_path / "reads.csv", tmp_path / "track.csv", track.make("glac", sim.scene), duration_s=6.0 / SPEED + 6.0, outputs=outputs)  # generous: the subscription waits hold the loop on a busy machine
    summary = asyncio.run(session.run())
    return outputs, summary


def _offline(sim, tmp_path):
    """The journal tracked offline, with covariances: what every output must say."""
    return track.run("glac", sim.scene, read_reads(tmp_path / "reads.csv"), covariance=True, **parameters.live("glac", {}))


def test_mcap_bag_and_parquet_from_a_live_run_read_back_independently(walls_simulation, tmp_path, serve_reads):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    sim = walls_simulation
    options = OutputOptions(parquet=str(tmp_path / "track.parquet"), mcap=str(tmp_path / "live.mcap"), ros2_bag=str(tmp_path / "bag"), frame_id="map")
    with serve_reads(sim.reads, speed=SPEED, drop_after_s=3.0) as emulator:
        outputs, summary = _live(sim, emulator, tmp_path, options)
    live = read_track(tmp_path / "track.csv")
    offline = _offline(sim, tmp_path)
    assert summary.estimates == len(live) == len(offline) > 0
    # Parquet: the CSV's rows, to the digit.
    parquet = read_track(tmp_path / "track.parquet")
    assert np.array_equal(parquet.position, live.position) and np.array_equal(parquet.time_s, live.time_s)
    mcap: dict = {}
    with open(tmp_path / "live.mcap", "rb") as stream:
        for schema, channel, message, decoded in make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            mcap.setdefault(channel.topic, []).append((message.log_time, decoded))
    store = get_typestore(Stores.ROS2_HUMBLE)
    bag: dict = {}
    with Reader(tmp_path / "bag") as reader:
        for connection, stamp, raw in reader.messages():
            bag.setdefault(connection.topic, []).append((stamp, store.deserialize_cdr(raw, connection.msgtype)))
    epc = str(live.epc[0])
    assert set(live.epc.astype(str)) == {epc}  # one tag in this layout
    for got in (mcap, bag):
        assert len(got[ros2.topic(epc, "pose")]) == len(got[ros2.topic(epc, "odom")]) == len(live)
        assert len(got[ros2.ANTENNA_TOPIC]) == 1
        for i, ((stamp, pose), (_, odom)) in enumerate(zip(got[ros2.topic(epc, "pose")], got[ros2.topic(epc, "odom")])):
            p = pose.pose.pose.position
            assert np.abs(np.array([p.x, p.y, p.z]) - live.position[i]).max() <= 1e-6
            assert abs(stamp - round(live.time_s[i] * 1e9)) <= 1 and pose.header.frame_id == "map"
            covariance = np.array(pose.pose.covariance).reshape(6, 6)
            assert np.allclose(covariance[:3, :3], offline.covariance[i][:3, :3], rtol=1e-9, atol=1e-15)
            twist = np.array(odom.twist.covariance).reshape(6, 6)
            assert np.allclose(twist[:3, :3], offline.covariance[i][3:, 3:], rtol=1e-9, atol=1e-15)
    assert outputs.topics == {name: len(messages) for name, messages in mcap.items()}


class OutputsWithAClient(LiveOutputs):
    """LiveOutputs with a Foxglove client: a tag's channel gets its first
    message once the client's subscription has reached the server (the
    server keeps no history), and the end waits until the client has
    everything published. Both waits are bounded; neither depends on speed."""

    def __init__(self, options, scene, track_csv):
        super().__init__(options, scene, track_csv)
        self.client = FoxgloveClient(self.foxglove.port)
        self.foxglove.on_channel = self._wait_for_subscription

    def _wait_for_subscription(self, channel) -> None:
        assert self.client.wait_for(channel.has_sinks), f"{channel.topic()}: the client never subscribed"

    def close(self) -> None:
        published = self.foxglove.published
        self.client.wait_for(lambda: self.client.count() >= published)
        try:
            super().close()
        finally:
            self.client.close()


def test_a_foxglove_client_receives_every_live_message(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    store = ros2.Builder().store
    outputs = OutputsWithAClient(OutputOptions(foxglove=("127.0.0.1", 0)), sim.scene, tmp_path / "track.csv")
    with serve_reads(sim.reads, speed=SPEED) as emulator:
        session = LiveSession(sim.scene, "127.0.0.1", emulator.port, tmp_path / "reads.csv", tmp_path / "track.csv", track.make("glac", sim.scene), duration_s=6.0 / SPEED + 6.0, outputs=outputs)  # generous: the subscription waits hold the loop on a busy machine
        asyncio.run(session.run())
    client = outputs.client
    live = read_track(tmp_path / "track.csv")
    epc = str(live.epc[0])
    offline = _offline(sim, tmp_path)
    assert outputs.foxglove_published == 2 * len(live) + 1 == client.count()
    for kind, msgtype in (("pose", ros2.POSE), ("odom", ros2.ODOMETRY)):
        channel = client.channels[ros2.topic(epc, kind)]
        assert channel["encoding"] == "cdr" and channel["schemaName"] == msgtype and channel["schemaEncoding"] == "ros2msg"
        received = client.received[ros2.topic(epc, kind)]
        assert len(received) == len(live)
        for i, (stamp, data) in enumerate(received):
            message = store.deserialize_cdr(data, msgtype)
            p = message.pose.pose.position
            assert np.abs(np.array([p.x, p.y, p.z]) - live.position[i]).max() <= 1e-6
            assert np.allclose(np.array(message.pose.covariance).reshape(6, 6)[:3, :3], offline.covariance[i][:3, :3], rtol=1e-9, atol=1e-15)
            assert abs(stamp - round(live.time_s[i] * 1e9)) <= 1
    markers = store.deserialize_cdr(client.received[ros2.ANTENNA_TOPIC][0][1], ros2.MARKERS)
    assert len(markers.markers) == 2 * len(sim.scene.antennas)


def test_every_estimate_reaches_an_mqtt_subscriber_as_its_track_row(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    with mosquitto_broker(tmp_path) as port:
        subscriber = Subscriber(port)
        try:
            with serve_reads(sim.reads, speed=SPEED) as emulator:
                outputs, summary = _live(sim, emulator, tmp_path, OutputOptions(mqtt=("127.0.0.1", port)))
            messages = subscriber.wait_for(summary.estimates)
        finally:
            subscriber.close()
    text = (tmp_path / "track.csv").read_text().splitlines()
    assert text[0].split(",") == COLUMNS
    rows = [line.split(",") for line in text[1:]]
    assert outputs.mqtt_published == summary.estimates == len(messages) == len(rows) > 0
    for (topic, payload), cells in zip(messages, rows):
        assert topic == f"scattertrack/tags/{cells[1]}/estimate"
        assert list(payload) == COLUMNS and payload["epc"] == cells[1]
        for name, cell in zip(COLUMNS, cells):
            if name != "epc":
                assert (payload[name] is None and math.isnan(float(cell))) or payload[name] == float(cell)


def test_a_broker_that_is_not_there_fails_before_the_run(tmp_path):
    with pytest.raises(OSError):
        LiveOutputs(OutputOptions(mqtt=("127.0.0.1", free_port()), mcap=str(tmp_path / "x.mcap")))
    assert not (tmp_path / "x.mcap").exists()
