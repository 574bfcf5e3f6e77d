"""``scattertrack batch`` on 100 recordings: a Dask LocalCluster of 2 workers against a sequential run.

Simulates ``--recordings`` recordings (``glac-3d-arm-5tags``, ``--duration`` s
each, seeds 0…N−1) into a temporary folder, tracks them with
``scattertrack batch --sequential`` and with ``--workers 2`` (a
LocalCluster on 127.0.0.1), checks that every track file is the same byte
for byte, and prints both wall times (start-up of the cluster included)
and their ratio.

    .venv/bin/python bench/batch.py [--recordings 100] [--duration 20]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from scattertrack.sim import load_scenario, simulate
from scattertrack.sim.simulation import write_simulation


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--duration", type=float, default=20.0)
    args = parser.parse_args()
    cli = str(Path(sys.executable).with_name("scattertrack"))
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        folders, reads = [], 0
        for seed in range(args.recordings):
            scenario = load_scenario("glac-3d-arm-5tags")
            scenario["duration_s"] = args.duration
            simulation = simulate(scenario, seed=seed)
            reads += len(simulation.reads)
            folders.append(str(write_simulation(simulation, root / f"rec{seed:03d}")))
        sequential = timed([cli, "batch", *folders, "--out-dir", str(root / "sequential"), "--sequential"])
        on_dask = timed([cli, "batch", *folders, "--out-dir", str(root / "dask"), "--workers", "2"])
        same = sum((root / "sequential" / Path(f).name / "track.csv").read_bytes() == (root / "dask" / Path(f).name / "track.csv").read_bytes() for f in folders)
    print(f"scattertrack batch, {args.recordings} recordings of glac-3d-arm-5tags ({args.duration:g} s, 5 tags, {reads:,} reads in all):")
    print(f"  sequential (one process): {sequential:.1f} s; Dask LocalCluster, 2 workers: {on_dask:.1f} s (cluster start-up included)")
    print(f"  ratio sequential / Dask: {sequential / on_dask:.2f}; tracks identical: {same}/{len(folders)}")
    return 0 if same == len(folders) else 1


if __name__ == "__main__":
    sys.exit(main())
