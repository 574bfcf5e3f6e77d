"""``scattertrack import FORMAT FILES... --scene S --out reads.csv``: reader logs into reads.csv.

The command-line face of :mod:`scattertrack.io.importers`: it prints the
columns used and their units, where the frequencies came from and one
summary line (rows kept, duplicates, reordered, declined by reason with
file and lines); input warnings print as ``warning:`` lines (cli.main).
"""

from __future__ import annotations

import argparse


def add_parser(commands) -> argparse.ArgumentParser:
    """Register the ``import`` subcommand on the ``commands`` subparsers of the main parser."""
    from scattertrack.io.importers import IMPORTERS

    parser = commands.add_parser(
        "import",
        help="convert reader logs (sllurp CSV, Impinj IoT JSON, I/Q phasors) into reads.csv",
        description="Read reader logs in FORMAT, convert them to SI units (docs/importers.md), decline and "
        "count malformed rows with their file and line, drop exact duplicates, sort by time and write "
        "reads.csv. Frequencies come from the rows, else the scene's [[hop_table]], else the US channel "
        "plan in index order (with a warning).",
    )
    parser.add_argument("format", choices=list(IMPORTERS), help="the log format")
    parser.add_argument("files", nargs="+", metavar="FILE", help="log files, read in this order")
    parser.add_argument("--scene", required=True, help="scene.toml (antennas, optional [[hop_table]])")
    parser.add_argument("--out", required=True, help="reads.csv to write")
    parser.set_defaults(run=run)
    return parser


def run(args) -> int:
    """Import, write, report; errors propagate to cli.main (exit code 2)."""
    from scattertrack import io
    from scattertrack.io.importers import import_files

    scene = io.read_scene(args.scene)
    reads, report = import_files(args.format, args.files, scene)
    io.write_reads(args.out, reads)
    for line in report.lines():
        print(line, flush=True)
    print(f"wrote {len(reads)} reads of {len(reads.epcs())} tag{'s' if len(reads.epcs()) != 1 else ''} to {args.out}",
          flush=True)
    return 0
