"""``scattertrack track`` on 10,000 tags: the streaming path against the in-memory one.

Writes a recording of ``--tags`` tags, each read ``--rate`` times a second
for each of ``--durations`` seconds (issue 21: 10,000 x 30 reads/s x 20, 60
and 120 s), straight from numpy: a tag per EPC circling (10 cm radius, 25 cm/s)
over the 4-antenna scene of ``glac-3d-arm``, one channel, 0.1 rad phase noise.
Then runs ``scattertrack track`` (a subprocess, CSV in and out) on each,
streaming, and with the in-memory path (``SCATTERTRACK_STREAM=0``) on the
recordings up to ``--in-memory-up-to`` seconds (it holds the whole
recording: about 7 GB for 20 s); prints reads/s end to end (parsing,
tracking and writing), the peak RSS of each run, and checks that both paths
wrote the same track.csv bytes.

    .venv/bin/python bench/many_tags.py [--quick] [--tags 10000] [--durations 20 60 120]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SPEED_OF_LIGHT = 299_792_458.0
FREQUENCY_HZ = 915.25e6
CIRCLE_RADIUS_M = 0.10
CIRCLE_SPEED_M_S = 0.25
ANTENNAS = np.array([[0.0, 0.0, 0.0], [0.30, 0.0, 0.0], [0.0, 0.80, 0.0], [0.80, 0.80, 0.0]])
SCENE = """\
name = "many-tags"
dimensions = 3

[reader]
kind = "cots"
phase_sign = 1
phase_period = "2pi"
phase_noise_rad = 0.1
""" + "".join(f"""
[[antennas]]
id = {k + 1}
position = [{x}, {y}, {z}]
phase_offset_rad = 0.0
""" for k, (x, y, z) in enumerate(ANTENNAS.tolist())) + """
[region]
min = [-0.2, -0.2, 0.1]
max = [1.2, 1.2, 1.4]
"""


def write_recording(path: Path, tags: int, rate_hz: float, duration_s: float, seed: int = 0) -> int:
    """reads.csv of ``tags`` tags read round-robin over the antennas; returns the number of reads."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(seed)
    # Each tag circles a centre of its own (radius 10 cm, 25 cm/s, a
    # horizontal circle): GLAC needs motion to resolve a tag.
    centre = rng.uniform([0.2, 0.2, 0.4], [0.7, 0.7, 0.9], size=(tags, 3))
    angular = CIRCLE_SPEED_M_S / CIRCLE_RADIUS_M * rng.choice([-1.0, 1.0], size=tags)
    phase0 = rng.uniform(0.0, 2.0 * np.pi, size=tags)
    offset = rng.uniform(0.0, 1.0 / rate_hz, size=tags)
    epcs = np.array([f"E2000000{k:08X}" for k in range(tags)], dtype=object)
    per_block = max(1, int(round(rate_hz)))  # one second of reads at a time keeps memory small
    reads = 0
    with open(path, "wb") as out:
        out.write(b"time_s,epc,antenna,frequency_hz,phase_rad\n")
        for second in range(int(np.ceil(duration_s))):
            k = np.arange(per_block)
            time_s = (second + k[None, :] / rate_hz + offset[:, None]).reshape(-1)
            tag = np.repeat(np.arange(tags), per_block)
            keep = time_s < duration_s
            time_s, tag = time_s[keep], tag[keep]
            order = np.argsort(time_s, kind="stable")
            time_s, tag = time_s[order], tag[order]
            antenna = (np.floor(time_s * rate_hz).astype(np.int64) + tag) % len(ANTENNAS)
            angle = phase0[tag] + angular[tag] * time_s
            position = centre[tag] + CIRCLE_RADIUS_M * np.column_stack([np.cos(angle), np.sin(angle), np.zeros(len(tag))])
            distance = np.linalg.norm(position - ANTENNAS[antenna], axis=1)
            phase = 4.0 * np.pi * FREQUENCY_HZ * distance / SPEED_OF_LIGHT + 0.1 * rng.standard_normal(len(tag))
            phase = np.mod(np.round(phase, 6), 2.0 * np.pi)
            table = pa.table({
                "time_s": np.round(time_s, 6), "epc": pa.array(epcs[tag], pa.string()),
                "antenna": antenna + 1, "frequency_hz": np.full(len(tag), FREQUENCY_HZ), "phase_rad": phase,
            })
            pacsv.write_csv(table, out, pacsv.WriteOptions(include_header=False, quoting_style="none"))
            reads += len(tag)
    return reads


def measured(command: list[str], env: dict, timeout_s: float | None = None) -> tuple[float, float, bool]:
    """(wall seconds, peak RSS GB, finished) of one command, run in its own watcher so the RSS is its own.

    A command still running after ``timeout_s`` is stopped: its figures are then lower bounds."""
    watcher = ("import resource, subprocess, sys, time; t = time.perf_counter(); p = subprocess.Popen(sys.argv[2:], "
               "stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)\n"
               "try:\n    err = p.communicate(timeout=float(sys.argv[1]) or None)[1]; code = p.returncode\n"
               "except subprocess.TimeoutExpired:\n    p.kill(); p.communicate(); err, code = '', 'timeout'\n"
               "print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, code); "
               "sys.stderr.write(err)")
    result = subprocess.run([sys.executable, "-c", watcher, str(timeout_s or 0), *command], capture_output=True, text=True, env=env)
    wall, rss_kib, code = result.stdout.split()
    if code not in ("0", "timeout"):
        raise SystemExit(f"{' '.join(command)} failed:\n{result.stderr}")
    return float(wall), int(rss_kib) / 2**20, code == "0"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tags", type=int, default=10_000)
    parser.add_argument("--rate", type=float, default=30.0, help="reads per second per tag")
    parser.add_argument("--durations", type=float, nargs="+", default=[20.0, 60.0, 120.0])
    parser.add_argument("--in-memory-up-to", type=float, default=20.0,
                        help="run the in-memory path on recordings up to this long, s (it needs ~7 GB for 20 s of 10,000 tags)")
    parser.add_argument("--in-memory-timeout", type=float, default=1800.0,
                        help="stop the in-memory run after this many seconds (its figures are then bounds)")
    parser.add_argument("--quick", action="store_true", help="1,000 tags, 10 and 20 s")
    args = parser.parse_args()
    if args.quick:
        args.tags, args.durations = 1000, [10.0, 20.0]
    cli = str(Path(sys.executable).with_name("scattertrack"))
    streaming_env = {**os.environ, "SCATTERTRACK_STREAM": "1"}
    in_memory_env = {**os.environ, "SCATTERTRACK_STREAM": "0"}
    print(f"scattertrack track, {args.tags:,} tags x {args.rate:g} reads/s, CSV in and out "
          f"({os.cpu_count()} cores; end to end: parsing, tracking, writing):")
    print(f"  {'recording':>10} {'reads':>12} {'path':>10} {'wall s':>8} {'reads/s':>10} {'peak RSS':>10}")
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        (root / "scene.toml").write_text(SCENE)
        written_s = 0.0
        # Streamed runs first (the figures asked for), then the in-memory ones, which may be stopped.
        compare = [d for d in args.durations if d <= args.in_memory_up_to]
        for duration in args.durations:
            reads_csv = root / f"reads_{duration:g}.csv"
            start = time.perf_counter()
            reads = write_recording(reads_csv, args.tags, args.rate, duration)
            written_s += time.perf_counter() - start
            base = [cli, "track", "--scene", str(root / "scene.toml"), "--reads", str(reads_csv), "--no-progress"]
            wall, rss, _ = measured(base + ["--out", str(root / f"stream_{duration:g}.csv")], streaming_env)
            print(f"  {duration:>8g} s {reads:>12,} {'streaming':>10} {wall:8.1f} {reads / wall:10,.0f} {rss:7.2f} GB")
            sys.stdout.flush()
            if duration not in compare:
                reads_csv.unlink()
                (root / f"stream_{duration:g}.csv").unlink()
            else:
                (root / f"reads_{duration:g}.txt").write_text(f"{reads} {wall} {rss}")
        for duration in compare:
            reads_csv = root / f"reads_{duration:g}.csv"
            reads, wall, rss = (float(x) for x in (root / f"reads_{duration:g}.txt").read_text().split())
            base = [cli, "track", "--scene", str(root / "scene.toml"), "--reads", str(reads_csv), "--no-progress"]
            old_wall, old_rss, finished = measured(base + ["--out", str(root / "memory.csv")], in_memory_env,
                                                   args.in_memory_timeout)
            bound = "" if finished else "> "
            print(f"  {duration:>8g} s {int(reads):>12,} {'in memory':>10} {bound + f'{old_wall:.1f}':>8} "
                  f"{('< ' if bound else '') + f'{reads / old_wall:,.0f}':>10} {bound + f'{old_rss:.2f}':>7} GB"
                  + ("" if finished else f"  (stopped after {args.in_memory_timeout:g} s)"))
            if finished:
                same = (root / f"stream_{duration:g}.csv").read_bytes() == (root / "memory.csv").read_bytes()
                verdict = f"track.csv {'identical' if same else 'DIFFERENT'}"
            else:
                verdict = "in-memory run stopped: tracks not compared"
            print(f"  {'':>10} streaming / in memory: {bound}{old_wall / wall:.2f}x the reads/s, "
                  f"{'< ' if bound else ''}{rss / old_rss:.2f}x the peak RSS; {verdict}")
            sys.stdout.flush()
    print(f"  (recordings written with numpy and pyarrow in {written_s:.0f} s, not counted)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
