"""``scattertrack stream``: a helper's SigMF recording through the real-time runtime.

    scattertrack stream --scene S --sigmf R [--calibration C] [--method turbotrack] --out T
                        [--speed X | --fast] [--layout team|per-antenna|shared] [--workers N]

Writes track.csv and prints the throughput and the latency from each
reply's arrival to its position, stage by stage.
"""

from __future__ import annotations

from scattertrack import outputs_command
from scattertrack.arguments import (
    UsageError,
    add_parameter_option,
    ascii_float,
    ascii_int,
    calibration_for,
    check_parameters,
    plural,
    say,
    tracker_parameters,
)
from scattertrack.reporting import format_duration, format_nanoseconds
from scattertrack.track_command import warn_about_geometry, write_track_file


def add_parser(commands) -> None:
    stream = commands.add_parser(
        "stream",
        help="run a helper's SigMF recording through the real-time runtime, with per-reply latency",
        description="Stream a SigMF recording of the localization helper through the multi-threaded runtime "
        "(capture -> per-antenna DSP workers -> fusion -> tracker) at the recording's speed or as fast as "
        "possible; write track.csv and print throughput and the latency from each reply's arrival to its position.",
    )
    stream.add_argument("--scene", required=True, help="scene.toml (a helper scene)")
    stream.add_argument("--sigmf", required=True, help="the recording (.sigmf-meta)")
    stream.add_argument("--calibration", help="calibration recording (default: calibration.sigmf-meta beside it)")
    stream.add_argument("--method", default="turbotrack", help="tracking method (default turbotrack)")
    stream.add_argument("--out", required=True, help="track.csv to write")
    pace = stream.add_mutually_exclusive_group()
    pace.add_argument("--speed", type=ascii_float, help="replay at this multiple of the recorded timing (default 1: live)")
    pace.add_argument("--fast", action="store_true", help="as fast as possible (throughput; latency then includes queueing)")
    stream.add_argument(
        "--layout", choices=("team", "per-antenna", "shared"), default="team",
        help="how antenna jobs meet threads: team (default; any thread takes any antenna, the one completing a reply "
        "fuses and tracks it), per-antenna (the thesis's pools and a fusion thread), shared (one pool, a fusion thread)",
    )
    stream.add_argument(
        "--workers", type=ascii_int,
        help="threads: in all for team and shared (default one per core), per antenna for per-antenna (default 1)",
    )
    stream.add_argument(
        "--prewake-us", type=ascii_float, default=1000.0,
        help="team at a paced speed: wake the idle workers this long before a reply is due to poll for it "
        "(default 1000; 0: they sleep until it arrives)",
    )
    stream.add_argument("--ema-alpha", type=ascii_float, help="EMA factor across each tag's channels (default: off)")
    add_parameter_option(stream)
    outputs_command.add_output_options(stream, files=False)
    stream.set_defaults(run=command_stream)


def command_stream(args) -> int:
    """``stream``: a helper recording through the real-time runtime."""
    from scattertrack import io
    from scattertrack import track as tracking
    from scattertrack.track.stream import stream_sigmf

    params = tracker_parameters(args.method, args.param)
    scene = io.read_scene(args.scene)
    if args.method not in tracking.WIDEBAND_METHODS:
        raise UsageError(f"stream runs the localization-helper methods ({', '.join(tracking.WIDEBAND_METHODS)}), not '{args.method}'")
    check_parameters(args.method, scene, params, args.scene)
    warn_about_geometry(scene, None)
    calibration = calibration_for(args)
    speed = None if args.fast else (1.0 if args.speed is None else args.speed)
    outputs = outputs_command.start_outputs(args, scene)  # before the run: clients can connect
    result = stream_sigmf(
        args.sigmf, scene, calibration, args.method, speed=speed,
        workers=args.workers, layout=args.layout, prewake_s=args.prewake_us * 1e-6, ema_alpha=args.ema_alpha, **params,
    )
    out = write_track_file(args.out, result.track)
    pacing = "as fast as possible" if speed is None else f"{speed:g} x the recording's timing"
    say(f"streamed {plural(result.replies, 'reply')} from {args.sigmf} ({pacing}), {args.method}: "
        f"wrote {plural(len(result.track), 'row')} to {out}")
    print_stream_summary(result)
    outputs_command.finish_outputs(outputs, result.track)
    return 0


def print_stream_summary(result) -> None:
    """What ``stream`` reports after the run: skips, throughput, latency, and where the time went."""
    say(f"  {result.track.skipped.summary()}")
    q = result.latency_percentile_ns
    say(f"  throughput: {result.frames_per_s:,.0f} frames/s ({format_duration(result.wall_s)} wall clock)")
    say(f"  latency, reply arrival to position: p50 {format_nanoseconds(q(0.5))}, p90 {format_nanoseconds(q(0.9))}, "
        f"p99 {format_nanoseconds(q(0.99))}, max {format_nanoseconds(q(1.0))}")
    if result.stage_ns.size:
        import numpy as np

        p50 = np.percentile(result.stage_ns, 50, axis=0)
        p99 = np.percentile(result.stage_ns, 99, axis=0)
        parts = ", ".join(
            f"{name} {format_nanoseconds(lo)}/{format_nanoseconds(hi)}" for name, lo, hi in zip(result.stages, p50, p99)
        )
        say(f"  where it went, p50/p99: {parts}")
