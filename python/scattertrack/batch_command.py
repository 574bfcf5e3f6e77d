"""``scattertrack batch``: many recordings tracked on a Dask cluster.

    scattertrack batch RECORDING [RECORDING ...] --out-dir DIR [--method glac] [--param NAME=VALUE]
                       [--workers N | --scheduler ADDRESS | --sequential] [--summary summary.csv]

A recording is a folder with ``scene.toml`` and ``reads.csv`` (what
``scattertrack simulate`` and the live journal write; Parquet twins are
read too). Each one is a task: read, track with ``st.track.run`` (the
same function ``scattertrack track`` uses, so a recording's
``DIR/<name>/track.csv`` is exactly what ``track`` writes for it), write.

Where the tasks run:

* default: a Dask ``LocalCluster`` on this machine, ``--workers`` processes
  (default: one per core) with one thread each, bound to 127.0.0.1, its
  dashboard off;
* ``--scheduler tcp://HOST:8786``: an existing cluster (``dask scheduler``
  on one machine, ``dask worker tcp://HOST:8786`` on each); the
  recordings' and ``--out-dir``'s paths must then be the same on every
  worker (a shared filesystem);
* ``--sequential``: in this process, one after the other (no Dask), the
  reference the cluster's results equal.

A recording that cannot be read or tracked is reported with its error
(file, line and column for a malformed file) and the others go on; the
exit status is then 1. ``--summary`` writes one row per recording.
"""

from __future__ import annotations

import csv
import os
import time
from pathlib import Path

from scattertrack.arguments import add_parameter_option, ascii_int, plural, say, tracker_parameters

SUMMARY_HEADER = ["recording", "status", "reads", "tags", "rows", "declined", "wall_s", "error"]


def add_parser(commands) -> None:
    batch = commands.add_parser(
        "batch",
        help="track many recordings (folders with scene.toml and reads.csv) on a Dask cluster",
        description="Track every recording (a folder with scene.toml and reads.csv) as one task on a Dask cluster: "
        "a LocalCluster on this machine by default, or --scheduler ADDRESS. Each recording's track goes to "
        "OUT_DIR/<folder name>/track.csv, exactly what `scattertrack track` writes for it.",
    )
    batch.add_argument("recordings", nargs="+", help="recording folders (each with scene.toml and reads.csv)")
    batch.add_argument("--out-dir", required=True, help="where each recording's track.csv goes (OUT_DIR/<name>/track.csv)")
    batch.add_argument("--method", default="glac", help="tracking method for phase reads (default glac)")
    add_parameter_option(batch)
    where = batch.add_mutually_exclusive_group()
    where.add_argument("--workers", type=ascii_int, help="LocalCluster worker processes (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://HOST:8786) instead of a LocalCluster")
    where.add_argument("--sequential", action="store_true", help="no Dask: one recording after the other in this process")
    batch.add_argument("--summary", help="summary.csv to write: one row per recording")
    batch.set_defaults(run=command_batch)


def track_recording(folder: str, out_dir: str, method: str, params: dict) -> dict:
    """One task: a recording's reads tracked and written; a dict for the summary
    (``status`` ``ok`` or ``error`` with the error's text), never an exception."""
    from scattertrack import io, track

    start = time.perf_counter()
    name = Path(folder).name
    row = {"recording": folder, "status": "ok", "reads": 0, "tags": 0, "rows": 0, "declined": 0, "wall_s": 0.0, "error": ""}
    try:
        scene = io.read_scene(_input(folder, "scene.toml"))
        reads = io.read_reads(_input(folder, "reads.csv"), scene)
        result = track.run(method, scene, reads, **params)
        out = Path(out_dir) / name / "track.csv"
        out.parent.mkdir(parents=True, exist_ok=True)
        io.write_track(out, result)
        row.update(reads=len(reads), tags=len(reads.epcs()), rows=len(result), declined=int(result.skipped.total))
    except (OSError, ValueError) as error:  # FormatError is a ValueError: it names the file, line and column
        row.update(status="error", error=str(error))
    row["wall_s"] = round(time.perf_counter() - start, 3)
    return row


def _input(folder: str, name: str) -> str:
    """``folder/name``, or its Parquet twin when only that is there."""
    path = Path(folder) / name
    twin = path.with_suffix(".parquet")
    return str(twin if not path.exists() and twin.exists() else path)


def command_batch(args) -> int:
    from scattertrack import track

    params = tracker_parameters(args.method, args.param)
    if track.REGISTRY[args.method].input != "reads":
        raise ValueError(f"batch tracks phase reads (reads.csv); method '{args.method}' takes {track.REGISTRY[args.method].input_files}")
    folders = [str(Path(r)) for r in args.recordings]
    missing = [f for f in folders if not Path(f).is_dir()]
    if missing:
        raise ValueError(f"not a recording folder: {', '.join(missing)}")
    names = [Path(f).name for f in folders]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"two recordings named {', '.join(twice)}: their tracks would overwrite each other in --out-dir")
    start = time.perf_counter()
    if args.sequential:
        say(f"batch: {plural(len(folders), 'recording')} in this process, one after the other")
        rows = [_report(track_recording(f, args.out_dir, args.method, params)) for f in folders]
    else:
        rows = _on_dask(folders, args, params)
    wall_s = time.perf_counter() - start
    failed = [r for r in rows if r["status"] != "ok"]
    say(f"batch: {plural(len(rows) - len(failed), 'recording')} tracked, {len(failed)} failed, {plural(sum(r['reads'] for r in rows), 'read')} in {wall_s:.1f} s; tracks in {args.out_dir}")
    if args.summary:
        Path(args.summary).parent.mkdir(parents=True, exist_ok=True)
        with open(args.summary, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, SUMMARY_HEADER)
            writer.writeheader()
            writer.writerows(sorted(rows, key=lambda r: folders.index(r["recording"])))
    return 1 if failed else 0


def _report(row: dict) -> dict:
    if row["status"] == "ok":
        say(f"  {row['recording']}: {plural(row['reads'], 'read')} of {plural(row['tags'], 'tag')}, {plural(row['rows'], 'row')}, {row['wall_s']:.2f} s")
    else:
        say(f"  {row['recording']}: error: {row['error']}")
    return row


def _on_dask(folders: list[str], args, params: dict) -> list[dict]:
    """Every recording as one task on the cluster, reported as it finishes."""
    import logging

    from dask.distributed import Client, LocalCluster, as_completed

    # distributed logs every worker's start and stop; the summary says what matters.
    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    if args.scheduler:
        client = Client(args.scheduler, timeout="10s")
        where = f"the Dask scheduler {args.scheduler}"
    else:
        workers = args.workers or os.cpu_count() or 1
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
        client = Client(cluster)
        where = f"a Dask LocalCluster of {plural(workers, 'worker')} on 127.0.0.1"
    try:
        say(f"batch: {plural(len(folders), 'recording')} on {where}")
        futures = [client.submit(track_recording, f, os.path.abspath(args.out_dir), args.method, params, key=f"track-{i}-{Path(f).name}", pure=False) for i, f in enumerate(folders)]
        return [_report(future.result()) for future in as_completed(futures)]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
