"""``scattertrack track`` and ``scattertrack check-scene``: a recording tracked offline, a layout checked.

    scattertrack track --scene S --reads R|--frames F|--features F|--sigmf R [--imu I] [--calibration C]
                       [--method M] --out T [--param name=value ...]
    scattertrack check-scene SCENE [--reads R]

``track`` dispatches on the method's input: phase reads (glac...),
wideband frames of the localization helper (turbotrack..., from
frames.csv or a SigMF recording) or the drone's IMU and LoRa features
(marvel, ulocate). Before tracking it prints the geometry check's
warnings; after, the tracker's summary (declined reads, per-tag counts,
unresolved tags, speed).
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from scattertrack import outputs_command
from scattertrack.arguments import (
    UsageError,
    add_parameter_option,
    calibration_for,
    check_parameters,
    plural,
    say,
    show_progress,
    tracker_parameters,
)
from scattertrack.reporting import format_duration, format_nanoseconds, output_path
from scattertrack.track.plausibility import UNRESOLVED_SIGMA_M, unresolved_warnings  # noqa: F401 - cli's names

MAX_TAGS_LISTED = 10
"""Per-tag lines printed by ``track``; more tags are summarised in one line."""


def add_parser(commands) -> None:
    track = commands.add_parser(
        "track",
        help="track tags from a scene and reads, write track.csv",
        description="Track every tag in a reads.csv, causally (each estimate uses only reads at or "
        "before its time), and write track.csv. Rows out of time order are sorted; duplicates and "
        "reads the tracker declines are counted and reported.",
    )
    track.add_argument("--scene", required=True, help="scene.toml")
    source = track.add_mutually_exclusive_group(required=True)
    source.add_argument("--reads", help="reads.csv (COTS reader methods: glac...)")
    source.add_argument("--frames", help="frames.csv (localization-helper methods: turbotrack...)")
    source.add_argument("--features", help="features.csv (LoRa-backscatter pose features: marvel)")
    source.add_argument(
        "--sigmf",
        help="a SigMF IQ recording (.sigmf-meta): of the helper (turned into frames first), or of a LoRa "
        "controller (marvel, ulocate: turned into features first)",
    )
    track.add_argument("--imu", help="imu.csv (marvel, ulocate: the drone's inertial samples)")
    track.add_argument(
        "--calibration",
        help="with --sigmf: the calibration recording (default: calibration.sigmf-meta beside the recording)",
    )
    track.add_argument(
        "--method",
        help="tracking method (see 'scattertrack methods'); default: the main method of the input given, "
        "glac for --reads, turbotrack for --frames, marvel for --features; for --sigmf, marvel when the scene's "
        "reader is lora-backscatter, else turbotrack",
    )
    track.add_argument("--out", required=True, help="track.csv to write")
    track.add_argument(
        "--causal-out",
        help="marvel, ulocate: also write the causal track.csv, each epoch as the estimator gave it at its own "
        "time (what 'live' publishes); --out gets the revised track, each epoch as the fixed-lag smoother last "
        "revised it, smoother_lag_s (4 s) later (docs/marvel.md section 8)",
    )
    add_parameter_option(
        track, help="tracker parameter, repeatable (see 'scattertrack methods --params METHOD' or docs/parameters.md)"
    )
    outputs_command.add_output_options(track, files=True, live=False)
    track.add_argument("--no-progress", action="store_true", help="no progress bar")
    track.set_defaults(run=command_track)


def add_check_scene_parser(commands) -> None:
    check_scene = commands.add_parser(
        "check-scene",
        help="check that a COTS or helper scene's antenna layout fixes a tag's position",
        description="Search the region for twin positions that fit every phase a monostatic reader reports "
        "(three antennas on one line, all antennas in one plane, ...) and print one 'warning:' line per "
        "ambiguity (antennas, size in cm, remedy) and 'note:' lines for weaker findings; for a localization "
        "helper, warn about receive antennas in line with the transmitter; exit 0 either way.",
    )
    check_scene.add_argument("scene", help="scene.toml")
    check_scene.add_argument("--reads", help="reads.csv: analyse the channels it reads (calibrated hopping removes integer shifts)")
    check_scene.set_defaults(run=command_check_scene)


def command_track(args) -> int:
    """``track``: the method's input checked against the options, then tracked by its pipeline.

    One dispatch, on the registry's input kind (``scattertrack.track.methods``):
    each pipeline reads its files into the batch input ``st.track.run`` takes.
    """
    from scattertrack import io
    from scattertrack.track import marvel, methods

    if args.method:
        # Before reading anything: an unknown method or a bad value fails at once.
        params = tracker_parameters(args.method, args.param)
        scene = io.read_scene(args.scene)
    else:
        scene = io.read_scene(args.scene)
        args.method = default_method(args, scene.reader.kind)
        params = tracker_parameters(args.method, args.param)
    kind = methods.method(args.method).input
    if kind in ("features+imu", "sigmf+imu"):
        return track_marvel(args, scene, params)
    if args.features or args.imu:
        raise UsageError(f"--features and --imu are inputs of {', '.join(marvel.MARVEL_METHODS)}, not of '{args.method}'")
    if args.causal_out:
        raise UsageError(f"--causal-out is an output of {', '.join(marvel.MARVEL_METHODS)}, not of '{args.method}'")
    # Before reading the input: a typo should not wait for a large file to load.
    check_parameters(args.method, scene, params, args.scene)
    if kind == "frames" and args.reads:
        raise UsageError(f"method '{args.method}' tracks wideband frames: give --frames or --sigmf, not --reads")
    if kind == "reads" and not args.reads:
        raise UsageError(f"method '{args.method}' tracks phase reads: give --reads")
    return track_frames(args, scene, params) if kind == "frames" else track_reads(args, scene, params)


def default_method(args, reader_kind: str) -> str:
    """The method a user means when none is named: each pipeline's main method,
    chosen by the input file; a SigMF recording by the scene's reader (a LoRa
    controller's capture for marvel, a localization helper's for turbotrack)."""
    if args.features:
        return "marvel"
    if args.sigmf:
        return "marvel" if reader_kind == "lora-backscatter" else "turbotrack"
    if args.frames:
        return "turbotrack"
    return "glac"


def say_imu_noise(noise: dict | None, imu_path, stated_by_user=()) -> None:
    """The IMU's white noise as measured from its samples (and which density was used);
    a ``warning:`` line naming the IMU file where the user stated a density
    (``--param``) that the samples show too small. A default density is ours,
    not the user's claim: a noisier IMU is then only reported."""
    if not noise or noise.get("measured") is None:
        return
    from scattertrack.io.errors import warn_input

    names = (("accelerometer", "accel_noise_density", "m/s^2/sqrt(Hz)"), ("gyroscope", "gyro_noise_density", "rad/s/sqrt(Hz)"))
    rows = list(zip(names, noise["measured"], noise["used"], noise["stated"]))
    parts = [
        f"{name} {measured:.2e} {unit} ({'used instead of' if used != stated else 'agrees with'} {parameter} = {stated:.2e})"
        for (name, parameter, unit), measured, used, stated in rows
    ]
    say("  IMU white noise measured from its samples: " + "; ".join(parts))
    contradicted = [
        f"{parameter} = {stated:.2e} {unit} but the {name}'s samples show {measured:.2e} ({measured / stated:.1f}x)"
        for (name, parameter, unit), measured, used, stated in rows
        if used != stated and parameter in stated_by_user
    ]
    if contradicted and imu_path is not None:
        warn_input(
            imu_path, None, None,
            "the IMU is noisier than stated: " + "; ".join(contradicted)
            + "; tracked with the measured density (--param imu_noise_from_data=false keeps the stated one)",
        )


def track_reads(args, scene, params: dict) -> int:
    """``track`` for a COTS reader: reads.csv (and the ROS 2 files, if asked for)."""
    from scattertrack import io

    if streams(args) and track_streamed(args, scene, params):
        return 0
    reads = io.read_reads(args.reads, scene)
    say_reads_loaded(len(reads), len(reads.epcs()), args.reads, reads.reordered)
    warn_about_geometry(scene, reads)
    warn_unmodelled_reflectors(args.method, scene)
    ros2_out = bool(args.mcap or args.ros2_bag)
    transform = outputs_command.ros2_transform(args)
    result, wall_s = run_tracker(args.method, scene, reads, params, show_progress(args), covariance=ros2_out)
    say_tracked(args.method, result, write_track_file(args.out, result))
    outputs_command.write_ros2_files(args, result, scene, transform)
    say_if_no_estimates(result)
    print_tracker_summary(result, reads, wall_s)
    return 0


def streams(args) -> bool:
    """Whether ``track`` streams (reads.csv to track.csv, no ROS 2 output; ``SCATTERTRACK_STREAM=0``: never)."""
    from scattertrack.io.csvutil import is_parquet

    return not (args.mcap or args.ros2_bag or is_parquet(args.out)) and os.environ.get("SCATTERTRACK_STREAM", "1") != "0"


def track_streamed(args, scene, params: dict) -> bool:
    """``track`` as a stream (scattertrack.track.streaming), printing what the in-memory path prints;
    False (with a ``warning:`` line) when the file must be read whole."""
    from scattertrack.track import streaming

    outputs_command.ros2_transform(args)  # a bad --transform fails here too, though nothing uses it
    try:
        result = streaming.track_file(args.method, scene, args.reads, Path(args.out), params, unresolved_sigma_m=UNRESOLVED_SIGMA_M)
    except streaming.NeedsWholeFile as reason:
        say(f"warning: {args.reads}: {reason}: reading the whole file instead of streaming it")
        return False
    reads = result.reads
    say_reads_loaded(len(reads), len(reads.tags), args.reads, reads.reordered)
    warn_about_geometry(scene, reads)
    warn_unmodelled_reflectors(args.method, scene)
    say_tracked(args.method, result, Path(args.out), tags=result.tracked_tags)
    say_if_no_estimates(result)
    print_tracker_summary(result, reads, result.wall_s)
    return True


def say_reads_loaded(count: int, tags: int, path, reordered: int) -> None:
    """The lines after reading reads.csv: reads, tags, and rows sorted back into time order."""
    say(f"read {plural(count, 'read')} of {plural(tags, 'tag')} from {path}")
    say(f"  {reordered} rows out of time order (sorted, not dropped)")


def say_if_no_estimates(result) -> None:
    """Why a reads track came out empty."""
    if not len(result):
        say("  no estimates: no tag got past initialisation (it needs a few reads on at least 3 antennas)")


REFLECTOR_METHODS = ("glac", "glac-no-velocity", "glac-naive", "glac-sync", "glac-sync-no-velocity")
"""COTS methods whose measurement model takes the scene's ``[[reflectors]]`` (the apparent range, docs/glac.md)."""


def warn_unmodelled_reflectors(method: str, scene) -> None:
    """A ``warning:`` line when the scene declares reflectors that ``method`` does not model."""
    if scene.reader.kind == "cots" and scene.reflectors and method not in REFLECTOR_METHODS:
        say(
            f"warning: {method} does not model the scene's {plural(len(scene.reflectors), 'reflector')} (its ranges are direct); "
            f"{', '.join(REFLECTOR_METHODS)} do"
        )


def warn_about_geometry(scene, reads) -> None:
    """Before tracking a COTS scene: the geometry check's ``warning:`` lines
    (twin positions the layout cannot tell apart on the channels read);
    for a helper scene those of the helper check (receivers in line with the
    transmitter); nothing on a layout that fixes the position. Never stops the tracking."""
    from scattertrack import check

    if scene.reader.kind == "sdr-helper":
        for finding in check.check_helper_scene(scene).warnings:
            say(finding.line())
        return
    if scene.reader.kind != "cots":
        return
    from scattertrack.check.calibration import reflector_warnings

    for line in reflector_warnings(scene):
        say(line)
    try:
        result = check.check_scene(scene, reads)
    except ValueError as error:
        say(f"  geometry check skipped: {error}")
        return
    for finding in result.warnings:
        say(finding.line())


def command_check_scene(args) -> int:
    """``check-scene``: every finding of the geometry check, then whether the layout fixes the position."""
    from scattertrack import check, io

    scene = io.read_scene(args.scene)
    if scene.reader.kind == "sdr-helper" and not args.reads:
        for line in check.check_helper_scene(scene).lines():
            say(line)
        return 0
    if scene.reader.kind != "cots":
        raise UsageError(f"check-scene checks reader scenes ([reader] kind = \"cots\", or \"sdr-helper\" without "
                         f"--reads), not {scene.reader.kind!r}" + (" with --reads" if args.reads else ""))
    reads = io.read_reads(args.reads, scene) if args.reads else None
    from scattertrack.check.calibration import calibration_lines, reflector_warnings

    # What is not calibrated first; the geometry's verdict stays the last line.
    for line in calibration_lines(scene, reads) + reflector_warnings(scene):
        say(line)
    for line in check.check_scene(scene, reads).lines():
        say(line)
    return 0


def track_marvel(args, scene, params: dict) -> int:
    """``track`` for the drone pipeline: IMU plus features.csv (or a LoRa recording)."""
    from scattertrack import io
    from scattertrack.io import summary

    if args.reads or args.frames:
        raise UsageError(f"method '{args.method}' takes --imu with --features or --sigmf, not --reads or --frames")
    if not args.imu:
        raise UsageError(f"method '{args.method}' needs the drone's inertial samples: give --imu")
    if scene.reader.kind != "lora-backscatter":
        raise UsageError(f"method '{args.method}' needs a scene with [reader] kind = \"lora-backscatter\", not {scene.reader.kind!r}")
    imu = io.read_imu(args.imu)
    say(summary.imu_line(imu, args.imu))
    start = time.perf_counter()
    if args.sigmf:
        result, epochs = _drone_from_sigmf(args, scene, imu, params)
        source = args.sigmf
    else:
        result, epochs = _drone_from_features(args, scene, imu, params)
        source = args.features
    wall_s = time.perf_counter() - start
    # Offline, every epoch's best estimate is its revised row: the smoother
    # has seen the next smoother_lag_s of features and IMU (docs/marvel.md,
    # "The revised track": 25-40 % closer to the truth, as honest). Live
    # runs publish the causal rows.
    revised = result.revised if result.revised is not None else result
    out = write_track_file(args.out, revised)
    say(f"tracked with {args.method}: wrote {plural(len(revised), 'row')} to {out} (from {source}), each epoch "
        f"as the fixed-lag smoother last revised it ({lag_phrase(params)} later)")
    fallbacks = int(result.stats.get("drone", {}).get("revised_fallbacks", 0))
    if fallbacks:
        say(f"  {plural(fallbacks, 'row')} of them causal: the smoother restarted while they were in its window")
    if not len(result):
        say(f"  no estimates from {plural(epochs, 'epoch')}: what was declined, and why, is below")
    if args.causal_out:
        causal_out = write_track_file(args.causal_out, result)
        say(f"  causal track (each epoch at its own time, as live publishes it): {plural(len(result), 'row')} to {causal_out}")
    print_drone_summary(result, epochs, wall_s, args.imu, stated_by_user=set(params))
    return 0


def lag_phrase(params: dict) -> str:
    """How late a revised row is read, in words: about ``smoother_lag_s`` (given or the default)."""
    from scattertrack.fusion import MarvelParams

    return f"about smoother_lag_s = {float(params.get('smoother_lag_s', MarvelParams().smoother_lag_s)):g} s"


def _drone_from_sigmf(args, scene, imu, params: dict):
    """The drone tracked from a LoRa recording (``--sigmf``); the track and its epochs."""
    from scattertrack.io import timeline
    from scattertrack.io.sigmf_lora import open_lora_sigmf
    from scattertrack import track as tracking

    # Validated before the long run: a broken recording fails at once, naming its key.
    epochs = open_lora_sigmf(args.sigmf).epoch_time_s
    timeline.warn_outside_span(args.sigmf, epochs, None, args.imu, imu.time_s, "IMU sample",
                               column="captures.scattertrack:time_s", noun="epoch")
    result = tracking.run(args.method, scene, tracking.DroneData(imu, recording=args.sigmf), progress=show_progress(args), **params)
    return result, int(result.stats.get("drone", {}).get("epochs", len(result)))


def _drone_from_features(args, scene, imu, params: dict):
    """The drone tracked from features.csv (``--features``); the track and its epochs."""
    from scattertrack import io
    from scattertrack.io import summary, timeline
    from scattertrack import track as tracking
    from scattertrack.track import methods

    if methods.method(args.method).input == "sigmf+imu":
        raise UsageError(f"method '{args.method}' differs from marvel in the pose sensing: give --sigmf, not --features")
    features = io.read_features(args.features)
    say(summary.features_line(features, args.features))
    timeline.warn_outside_span(args.features, features.time_s, features.line, args.imu, imu.time_s, "IMU sample")
    result = tracking.run(args.method, scene, tracking.DroneData(imu, features), progress=show_progress(args), **params)
    return result, len(features)


def print_drone_summary(result, epochs: int, wall_s: float, imu_path=None, stated_by_user=()) -> None:
    """What ``track`` reports after tracking a drone: declined rows, the controller, the start,
    the IMU's noise, divergences, speed."""
    say(f"  {result.skipped.summary() if result.skipped.total else 'nothing declined'}")
    stats = result.stats.get("drone", {})
    controller = stats.get("controller")
    if controller is not None:
        say("  controller estimated at (" + ", ".join(f"{v:.2f}" for v in controller) + ") m")
    elif stats.get("controller_refused"):
        say(f"  controller estimate refused: {stats['controller_refused']}")
    rest = stats.get("rest")
    if rest:
        start = "at rest (ground factors)" if rest["state"] == "rest" else f"not at rest (failed check: {rest['failed_check']}; wide velocity prior)"
        dropped = f", {plural(rest['ground_factors_dropped'], 'ground factor')} dropped" if rest.get("ground_factors_dropped") else ""
        say(f"  start: {start}{dropped}")
    say_imu_noise(stats.get("imu_noise"), imu_path, stated_by_user)
    white = stats.get("feature_white_fraction")
    if white and white.get("measured_shares") is not None:
        range_f, direction_f = white["used"]
        say(
            f"  features' errors: white share f = {range_f:.2f} (range), {direction_f:.2f} (direction), measured over "
            f"{plural(white['measured_shares'][2], 'epoch pair')} (multipath_white_fraction = {white['stated']:g} until then)"
        )
    if "divergences" in stats:
        unrecovered = stats["divergences"] - stats.get("divergences_recovered", 0)
        say(
            f"  divergences: {stats['divergences']} (restarted from the features), "
            f"{stats.get('divergences_recovered', 0)} recovered, {unrecovered} not recovered"
        )
    q = result.latency_quantiles_ns
    rate = epochs / wall_s if wall_s > 0 else math.inf
    say(
        f"  speed: {rate:,.0f} epochs/s wall clock ({format_duration(wall_s)} for {epochs} epochs); "
        f"per epoch {format_nanoseconds(q.get('p50', 0))} p50, {format_nanoseconds(q.get('p99', 0))} p99"
    )


def track_frames(args, scene, params: dict) -> int:
    """``track`` for the localization helper: frames.csv or a SigMF recording."""
    from scattertrack import io
    from scattertrack import track as tracking
    from scattertrack.io import summary

    if args.sigmf:
        from scattertrack.dsp import read_sigmf_frames

        calibration = calibration_for(args)
        frames = read_sigmf_frames(args.sigmf, scene, calibration)
        source = args.sigmf
    else:
        frames = io.read_frames(args.frames, scene)
        source = args.frames
    for line in summary.frames_lines(frames, source):
        say(line)
    warn_about_geometry(scene, None)
    start = time.perf_counter()
    result = tracking.run(args.method, scene, frames, progress=show_progress(args), **params)
    wall_s = time.perf_counter() - start
    say_tracked(args.method, result, write_track_file(args.out, result))
    print_frames_summary(result, frames, wall_s)
    return 0


def print_frames_summary(result, frames, wall_s: float) -> None:
    """What ``track`` reports after tracking frames: skips, per-tag counts, speed."""
    say(f"  {result.skipped.summary()}")
    for epc, tag in list(result.stats.items())[:MAX_TAGS_LISTED]:
        say(
            f"  tag {epc}: {tag.get('measurements', 0)} frames, {tag.get('outliers', 0)} outliers, "
            f"{tag.get('reinitialisations', 0)} reinitialisations"
        )
    rate = frames.n_frames / wall_s if wall_s > 0 else math.inf
    line = f"  speed: {rate:,.0f} frames/s wall clock ({format_duration(wall_s)} for {frames.n_frames} frames)"
    if result.latency and result.latency[0]:
        _, mean_ns, max_ns = result.latency
        q = result.latency_quantiles_ns
        line += (
            f"; tracker step {format_nanoseconds(mean_ns)} mean, {format_nanoseconds(q.get('p50', 0))} p50, "
            f"{format_nanoseconds(q.get('p99', 0))} p99, {format_nanoseconds(max_ns)} max per frame"
        )
    say(line)


def write_track_file(path, result) -> Path:
    """``result`` written as a track.csv at ``path``, its folder made if need be; returns the path."""
    from scattertrack import io

    out = output_path(path)
    io.write_track(out, result)
    return out


def say_tracked(method: str, result, out: Path, tags: int | None = None) -> None:
    """The line after tracking tags: rows and tags written (``tags``, or counted from the track), and where."""
    if tags is None:
        tags = len(set(result.epc.tolist()))
    say(f"tracked with {method}: wrote {plural(len(result), 'row')} of {plural(tags, 'tag')} to {out}")


def run_tracker(method: str, scene, reads, params: dict, progress: bool, covariance: bool = False):
    """Track every tag; returns the Track and the wall-clock seconds the tracking took."""
    from scattertrack import track

    start = time.perf_counter()
    extra = {"covariance": True} if covariance else {}
    result = track.run(method, scene, reads, progress=progress, **extra, **params)
    return result, time.perf_counter() - start


def print_tracker_summary(result, reads, wall_s: float) -> None:
    """What ``track`` reports after tracking: skips, per-tag stats, speed."""
    say(f"  {result.skipped.summary()}")
    stats = result.stats
    for epc in list(stats)[:MAX_TAGS_LISTED]:
        tag = stats[epc]
        say(
            f"  tag {epc}: {tag.get('measurements', 0)} reads, "
            f"{tag.get('initialising', 0)} initialising, "
            f"{tag.get('reinitialisations', 0)} reinitialisations, "
            f"at most {tag.get('max_hypotheses', 0)} hypotheses"
        )
    streamed = getattr(result, "summary_warnings", None)  # a streamed track worked them out as it went
    for line in unresolved_warnings(result) if streamed is None else streamed:
        say(line)
    if streamed is None and reads is not None and hasattr(reads, "phase_rad"):
        from scattertrack.track.plausibility import implausible_speed_warnings

        for line in implausible_speed_warnings(result, reads):
            say(line)
    if len(stats) > MAX_TAGS_LISTED:
        rest = list(stats.values())[MAX_TAGS_LISTED:]
        say(
            f"  ... and {len(rest)} more tags: "
            f"{sum(t.get('reinitialisations', 0) for t in rest)} reinitialisations in all"
        )
    throughput = len(reads) / wall_s if wall_s > 0 else math.inf
    line = f"  speed: {throughput:,.0f} reads/s wall clock ({format_duration(wall_s)} for {len(reads)} reads)"
    latency = result.latency
    if latency and latency[0]:
        _, mean_ns, max_ns = latency
        line += f"; tracker step {format_nanoseconds(mean_ns)} mean, {format_nanoseconds(max_ns)} max per read"
    say(line)
