"""Scale-out: one process reads the reader and publishes each read to its tag's
shard; two workers track their shards (a real mosquitto broker on loopback)."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from robots import mosquitto_broker
from scattertrack import track
from scattertrack.cli import main
from scattertrack.io import read_reads, read_track
from scattertrack.io.mqtt import MqttPublisher, read_payload, shard_of
from scattertrack.readers.live import LiveSession
from scattertrack.readers.mqtt_in import MqttReadsSession
from scattertrack.sim import load_scenario, simulate

SPEED = 8.0  # simulated seconds per wall second


@pytest.fixture(scope="module")
def five_tags():
    """4 s of five tags read at once: tags of both shards (E2000A01-03 in 1, A04-05 in 0 of 2)."""
    scenario = load_scenario("glac-3d-arm-5tags")
    scenario["duration_s"] = 4.0
    return simulate(scenario, seed=2)


def test_the_shard_of_a_tag_is_crc32_of_its_upper_case_epc():
    assert shard_of("e2000a01", 2) == shard_of("E2000A01", 2) == 1  # zlib.crc32(b"E2000A01") % 2
    assert [shard_of(f"E2000A0{i}", 2) for i in range(1, 6)] == [1, 1, 1, 0, 0]
    assert all(shard_of("E2000A01", n) < n for n in range(1, 50))


def test_every_read_is_tracked_by_exactly_one_worker(five_tags, tmp_path, serve_reads):
    sim = five_tags
    with mosquitto_broker(tmp_path) as port:
        # Workers first: their subscriptions exist before the first read is published.
        workers = [
            MqttReadsSession(sim.scene, "127.0.0.1", port, k, 2, tmp_path / f"reads{k}.csv", tmp_path / f"track{k}.csv", track.make("glac", sim.scene))
            for k in range(2)
        ]
        publisher = MqttPublisher("127.0.0.1", port)
        with serve_reads(sim.reads, speed=SPEED) as emulator:
            ingest = LiveSession(sim.scene, "127.0.0.1", emulator.port, tmp_path / "reads.csv", None, None, duration_s=4.0 / SPEED + 4.0, read_publisher=publisher, shards=2)

            async def run_all():
                stops = [asyncio.Event() for _ in workers]
                running = [asyncio.create_task(w.run(s)) for w, s in zip(workers, stops)]
                summary = await ingest.run()
                deadline = time.monotonic() + 15.0
                while sum(w.summary.reads for w in workers) < summary.reads and time.monotonic() < deadline:
                    await asyncio.sleep(0.05)
                for stop in stops:
                    stop.set()
                return summary, [await r for r in running]

            summary, worked = asyncio.run(run_all())
    assert summary.reads > 100 and publisher.published == summary.reads and summary.estimates == 0
    assert not (tmp_path / "track.csv").exists()
    assert sum(w.reads for w in worked) == summary.reads
    everything = read_reads(tmp_path / "reads.csv", sim.scene)
    seen = set()
    for k, worker in enumerate(worked):
        tags = set(worker.tags)
        assert tags and all(shard_of(epc, 2) == k for epc in tags)
        assert not tags & seen, "a tag on two workers"
        seen |= tags
        mine = read_reads(tmp_path / f"reads{k}.csv", sim.scene)
        theirs = everything.select(np.isin(everything.epc, list(tags)))
        # The worker's journal is the reader's rows of its tags, value for value.
        np.testing.assert_array_equal(mine.time_s, theirs.time_s)
        np.testing.assert_array_equal(mine.phase_rad, theirs.phase_rad)
        np.testing.assert_array_equal(mine.antenna, theirs.antenna)
        tracked = read_track(tmp_path / f"track{k}.csv")
        assert worker.estimates == len(tracked) > 0 and set(tracked.epc) <= tags
    assert seen == set(summary.tags) == set(everything.epc)


def test_a_worker_declines_and_counts_what_is_not_its_read(five_tags, tmp_path):
    sim = five_tags
    with mosquitto_broker(tmp_path) as port:
        worker = MqttReadsSession(sim.scene, "127.0.0.1", port, 0, 2, tmp_path / "reads.csv", tmp_path / "track.csv", track.make("glac", sim.scene))
        try:
            worker.receive(b"not json")
            worker.receive(b'{"time_s": 1.0, "epc": "E2000A04"}')
            worker.receive(read_payload({"time_s": 1.0, "epc": "E2000A01", "antenna": 1, "frequency_hz": 915.25e6, "phase_rad": 1.0}))
            good = read_payload({"time_s": 1.0, "epc": "E2000A04", "antenna": 1, "frequency_hz": 915.25e6, "phase_rad": 1.0})
            worker.receive(good)
            worker.receive(good)  # QoS 1 may deliver twice
        finally:
            worker.subscriber.close()
            worker.journal.close()
            worker.track.close()
    declined = worker.summary.declined
    assert worker.summary.reads == 1 and sum(declined.values()) == 4
    assert any("not JSON" in reason for reason in declined) and any("no antenna" in reason for reason in declined)
    assert any("another shard" in reason for reason in declined) and any("duplicate" in reason for reason in declined)


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--mqtt-in", "127.0.0.1:1"], "--mqtt-in needs --shard"),
        (["--llrp", "127.0.0.1:1", "--shard", "0/2"], "--shard goes with --mqtt-in"),
        (["--llrp", "127.0.0.1:1", "--shards", "2"], "--shards goes with --publish-reads"),
        (["--llrp", "127.0.0.1:1"], "--out is required"),
        (["--mqtt-in", "127.0.0.1:1", "--shard", "2/2"], "expected K/N"),
        (["--llrp", "127.0.0.1:1", "--mqtt-in", "127.0.0.1:1"], "not allowed with"),
    ],
)
def test_the_worker_and_publisher_flags_are_checked(tmp_path, capsys, flags, message):
    scene = tmp_path / "scene.toml"
    simulate(load_scenario("glac-3d-walls") | {"duration_s": 1.0}, seed=1).scene.save(scene)
    code = main(["live", "--scene", str(scene), "--journal", str(tmp_path / "reads.csv"), *flags])
    assert code == 2
    assert message in capsys.readouterr().err
