"""Live LLRP runs against the simulated reader, on loopback, bounded in time."""

from __future__ import annotations

import asyncio
import dataclasses
import time

import numpy as np
import pytest
from robots import free_port

from scattertrack import track
from scattertrack.track import parameters
from scattertrack.io import read_reads, read_track
from scattertrack.readers.live import DUPLICATE, LiveSession

SPEED = 8.0  # simulated seconds per wall second: 6 s of reads in 0.75 s


def _live(scene, port, tmp_path, duration_s, **options):
    session = LiveSession(scene, "127.0.0.1", port, tmp_path / "reads.csv", tmp_path / "track.csv", track.make("glac", scene), duration_s=duration_s, **options)
    return session, asyncio.run(session.run())


def test_every_read_sent_is_journaled_once_across_a_forced_disconnect(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    with serve_reads(sim.reads, speed=SPEED, drop_after_s=3.0) as emulator:
        session, summary = _live(sim.scene, emulator.port, tmp_path, duration_s=6.0 / SPEED + 1.5)
        sent = emulator.sent_first_seen_us()
        assert emulator.drops == 1
    journal = read_reads(tmp_path / "reads.csv")
    journal_us = np.rint(journal.time_s * 1e6).astype(np.int64)
    assert journal_us.tolist() == sent  # the same reads, once each, in order
    assert summary.reads == len(sent) and summary.connections == 2
    assert len(summary.outages_s) == 1 and 0 < summary.outages_s[0] < 1.5
    assert summary.stopped_by == "duration"
    assert len(sent) < len(sim.reads)  # the reader read nothing while disconnected


def test_the_live_track_is_the_offline_track_of_the_journal(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    with serve_reads(sim.reads, speed=SPEED, drop_after_s=2.0) as emulator:
        _, summary = _live(sim.scene, emulator.port, tmp_path, duration_s=6.0 / SPEED + 1.5)
    live = read_track(tmp_path / "track.csv")
    # With the live tracker's read budget, which offline runs leave unbounded.
    offline = track.run("glac", sim.scene, read_reads(tmp_path / "reads.csv"), **parameters.live("glac", {}))
    assert summary.estimates == len(live) == len(offline) > 0
    assert np.abs(live.time_s - offline.time_s).max() < 1e-6
    assert np.abs(live.position - offline.position).max() < 2e-6  # 6-decimal cells
    # The reader clock is the Unix epoch: the reads are on the simulated trajectory all the same.
    truth_start = float(sim.truth.time_s[0])
    assert live.time_s[0] > 1.7e9 and truth_start < 1.0


def test_reports_the_scene_cannot_use_are_declined_and_counted(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    scene = dataclasses.replace(sim.scene, antennas=[a for a in sim.scene.antennas if a.id != 4])
    with serve_reads(sim.reads, speed=SPEED) as emulator:
        session, summary = _live(scene, emulator.port, tmp_path, duration_s=6.0 / SPEED + 1.0)
        sent = len(emulator.sent)
    from_four = int(np.sum(sim.reads.antenna == 4))
    assert summary.declined["antenna 4 is not in the scene"] == from_four
    assert summary.reads + from_four == sent


def test_a_report_received_twice_is_journaled_once(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation
    with serve_reads(sim.reads, speed=SPEED) as emulator:
        session, summary = _live(sim.scene, emulator.port, tmp_path, duration_s=6.0 / SPEED + 1.0)
    journal = read_reads(tmp_path / "reads.csv")
    # Replay the first report as a reader with report holding would after a reconnect.
    from llrpkit.inventory import TagReport

    session.journal = type(session.journal)(tmp_path / "reads.csv")
    report = TagReport(epc=bytes.fromhex(str(journal.epc[0])), antenna=int(journal.antenna[0]), channel_index=int(_channel_of(summary, journal.frequency_hz[0])), first_seen_us=round(journal.time_s[0] * 1e6), phase_deg=float(np.degrees(journal.phase_rad[0])))
    session.handle(report, summary.hop_table_hz)
    session.journal.close()
    assert summary.declined[DUPLICATE] == 1
    assert len(read_reads(tmp_path / "reads.csv")) == len(journal)


def _channel_of(summary, frequency_hz):
    return next(i for i, f in summary.hop_table_hz.items() if f == frequency_hz)


def test_duration_is_a_hard_stop_when_the_reader_never_answers(walls_simulation, tmp_path):
    port = free_port()  # a port nobody listens on
    start = time.monotonic()
    _, summary = _live(walls_simulation.scene, port, tmp_path, duration_s=0.8, backoff_s=(0.05, 0.2))
    assert time.monotonic() - start < 0.8 + 1.5
    assert summary.connections == 0 and summary.reads == 0 and summary.errors
    assert (tmp_path / "reads.csv").read_text().startswith("time_s,")  # a journal with its header


def test_a_stop_request_ends_the_run_cleanly(walls_simulation, tmp_path, serve_reads):
    sim = walls_simulation

    async def run_and_stop(port):
        session = LiveSession(sim.scene, "127.0.0.1", port, tmp_path / "reads.csv", tmp_path / "track.csv", track.make("glac", sim.scene), duration_s=30.0)
        stop = asyncio.Event()
        asyncio.get_running_loop().call_later(0.5, stop.set)
        return await session.run(stop)

    with serve_reads(sim.reads, speed=1.0) as emulator:
        start = time.monotonic()
        summary = asyncio.run(run_and_stop(emulator.port))
    assert summary.stopped_by == "stop" and time.monotonic() - start < 3.0
    assert summary.reads == len(read_reads(tmp_path / "reads.csv")) > 0
