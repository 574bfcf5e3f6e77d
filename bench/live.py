"""The live LLRP path: throughput, reconnect time, live = offline.

The reader emulator (``scattertrack emulate-reader``, a child process: its
own interpreter, as a real reader is its own machine) serves a simulated
five-tag arm session in the Impinj encoding, faster than real time so that
the reports come in faster than ``live`` can take them; ``live`` runs
in-process. Printed:

* throughput: reads per second journaled and tracked between the first and
  the last read (target >= 1,000 reads/s through the LLRP path);
* the forced disconnect: the outage from losing the reader to its first
  report after reconnecting (backoff 0.1 s, then set-up again);
* exactly once: the reads the emulator sent against the journal's rows;
* live = offline: the largest difference between the live track and
  ``scattertrack.track.run`` on the journal, and both tracks' median 3D
  error against the truth.

With ``--outputs`` the same run also writes every live output (Parquet at
the end, MCAP, a ROS 2 bag) and serves them (a Foxglove WebSocket on a free
loopback port, MQTT to a ``mosquitto`` the bench starts on loopback), and
prints how many of each went out: compare its throughput with a run
without.

    .venv/bin/python bench/live.py [--speed 40] [--duration 60] [--outputs]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import logging
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from scattertrack import track
from scattertrack.track import parameters
from scattertrack.eval import compare
from scattertrack.io import read_reads, read_track
from scattertrack.readers.live import LiveSession
from scattertrack.readers.outputs import LiveOutputs, OutputOptions
from scattertrack.sim import load_scenario, simulate

SCENARIO = "glac-3d-arm-5tags"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def start_emulator(port: int, speed: float, duration_s: float, drop_after_s: float, seed: int) -> subprocess.Popen:
    scenario = Path(tempfile.mkdtemp()) / "scenario.toml"
    text = Path(load_scenario(SCENARIO)["source"]).read_text()
    scenario.write_text(re.sub(r"(?m)^duration_s = .*$", f"duration_s = {duration_s}", text, count=1))
    process = subprocess.Popen(
        [sys.executable, "-m", "scattertrack", "emulate-reader", "--scenario", str(scenario), "--port", str(port), "--speed", str(speed), "--drop-after", str(drop_after_s), "--seed", str(seed), "--linger", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                time.sleep(0.2)  # the probe held the emulator's one client slot
                return process
        time.sleep(0.05)
    process.kill()
    raise RuntimeError("the emulator did not start")


@contextlib.contextmanager
def mosquitto(folder: Path):
    """A loopback MQTT broker on a free port (yields the port)."""
    binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    port = free_port()
    (folder / "mosquitto.conf").write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    process = subprocess.Popen([binary, "-c", str(folder / "mosquitto.conf")], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10.0
        while True:
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError("mosquitto did not start")
            time.sleep(0.02)
        yield port
    finally:
        process.terminate()
        process.wait(5.0)


def read_back(folder: Path, live, offline) -> str:
    """The MCAP and the bag read with independent readers (``mcap`` +
    ``mcap_ros2.decoder``, ``rosbags``) against the live track.csv and the
    offline covariances of the journal."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from scattertrack.io import ros2

    poses: dict = {"MCAP": {}, "bag": {}}
    with open(folder / "track.mcap", "rb") as stream:
        for _, channel, _, decoded in make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            poses["MCAP"].setdefault(channel.topic, []).append(decoded)
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(folder / "bag") as reader:
        for connection, _, raw in reader.messages():
            poses["bag"].setdefault(connection.topic, []).append(store.deserialize_cdr(raw, connection.msgtype))
    parts = []
    for name, topics in poses.items():
        counts_match, worst_position, worst_covariance = True, 0.0, 0.0
        for epc in sorted(set(live.epc.astype(str))):
            mine = np.flatnonzero(live.epc.astype(str) == epc)
            for kind in ("pose", "odom"):
                counts_match &= len(topics.get(ros2.topic(epc, kind), [])) == len(mine)
            for message, i in zip(topics[ros2.topic(epc, "pose")], mine):
                p = message.pose.pose.position
                worst_position = max(worst_position, float(np.abs(np.array([p.x, p.y, p.z]) - live.position[i]).max()))
                covariance = np.array(message.pose.covariance).reshape(6, 6)[:3, :3]
                worst_covariance = max(worst_covariance, float(np.abs(covariance - offline.covariance[i][:3, :3]).max() / np.abs(offline.covariance[i][:3, :3]).max()))
        tags = len(set(live.epc.astype(str)))
        parts.append(f"{name}: {'pose and odom per tag = rows per tag' if counts_match else 'COUNTS DIFFER'} ({tags} tags), position to track.csv <= {worst_position:.1e} m, covariance to offline <= {worst_covariance:.1e} (relative)")
    return "; ".join(parts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=40.0, help="simulated seconds per wall second")
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--outputs", action="store_true", help="all live outputs on: Parquet, MCAP, ROS 2 bag, Foxglove, MQTT")
    args = parser.parse_args()
    logging.getLogger("llrpkit").setLevel(logging.CRITICAL)  # the forced disconnect is expected
    scenario = load_scenario(SCENARIO)
    scenario["duration_s"] = args.duration
    sim = simulate(scenario, seed=args.seed)
    folder = Path(tempfile.mkdtemp())
    port = free_port()
    drop_after = args.duration / 2
    with contextlib.ExitStack() as stack:
        outputs = None
        if args.outputs:
            broker = stack.enter_context(mosquitto(folder))
            options = OutputOptions(parquet=str(folder / "track.parquet"), mcap=str(folder / "track.mcap"), ros2_bag=str(folder / "bag"), foxglove=("127.0.0.1", 0), mqtt=("127.0.0.1", broker))
            outputs = LiveOutputs(options, sim.scene, folder / "track.csv")
        emulator = start_emulator(port, args.speed, args.duration, drop_after, args.seed)
        session = LiveSession(sim.scene, "127.0.0.1", port, folder / "reads.csv", folder / "track.csv", track.make("glac", sim.scene), duration_s=args.duration / args.speed + 3.0, outputs=outputs)
        summary = asyncio.run(session.run())
    served, _ = emulator.communicate(timeout=60)
    sent = int(re.search(r"sent (\d+) read", served).group(1))
    journal = read_reads(folder / "reads.csv")
    live = read_track(folder / "track.csv")
    offline = track.run("glac", sim.scene, journal, covariance=args.outputs, **parameters.live("glac", {}))
    difference = float(np.abs(live.position - offline.position).max()) if len(live) == len(offline) else float("nan")
    # The journal's clock is the emulated reader's: Unix epoch + simulated time.
    epoch_s = float(re.search(r"reader clock = simulated time \+ ([0-9.]+) s", served).group(1))
    live_on_sim_clock = dataclasses.replace(live, time_s=live.time_s - epoch_s)
    print(f"live LLRP path, {SCENARIO}: {args.duration:g} s simulated at {args.speed:g}x ({len(sim.reads) / (args.duration / args.speed):,.0f} reads/s offered), seed {args.seed}")
    print(f"  throughput: {summary.throughput_reads_per_s:,.0f} reads/s journaled and tracked (target >= 1,000)")
    if outputs is not None:
        print(f"  outputs on: {outputs.messages:,} ROS 2 messages in the MCAP and the bag each, {outputs.foxglove_published:,} served on Foxglove, {outputs.mqtt_published:,} estimates over MQTT, Parquet of {len(read_track(folder / 'track.parquet')):,} rows")
        print(f"  read back: {read_back(folder, live, offline)}")
    print(f"  exactly once: emulator sent {sent:,}, journal holds {len(journal):,}, duplicates declined {summary.declined.get('duplicate report (already received)', 0)}")
    outage = summary.outages_s[0] if summary.outages_s else float("nan")
    print(f"  forced disconnect at {drop_after:g} s simulated: back after {outage:.3f} s ({summary.connections} connections)")
    print(f"  live vs offline on the journal: {len(live)} vs {len(offline)} rows, largest position difference {difference:.2e} m")
    report = compare(sim.truth, live_on_sim_clock)
    print(f"  live track vs truth: median 3D {report.overall.median_3d_m * 1e3:.1f} mm over {len(live)} rows")
    return 0


if __name__ == "__main__":
    sys.exit(main())
