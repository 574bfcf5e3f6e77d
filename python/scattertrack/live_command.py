"""``scattertrack live`` and ``scattertrack emulate-reader``: a real reader in.

    scattertrack live --scene S --llrp HOST[:PORT] --out track.csv|track.parquet --journal reads.csv
                      [--publish-reads HOST[:PORT] --shards N]
                      [--method glac] [--duration SECONDS] [--antennas 1,2,3,4]
                      [--tx-power-dbm P] [--reader-mode M] [--session N] [--search-mode N]
                      [--mcap FILE] [--ros2-bag DIR] [--frame-id F] [--transform x,y,z,qw,qx,qy,qz]
                      [--foxglove [HOST:]PORT] [--mqtt-out HOST[:PORT]]
    scattertrack live --scene S --mqtt-in HOST[:PORT] --shard K/N --out track.csv --journal reads.csv ...
    scattertrack emulate-reader --scenario NAME [--port P] [--speed X] [--drop-after S] [--seed N]

``live`` runs :class:`scattertrack.readers.live.LiveSession` (reads from a
reader; with ``--publish-reads`` also to their shards' MQTT topics, and
with no ``--out`` only journaled and published) or, with ``--mqtt-in``,
:class:`scattertrack.readers.mqtt_in.MqttReadsSession` (one shard's reads
from the broker) until
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
from scattertrack.arguments import (
    LLRP_PORT,
    add_parameter_option,
    ascii_float,
    ascii_int,
    host_and_port,
    plural,
    say,
    tracker_parameters,
)


def antenna_list(text: str) -> tuple[int, ...]:
    """``1,2,3,4``: antenna ports, 1-based."""
    ports = tuple(ascii_int(part.strip()) for part in text.split(",") if part.strip())
    if not ports or any(not 1 <= p <= 65535 for p in ports):
        raise argparse.ArgumentTypeError(f"expected antenna ports like 1,2,3,4, got {text!r}")
    return ports


def shard_spec(text: str) -> tuple[int, int]:
    """``K/N``: shard K (0-based) of N."""
    k, slash, n = text.partition("/")
    try:
        shard, shards = ascii_int(k.strip()), ascii_int(n.strip())
    except (argparse.ArgumentTypeError, ValueError):
        shard = shards = -1
    if not slash or not 1 <= shards <= 65536 or not 0 <= shard < shards:
        raise argparse.ArgumentTypeError(f"expected K/N with 0 <= K < N (e.g. 0/2), got {text!r}")
    return shard, shards


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
    source = live.add_mutually_exclusive_group(required=True)
    source.add_argument("--llrp", type=host_and_port, metavar="HOST[:PORT]", help=f"the reader (port {LLRP_PORT} by default)")
    source.add_argument("--mqtt-in", type=outputs_command.mqtt_address, metavar="HOST[:PORT]",
                        help="a worker: track the reads of one shard (--shard K/N) from this MQTT broker (scattertrack/reads/<K>)")
    live.add_argument("--shard", type=shard_spec, metavar="K/N", help="with --mqtt-in: this worker's shard K of N (0-based)")
    live.add_argument("--publish-reads", type=outputs_command.mqtt_address, metavar="HOST[:PORT]",
                      help="with --llrp: publish every journaled read to this MQTT broker, on its tag's shard topic scattertrack/reads/<K> "
                      "(K = CRC-32 of the upper-case EPC mod --shards), for --mqtt-in workers")
    live.add_argument("--shards", type=ascii_int, default=1, help="with --publish-reads: the number of shards (workers), default 1")
    live.add_argument("--out", help="track.csv to write (appended to if it exists); track.parquet: the CSV beside it as it goes, the Parquet twin at the end; "
                      "required unless --publish-reads (then without --out the reads are only journaled and published)")
    live.add_argument("--journal", required=True, help="reads.csv to append every received read to")
    live.add_argument("--method", default="glac", help="tracking method for phase reads (default glac)")
    add_parameter_option(live)
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


def _check_sources(args) -> None:
    """The option combinations of the reader, worker and publisher roles."""
    if args.mqtt_in and args.shard is None:
        raise ValueError("--mqtt-in needs --shard K/N (this worker's shard)")
    if args.shard is not None and not args.mqtt_in:
        raise ValueError("--shard goes with --mqtt-in (a worker); a reader process publishes with --publish-reads and --shards")
    if args.mqtt_in and (args.publish_reads or args.antennas or args.tx_power_dbm is not None or args.reader_mode is not None or args.search_mode is not None):
        raise ValueError("--mqtt-in takes reads from the broker: --publish-reads and the reader's settings do not apply")
    if not 1 <= args.shards <= 65536:
        raise ValueError(f"--shards must be from 1 to 65536, got {args.shards}")
    if args.shards != 1 and not args.publish_reads:
        raise ValueError("--shards goes with --publish-reads")
    if not args.out and not args.publish_reads:
        raise ValueError("--out is required (only a --publish-reads process may run without tracking)")


def command_live(args) -> int:
    from scattertrack import io, track
    from scattertrack.io.csvutil import is_parquet
    from scattertrack.readers.live import ReaderSettings
    from scattertrack.readers.outputs import LiveOutputs

    _check_sources(args)
    params = tracker_parameters(args.method, args.param)
    scene = io.read_scene(args.scene)
    # A bad parameter or method fails before connecting; without --out nothing is tracked.
    tracker = track.make(args.method, scene, **params) if args.out else None
    # Parquet has no append: the rows go to the CSV beside it as they come, the twin is made at the end.
    track_csv = None if not args.out else Path(args.out).with_suffix(".csv") if is_parquet(args.out) else Path(args.out)
    options = outputs_command.output_options(args, parquet=args.out if args.out and is_parquet(args.out) else None)
    if options.any and tracker is None:
        raise ValueError("the track outputs (--mcap, --ros2-bag, --foxglove, --mqtt-out) need --out (a tracked run)")
    for path in (args.out, args.journal, args.mcap, args.ros2_bag):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    # llrpkit logs every lost connection; the summary reports them instead.
    logging.getLogger("llrpkit").setLevel(logging.CRITICAL)
    settings = ReaderSettings(args.antennas, args.tx_power_dbm, args.reader_mode, args.session, args.search_mode)
    outputs = LiveOutputs(options, scene, track_csv) if options.any else None
    publisher = None
    try:
        if args.publish_reads and not args.mqtt_in:
            from scattertrack.io.mqtt import MqttPublisher

            publisher = MqttPublisher(*args.publish_reads)
        session = _open_session(args, scene, settings, track_csv, tracker, outputs, publisher)
    except BaseException:
        for opened in (outputs, publisher):
            if opened is not None:  # the session closes them, once it exists
                opened.close()
        raise
    say_live_start(args, track_csv, publisher, outputs, options)
    summary = asyncio.run(_run_until_interrupted(session))
    print_live_summary(summary, args)
    if publisher is not None:
        say(f"  published {plural(publisher.published, 'read')} to {plural(args.shards, 'shard')}")
    if outputs is not None:
        outputs_command.say_outputs(outputs)
    if summary.hop_table_hz:
        # Offline runs of the journal (import, calibrate, locate) read the carriers from it.
        scene_out = Path(args.scene_out) if args.scene_out else Path(args.journal).with_suffix(".scene.toml")
        dataclasses.replace(scene, hop_table=dict(summary.hop_table_hz)).save(scene_out)
        say(f"  wrote the scene with the reader's hop table ({plural(len(summary.hop_table_hz), 'channel')}) to {scene_out}")
    return 0


def say_live_start(args, track_csv, publisher, outputs, options) -> None:
    """What ``live`` says before it reads: the source, the journal, the track, and where reads and rows go."""
    host, port = args.llrp or args.mqtt_in
    role = f"shard {args.shard[0]} of {args.shard[1]} from the MQTT broker" if args.mqtt_in else "reader"
    say(f"live: {role} {host}:{port}, journal {args.journal}, track {track_csv or '(none: journal and publish only)'}" + (f", {args.duration:g} s" if args.duration else ", until Ctrl-C"))
    if publisher is not None:
        say(f"  publishing every read to the MQTT broker {args.publish_reads[0]}:{args.publish_reads[1]} on scattertrack/reads/<K>, {plural(args.shards, 'shard')}")
    if outputs is not None and outputs.foxglove is not None:
        say(f"  Foxglove WebSocket on ws://{options.foxglove[0]}:{outputs.foxglove.port}")


def _open_session(args, scene, settings, track_csv, tracker, outputs, publisher):
    """The session reading from the reader (``--llrp``, its reads published by ``publisher``
    unless None) or from an MQTT shard (``--mqtt-in``)."""
    host, port = args.llrp or args.mqtt_in
    progress = None if args.no_progress else _progress_line
    if args.mqtt_in:
        from scattertrack.readers.mqtt_in import MqttReadsSession

        shard, shards = args.shard
        return MqttReadsSession(scene, host, port, shard, shards, args.journal, track_csv, tracker, duration_s=args.duration, progress=progress, outputs=outputs)
    from scattertrack.readers.live import LiveSession

    return LiveSession(scene, host, port, args.journal, track_csv, tracker, settings=settings, duration_s=args.duration, progress=progress,
                       outputs=outputs, read_publisher=publisher, shards=args.shards)


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
    written = f"{plural(summary.estimates, 'estimate')} written to {args.out}" if args.out else "nothing tracked"
    say(f"live run {ended} after {summary.wall_s:.1f} s: {plural(summary.reads, 'read')} of {plural(len(summary.tags), 'tag')} journaled to {args.journal} ({summary.reads_per_s:,.0f} reads/s), {written}")
    if summary.reader:
        say(f"  reader: {summary.reader}" + (f"; hop table of {plural(len(summary.hop_table_hz), 'channel')}" if summary.hop_table_hz else ""))
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
