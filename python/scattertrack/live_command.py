"""``scattertrack live`` and ``scattertrack emulate-reader``: a real reader in.

    scattertrack live --scene S --llrp HOST[:PORT] --out track.csv|track.parquet --journal reads.csv
                      [--method glac] [--duration SECONDS] [--antennas 1,2,3,4]
                      [--tx-power-dbm P] [--reader-mode M] [--session N] [--search-mode N]
                      [--mcap FILE] [--ros2-bag DIR] [--frame-id F] [--transform x,y,z,qw,qx,qy,qz]
                      [--foxglove [HOST:]PORT] [--mqtt-out HOST[:PORT]]
    scattertrack emulate-reader --scenario NAME [--port P] [--speed X] [--drop-after S] [--seed N]

``live`` runs :class:`scattertrack.readers.live.LiveSession` until
``--duration`` (a hard wall-clock stop) or Ctrl-C, printing a progress line
a second on stderr, then its summary on stdout; exit 0. ``emulate-reader``
serves a simulated scenario as an Impinj reader on 127.0.0.1 (loopback
unless ``--host`` says otherwise) until its reads are all served.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import contextlib
import logging
import math
import signal
import sys
import time
from pathlib import Path

from scattertrack import outputs_command
from scattertrack.arguments import LLRP_PORT, ascii_float, ascii_int, host_and_port, parse_parameter, plural, say, tracker_parameters

def antenna_list(text: str) -> tuple[int, ...]:
    """``1,2,3,4``: antenna ports, 1-based."""
    ports = tuple(ascii_int(part.strip()) for part in text.split(",") if part.strip())
    if not ports or any(not 1 <= p <= 65535 for p in ports):
        raise argparse.ArgumentTypeError(f"expected antenna ports like 1,2,3,4, got {text!r}")
    return ports


def add_parsers(commands) -> None:
    """The two subcommands, on ``build_parser``'s subparsers."""
    live = commands.add_parser(
        "live",
        help="track tags live from an LLRP reader; journal every read",
        description="Connect to an LLRP reader (Impinj Octane extensions for phase, RSSI and Doppler), map "
        "every report to a read (the frequency from the reader's hop table and the report's channel index), "
        "append it to the journal (reads.csv, flushed), track causally and write track.csv as it goes. "
        "Reconnects with backoff. Ends after --duration seconds of wall-clock time or on Ctrl-C, with a summary.",
    )
    live.add_argument("--scene", required=True, help="scene.toml (the antennas' ids are the reader's ports)")
    live.add_argument("--llrp", required=True, type=host_and_port, metavar="HOST[:PORT]", help=f"the reader (port {LLRP_PORT} by default)")
    live.add_argument("--out", required=True, help="track.csv to write (appended to if it exists); track.parquet: the CSV beside it as it goes, the Parquet twin at the end")
    live.add_argument("--journal", required=True, help="reads.csv to append every received read to")
    live.add_argument("--method", default="glac", help="tracking method for phase reads (default glac)")
    live.add_argument("--param", action="append", type=parse_parameter, metavar="NAME=VALUE", help="tracker parameter, repeatable")
    live.add_argument("--duration", type=ascii_float, help="stop after this many seconds of wall-clock time")
    live.add_argument("--antennas", type=antenna_list, default=(), help="antenna ports to read, e.g. 1,2,3,4 (default: all)")
    live.add_argument("--tx-power-dbm", type=ascii_float, help="transmit power, dBm (default: the reader's)")
    live.add_argument("--reader-mode", type=ascii_int, help="RF mode index (Impinj AutoSet modes are 1000 and up)")
    live.add_argument("--session", type=ascii_int, default=1, help="Gen2 session 0-3 (default 1)")
    live.add_argument("--search-mode", type=ascii_int, help="Impinj search mode (1 single, 2 dual target, 3 TagFocus)")
    live.add_argument("--scene-out", help="the scene with the reader's hop table ([[hop_table]]) to write (default: beside the journal, JOURNAL.scene.toml)")
    live.add_argument("--no-progress", action="store_true", help="no progress line")
    outputs_command.add_output_options(live, files=True)
    live.set_defaults(run=command_live)

    emulate = commands.add_parser(
        "emulate-reader",
        help="serve a simulated scenario as an Impinj LLRP reader on loopback",
        description="An LLRP reader emulator: speaks LLRP on HOST:PORT and reports the reads of a simulated "
        "scenario in the Impinj encoding (phase 0-4095, Doppler in 1/16 Hz, a shuffled hop table and channel "
        "indices). Runs until the scenario's reads are served (or Ctrl-C).",
    )
    emulate.add_argument("--scenario", required=True, help="scenario name or TOML file (a glac scenario)")
    emulate.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: loopback only)")
    emulate.add_argument("--port", type=ascii_int, default=LLRP_PORT, help=f"port (default {LLRP_PORT}; 0 picks a free one)")
    emulate.add_argument("--seed", type=ascii_int, default=None, help="simulation seed (default: the scenario's)")
    emulate.add_argument("--speed", type=ascii_float, default=1.0, help="simulated seconds per wall-clock second (default 1)")
    emulate.add_argument("--drop-after", type=ascii_float, help="close the client's connection once, after this many simulated seconds")
    emulate.add_argument("--linger", type=ascii_float, default=2.0, help="seconds to keep serving the protocol after the last read (default 2)")
    emulate.set_defaults(run=command_emulate_reader)


OPTION_RANGES = {
    "port": (lambda v: 0 <= v <= 65535, "a TCP port from 0 to 65535"),
    "tx_power_dbm": (lambda v: -10 <= v <= 40, "in [-10, 40] (dBm)"),
    "reader_mode": (lambda v: 0 <= v <= 65535, "an RF mode index from 0 to 65535"),
    "session": (lambda v: 0 <= v <= 3, "a Gen2 session from 0 to 3"),
    "search_mode": (lambda v: 0 <= v <= 6, "an Impinj search mode from 0 to 6"),
    "drop_after": (lambda v: v > 0, "> 0 (simulated seconds)"),
    "linger": (lambda v: v >= 0, ">= 0 (seconds)"),
}
"""The ranges of these commands' numeric options (merged into ``cli.OPTION_RANGES``)."""


def _progress_line(session) -> None:
    s = session.summary
    rate = s.reads / s.wall_s if s.wall_s > 0 else 0.0
    parts = [f"{s.wall_s:6.1f} s", f"{s.reads:,} reads ({rate:,.0f}/s)", plural(len(s.tags), "tag")]
    if session._lost_at is not None:
        parts.append(f"reconnecting ({time.monotonic() - session._lost_at:.1f} s)")
    for epc, estimate in list(session.last_estimate.items())[:3]:
        sigma = max(math.sqrt(max(estimate.covariance[k, k], 0.0)) for k in range(3))
        state = "resolving" if sigma > 0.04 else "tracking"
        parts.append(f"{epc}: {state}, sigma {sigma * 1e3:.0f} mm, {estimate.hypotheses} hyp")
    print("  ".join(parts), file=sys.stderr, flush=True)


def command_live(args) -> int:
    from scattertrack import io, track
    from scattertrack.io.csvutil import is_parquet
    from scattertrack.readers.live import LiveSession, ReaderSettings
    from scattertrack.readers.outputs import LiveOutputs

    params = tracker_parameters(args.method, args.param)
    scene = io.read_scene(args.scene)
    tracker = track.make(args.method, scene, **params)  # a bad parameter or method fails before connecting
    host, port = args.llrp
    # Parquet has no append: the rows go to the CSV beside it as they come, the twin is made at the end.
    track_csv = Path(args.out).with_suffix(".csv") if is_parquet(args.out) else Path(args.out)
    options = outputs_command.output_options(args, parquet=args.out if is_parquet(args.out) else None)
    for path in (args.out, args.journal, args.mcap, args.ros2_bag):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    # llrpkit logs every lost connection; the summary reports them instead.
    logging.getLogger("llrpkit").setLevel(logging.CRITICAL)
    settings = ReaderSettings(args.antennas, args.tx_power_dbm, args.reader_mode, args.session, args.search_mode)
    progress = None if args.no_progress else _progress_line
    outputs = LiveOutputs(options, scene, track_csv) if options.any else None
    try:
        session = LiveSession(scene, host, port, args.journal, track_csv, tracker, settings=settings, duration_s=args.duration, progress=progress, outputs=outputs)
    except BaseException:
        if outputs is not None:  # the session closes them, once it exists
            outputs.close()
        raise
    say(f"live: {host}:{port}, journal {args.journal}, track {track_csv}" + (f", {args.duration:g} s" if args.duration else ", until Ctrl-C"))
    if outputs is not None and outputs.foxglove is not None:
        say(f"  Foxglove WebSocket on ws://{options.foxglove[0]}:{outputs.foxglove.port}")
    summary = asyncio.run(_run_until_interrupted(session))
    print_live_summary(summary, args)
    if outputs is not None:
        outputs_command.say_outputs(outputs)
    if summary.hop_table_hz:
        # Offline runs of the journal (import, calibrate, locate) read the carriers from it.
        scene_out = Path(args.scene_out) if args.scene_out else Path(args.journal).with_suffix(".scene.toml")
        dataclasses.replace(scene, hop_table=dict(summary.hop_table_hz)).save(scene_out)
        say(f"  wrote the scene with the reader's hop table ({plural(len(summary.hop_table_hz), 'channel')}) to {scene_out}")
    return 0


def _stop_event() -> asyncio.Event:
    """An event that Ctrl-C (SIGINT) or SIGTERM sets, for a clean end with a summary."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    with contextlib.suppress(NotImplementedError, RuntimeError):  # no signals off the main thread
        loop.add_signal_handler(signal.SIGINT, stop.set)
        loop.add_signal_handler(signal.SIGTERM, stop.set)
    return stop


async def _run_until_interrupted(session):
    return await session.run(_stop_event())


def print_live_summary(summary, args) -> None:
    ended = {"duration": f"--duration {args.duration:g} s reached", "stop": "interrupted"}.get(summary.stopped_by, "ended")
    say(f"live run {ended} after {summary.wall_s:.1f} s: {plural(summary.reads, 'read')} of {plural(len(summary.tags), 'tag')} journaled to {args.journal} ({summary.reads_per_s:,.0f} reads/s), {plural(summary.estimates, 'estimate')} written to {args.out}")
    if summary.reader:
        say(f"  reader: {summary.reader}; hop table of {plural(len(summary.hop_table_hz), 'channel')}")
    declined = sum(summary.declined.values())
    say(f"  declined {plural(declined, 'report')}" + (": " + "; ".join(f"{n} {reason}" for reason, n in summary.declined.most_common()) if declined else ""))
    reconnects = len(summary.outages_s)
    if summary.connections == 0:
        say(f"  never connected to the reader: {summary.errors[-1] if summary.errors else 'no answer'}")
    elif reconnects or summary.connections > 1:
        worst = max(summary.outages_s) if summary.outages_s else math.nan
        say(f"  {plural(summary.connections, 'connection')}, {plural(reconnects, 'reconnect')} (longest outage {worst:.2f} s); why they ended: {'; '.join(dict.fromkeys(summary.errors))}")
    for epc, count in list(summary.tags.items())[:10]:
        say(f"  tag {epc}: {plural(count, 'read')}")


def command_emulate_reader(args) -> int:
    from scattertrack.readers.emulator import SimulatedReader
    from scattertrack.sim import load_scenario, simulate

    scenario = load_scenario(args.scenario)
    simulation = simulate(scenario, seed=args.seed)
    if getattr(simulation, "reads", None) is None:
        raise ValueError(f"scenario {args.scenario!r} is not a COTS reader scenario (no reads to serve)")
    emulator = SimulatedReader(simulation.reads, host=args.host, port=args.port, speed=args.speed, drop_after_s=args.drop_after, seed=scenario.get("seed", 1) if args.seed is None else args.seed)
    logging.getLogger("llrpkit").setLevel(logging.CRITICAL)
    return asyncio.run(_serve(emulator, simulation, args))


async def _serve(emulator, simulation, args) -> int:
    stop = _stop_event()
    await emulator.start()
    say(f"emulate-reader: LLRP on {args.host}:{emulator.port}, {plural(len(simulation.reads), 'read')} of {plural(len(simulation.reads.epcs()), 'tag')} over {simulation.reads.time_s.max():.1f} s at {args.speed:g}x")
    say(f"emulate-reader: reader clock = simulated time + {emulator.epoch_us / 1e6:.6f} s (Unix epoch)")
    try:
        while not stop.is_set():
            if emulator.finished:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), args.linger)
                break
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.1)
    finally:
        await emulator.stop()
    say(f"emulate-reader: sent {plural(len(emulator.sent), 'read')}, {emulator.unsent} not read while no inventory ran, {plural(emulator.drops, 'forced disconnect')}")
    return 0
