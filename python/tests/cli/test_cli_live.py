"""``scattertrack live`` and ``emulate-reader``: the reader emulator in a child
process on loopback, ``live`` in-process, every run bounded by --duration."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robots import free_port
from scattertrack.cli import main
from scattertrack.io import read_reads, read_scene, read_track

from cli_runs import run


@pytest.fixture(scope="module")
def walls(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("walls")
    assert main(["simulate", "--scenario", "glac-3d-walls", "--out", str(folder), "--duration", "20"]) == 0
    return folder


def wait_listening(port: int, process, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert process.poll() is None, process.communicate()
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError("the emulator did not start listening")


def test_live_against_the_emulator_with_a_forced_disconnect(capsys, walls, tmp_path):
    port = free_port()
    emulator = subprocess.Popen(
        [sys.executable, "-m", "scattertrack", "emulate-reader", "--scenario", "glac-3d-walls", "--port", str(port), "--speed", "10", "--drop-after", "8", "--linger", "0.5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_listening(port, emulator)
        # The probe connection above used the emulator's one client slot for a moment; give it back.
        time.sleep(0.2)
        code, out, err = run(capsys, "live", "--scene", walls / "scene.toml", "--llrp", f"127.0.0.1:{port}", "--out", tmp_path / "track.csv", "--journal", tmp_path / "reads.csv", "--duration", "3.5", "--no-progress")
        served, _ = emulator.communicate(timeout=20)
    finally:
        emulator.kill()
    assert code == 0, err
    journal = read_reads(tmp_path / "reads.csv")
    assert f"sent {len(journal)} reads" in served and "1 forced disconnect" in served
    assert "--duration 3.5 s reached" in out and f"{len(journal)} reads of 1 tag journaled" in out
    assert "1 reconnect" in out and "hop table of 50 channels" in out
    assert len(read_track(tmp_path / "track.csv")) > 0
    # The reader's hop table, for offline runs: the journal's channel indices map to its carriers.
    scene = read_scene(tmp_path / "reads.scene.toml")
    assert len(scene.hop_table) == 50
    assert all(scene.hop_table[int(c)] == f for c, f in zip(journal.channel_index, journal.frequency_hz))


def test_live_refuses_bad_options_before_connecting(capsys, walls, tmp_path):
    base = ["live", "--scene", walls / "scene.toml", "--out", tmp_path / "t.csv", "--journal", tmp_path / "r.csv"]
    code, _, err = run(capsys, *base, "--llrp", "127.0.0.1:99999")
    assert code == 2 and "HOST[:PORT]" in err
    code, _, err = run(capsys, *base, "--llrp", "127.0.0.1", "--session", "7")
    assert code == 2 and "--session must be a Gen2 session from 0 to 3, got 7" in err
    code, _, err = run(capsys, *base, "--llrp", "127.0.0.1", "--param", "max_hypotheses=-1")
    assert code == 2 and "max_hypotheses" in err
    assert not (tmp_path / "r.csv").exists()


def test_live_with_no_reader_stops_at_its_duration(capsys, walls, tmp_path):
    start = time.monotonic()
    code, out, _ = run(capsys, "live", "--scene", walls / "scene.toml", "--llrp", f"127.0.0.1:{free_port()}", "--out", tmp_path / "t.csv", "--journal", tmp_path / "r.csv", "--duration", "0.5", "--no-progress")
    assert code == 0 and time.monotonic() - start < 3.0
    assert "never connected to the reader" in out and "0 reads of 0 tags" in out


def test_emulate_reader_needs_a_cots_scenario(capsys):
    code, _, err = run(capsys, "emulate-reader", "--scenario", "turbotrack-static", "--port", "0")
    assert code == 2 and "not a COTS reader scenario" in err


def test_live_writes_parquet_mcap_and_a_bag_and_serves_mqtt(capsys, walls, tmp_path):
    from robots import Subscriber, mosquitto_broker

    port = free_port()
    emulator = subprocess.Popen(
        [sys.executable, "-m", "scattertrack", "emulate-reader", "--scenario", "glac-3d-walls", "--port", str(port), "--speed", "10", "--linger", "0.5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        with mosquitto_broker(tmp_path) as broker:
            subscriber = Subscriber(broker)
            try:
                wait_listening(port, emulator)
                time.sleep(0.2)
                code, out, err = run(
                    capsys, "live", "--scene", walls / "scene.toml", "--llrp", f"127.0.0.1:{port}", "--out", tmp_path / "track.parquet", "--journal", tmp_path / "reads.csv",
                    "--duration", "2.5", "--no-progress", "--mcap", tmp_path / "live.mcap", "--ros2-bag", tmp_path / "bag", "--frame-id", "map",
                    "--transform", "1,0,0,1,0,0,0", "--foxglove", "0", "--mqtt-out", f"127.0.0.1:{broker}",
                )
                assert code == 0, err
                csv = read_track(tmp_path / "track.csv")  # the row-by-row record beside the Parquet twin
                messages = subscriber.wait_for(len(csv))
            finally:
                subscriber.close()
    finally:
        emulator.kill()
        emulator.communicate()
    assert code == 0, err
    assert len(csv) > 0 and len(messages) == len(csv)
    parquet = read_track(tmp_path / "track.parquet")
    assert (parquet.position == csv.position).all()
    assert f"wrote {2 * len(csv) + 1} ROS 2 messages on 3 topics to the MCAP file" in out and "to the ROS 2 bag" in out
    assert f"published {len(csv)} estimates to the MQTT broker" in out and "Foxglove WebSocket on ws://127.0.0.1:" in out


def test_live_refuses_bad_output_options_before_connecting(capsys, walls, tmp_path):
    base = ["live", "--scene", walls / "scene.toml", "--llrp", "127.0.0.1", "--out", tmp_path / "t.csv", "--journal", tmp_path / "r.csv"]
    code, _, err = run(capsys, *base, "--foxglove", "localhost")
    assert code == 2 and "[HOST:]PORT" in err
    code, _, err = run(capsys, *base, "--transform", "1,2,3")
    assert code == 2 and "--transform" in err
    (tmp_path / "bag").mkdir()
    code, _, err = run(capsys, *base, "--ros2-bag", tmp_path / "bag")
    assert code == 2 and "already exists" in err
    assert not (tmp_path / "r.csv").exists()
