"""The ``scattertrack`` command: a thin layer over the Python API.

Subcommands::

    scattertrack simulate --scenario NAME|FILE --out DIR [--seed N] [--duration S] [--pipeline glac|turbotrack|marvel] [--iq]
    scattertrack scenarios
    scattertrack methods
    scattertrack track --scene S --reads R|--frames F|--sigmf R [--calibration C] [--method glac] --out T [--param name=value ...]
    scattertrack stream --scene S --sigmf R [--calibration C] [--method turbotrack] --out T [--speed X | --fast]
    scattertrack check-scene SCENE [--reads R]
    scattertrack import sllurp-csv|impinj-iot|iq-phasors FILE... --scene S --out R
    scattertrack eval --truth T --track K [--out DIR] [--json FILE] [--threshold-m 0.02]
    scattertrack demo [--out DIR] [--scenario NAME] [--seed N]
    scattertrack live --scene S --llrp HOST[:PORT] --out T --journal R [--duration S] [reader settings]
    scattertrack emulate-reader --scenario NAME [--port P] [--speed X] [--drop-after S]
    scattertrack calibrate --scene S --reads R --reference EPC=x,y,z [...] [--truth T] --out C
    scattertrack locate --scene S --reads R --out positions.csv
    scattertrack dashboard [--host 127.0.0.1] [--port 8050] [--token T]

Bad input never ends in a traceback: a malformed file, an unknown method or
parameter, or a missing file prints ``scattertrack: error: <message>`` on
stderr (the message names the file, line and column where it can) and
returns exit code 2. Output is plain ASCII so that it survives any terminal
encoding and log file.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from scattertrack.arguments import ascii_float, ascii_int, parse_parameter, plural, say, tracker_parameters
from scattertrack import batch_command, calibrate_command, live_command, locate_command, outputs_command
from scattertrack.server import command as dashboard_command

DEMO_SCENARIO = "glac-3d-arm"
"""The scenario ``scattertrack demo`` (and so ``make demo``) runs by default."""

DEMO_OUT = "out/demo"
"""Where ``scattertrack demo`` writes its files by default."""

MAX_TAGS_LISTED = 10
"""Per-tag lines printed by ``track``; more tags are summarised in one line."""

class UsageError(ValueError):
    """Bad command-line input that is not about a file (reported like any ValueError)."""


SEED_MAX = 2**63 - 1
"""Seeds must fit in a signed 64-bit integer (numpy's generators take any non-negative one)."""

OPTION_RANGES = {
    "duration": (lambda v: v > 0, "> 0 (seconds)"),
    "seed": (lambda v: 0 <= v <= SEED_MAX, f"an integer from 0 to {SEED_MAX}"),
    "speed": (lambda v: v > 0, "> 0 (a multiple of the recorded timing)"),
    "workers": (lambda v: 1 <= v <= 1024, "from 1 to 1024"),
    "prewake_us": (lambda v: 0 <= v <= 1e6, "in [0, 1e6] (microseconds)"),
    "ema_alpha": (lambda v: 0 < v <= 1, "in (0, 1]"),
    "threshold_m": (lambda v: v > 0, "> 0 (metres)"),
}
"""Allowed values of the numeric options, by argparse destination: checked for every command
before it runs, so a bad value never reaches a scenario file or the Rust core."""
OPTION_RANGES.update(live_command.OPTION_RANGES)


def check_options(args) -> None:
    """Refuse a numeric option outside its range, or a non-finite one (UsageError naming the option)."""
    for name, (allowed, description) in OPTION_RANGES.items():
        value = getattr(args, name, None)
        if value is None:
            continue
        finite = math.isfinite(value) if isinstance(value, float) else True
        if not finite or not allowed(value):
            raise UsageError(f"--{name.replace('_', '-')} must be {description}, got {value}")


def print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Input warnings as one ``warning: ...`` line on stderr; other warnings as Python shows them."""
    from scattertrack.io import InputWarning

    if issubclass(category, InputWarning):
        print(f"warning: {message}", file=sys.stderr, flush=True)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


# --- small helpers -------------------------------------------------------------


def show_progress(args) -> bool:
    """Progress bars only on a terminal: they would clutter logs and captured output."""
    return not getattr(args, "no_progress", False) and sys.stderr.isatty()


def format_duration(seconds: float) -> str:
    """A wall-clock time with sensible precision: '0.0042 s', '1.23 s', '75 s'."""
    if seconds < 0.1:
        return f"{seconds:.4f} s"
    if seconds < 10:
        return f"{seconds:.2f} s"
    return f"{seconds:.0f} s"


def format_nanoseconds(nanoseconds: float) -> str:
    """A latency in microseconds, or milliseconds when large ('3.6 us', '12.5 ms')."""
    if nanoseconds >= 1e6:
        return f"{nanoseconds / 1e6:.1f} ms"
    return f"{nanoseconds / 1e3:.1f} us"


def format_millimetres(metres: float) -> str:
    """A distance in mm, or 'n/a' for nan (no rows evaluated)."""
    return f"{metres * 1e3:.1f} mm" if math.isfinite(metres) else "n/a"


def check_parameters(method: str, scene, params: dict, scene_path=None) -> None:
    """Refuse parameters the tracker would refuse, before any input is read.

    ``params`` are already typed and in range (:func:`tracker_parameters`);
    building the tracker once more checks what one row cannot: combinations
    (likelihood=paper needs manoeuvre_q=none) and the scene's fitness. Its
    errors name the parameter.
    """
    from scattertrack import track

    try:
        track.make(method, scene, **params)
    except ValueError as error:
        # The core words what the scene lacks; the file it came from is ours to name.
        if scene_path is not None and str(error).startswith("invalid scene:"):
            raise ValueError(f"{scene_path}: {error}") from None
        raise


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


# A row is unresolved while its largest sigma exceeds this (m): a quarter
# of the λ/2 ≈ 16 cm candidate spacing, the scale at which competing
# candidate trajectories (or geometric twins) still carry weight.
UNRESOLVED_SIGMA_M = 0.04


def unresolved_warnings(result) -> list[str]:
    """One ``warning:`` line per tag whose track ends unresolved (its last
    row's largest sigma above :data:`UNRESOLVED_SIGMA_M`), saying how much
    of the track was; a tag that resolved says nothing."""
    if result.sigma is None or len(result) == 0:
        return []
    largest = np.nanmax(result.sigma, axis=1)
    unresolved = largest > UNRESOLVED_SIGMA_M
    # Per tag in one pass over the rows (a recording may hold thousands of
    # tags): its last row, its share of unresolved rows and its widest sigma.
    epcs, tag = np.unique(result.epc.astype(str), return_inverse=True)
    rows = np.arange(len(result))
    first, last = np.full(len(epcs), len(result)), np.zeros(len(epcs), dtype=int)
    np.minimum.at(first, tag, rows)
    np.maximum.at(last, tag, rows)
    widest = np.full(len(epcs), -np.inf)
    np.maximum.at(widest, tag, largest)
    share = np.bincount(tag, weights=unresolved, minlength=len(epcs)) / np.bincount(tag, minlength=len(epcs))
    lines = []
    for k in np.argsort(first, kind="stable"):  # in order of first appearance
        if unresolved[last[k]]:
            lines.append(
                f"warning: tag {epcs[k]}: the reads did not resolve its position: "
                f"{share[k] * 100:.0f} % of its rows, the last included, have a sigma above "
                f"{UNRESOLVED_SIGMA_M * 100:.0f} cm (up to {widest[k] * 100:.0f} cm); "
                "the sigmas cover the competing candidates, the position is the likeliest of them"
            )
    return lines


def run_tracker(method: str, scene, reads, params: dict, progress: bool, covariance: bool = False):
    """Track every tag; returns the Track and the wall-clock seconds the tracking took."""
    from scattertrack import track

    start = time.perf_counter()
    extra = {"covariance": True} if covariance else {}
    result = track.run(method, scene, reads, progress=progress, **extra, **params)
    return result, time.perf_counter() - start


def save_figures(report, truth, result, out_dir: Path, tag: str | None = None) -> list[Path]:
    """Write error_cdf.png and track.png into ``out_dir``; returns the files written."""
    from scattertrack import eval as evaluation

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    if report.overall.n:
        path = out_dir / "error_cdf.png"
        evaluation.save_error_cdf(report, path)
        written.append(path)
    else:
        say("  no rows could be evaluated: error_cdf.png not written")
    if len(result):
        path = out_dir / "track.png"
        evaluation.save_track_plot(truth, result, path, epc=tag)
        written.append(path)
    else:
        say("  the track has no rows: track.png not written")
    return written


def write_json(path: Path, report, **inputs) -> None:
    """The report as JSON, with the package version and the inputs (reproducibility)."""
    from scattertrack import __version__
    from scattertrack import eval as evaluation

    record = {"version": __version__, **inputs, **evaluation.report_to_dict(report)}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")


# --- subcommands ----------------------------------------------------------------


def simulate_and_write(args):
    """The scenario named by ``args.scenario`` (``args.duration`` overriding its
    length), simulated with ``args.seed`` and written to ``args.out``.

    ``args.pipeline`` (absent: ``"glac"``; None: the scenario's own) must
    match the scenario's ``pipeline``, else a UsageError says which it is."""
    from scattertrack import sim

    scenario = sim.load_scenario(args.scenario)
    wanted = getattr(args, "pipeline", "glac")
    declared = scenario.get("pipeline", "glac")
    if wanted is not None and wanted != declared:
        others = ", ".join(sim.list_scenarios(wanted)) or "none"
        raise UsageError(
            f"scenario {args.scenario} is for the {declared} pipeline, not {wanted} "
            f"({wanted} scenarios: {others})"
        )
    if args.duration is not None:
        scenario = scenario | {"duration_s": args.duration}
    simulation = sim.simulate(scenario, seed=args.seed)
    return simulation, sim.write_simulation(simulation, args.out)


def command_simulate(args) -> int:
    if getattr(args, "iq", False):
        return simulate_iq_and_write(args)
    simulation, out = simulate_and_write(args)
    if simulation.frames is not None:
        return report_frames(simulation, out, args)
    if simulation.features is not None:
        return report_marvel(simulation, out, args)
    reads = simulation.reads
    duration = float(simulation.scenario["duration_s"])
    tags = reads.epcs()
    say(f"wrote {out}: scene.toml, reads.csv, truth.csv, simulation.json")
    say(f"  scenario {simulation.scenario.get('name', args.scenario)}, seed {simulation.seed}, {duration:g} s")
    say(f"  {plural(len(reads), 'read')} of {plural(len(tags), 'tag')}: {read_rates(len(reads), len(tags), duration)}")
    return 0


def simulate_iq_and_write(args) -> int:
    """``simulate --iq``: the raw IQ (SigMF) of a turbotrack scenario's helper or a marvel scenario's controller."""
    from scattertrack import sim

    scenario = sim.load_scenario(args.scenario)
    declared = scenario.get("pipeline", "glac")
    if declared == "marvel" and args.pipeline in (None, "marvel"):
        return simulate_marvel_iq_and_write(args, scenario)
    if declared != "turbotrack" or (args.pipeline not in (None, "turbotrack")):
        raise UsageError(
            f"--iq simulates the raw IQ of a turbotrack scenario's helper or a marvel scenario's controller: "
            f"scenario {args.scenario} is for the {declared} pipeline"
        )
    simulation = sim.simulate_iq_scenario(scenario, seed=args.seed, duration_s=args.duration)
    out = sim.write_iq_simulation(simulation, args.out)
    replies = len(simulation.recording.meta["captures"])
    duration = sim.iq.IQ_DEFAULT_DURATION_S if args.duration is None else args.duration
    size = sum(f.stat().st_size for f in Path(out).glob("*.sigmf-data"))
    say(f"wrote {out}: recording.sigmf-meta/-data, calibration.sigmf-meta/-data, scene.toml, truth.csv, simulation.json")
    say(f"  scenario {scenario.get('name', args.scenario)} (turbotrack, IQ), seed {simulation.seed}, {duration:g} s")
    say(f"  {plural(replies, 'reply window')}, {size / 1e6:.1f} MB of samples; "
        f"track with: scattertrack stream --scene {out}/scene.toml --sigmf {out}/recording.sigmf-meta --out TRACK.csv")
    return 0


def simulate_marvel_iq_and_write(args, scenario: dict) -> int:
    """``simulate --iq`` for a marvel scenario: the controller's LoRa recording (ci16 SigMF) of
    the flight, with scene.toml, imu.csv, truth.csv and simulation.json (no features.csv: the
    pose sensing makes them from the recording). Duration: the scenario's unless --duration."""
    from scattertrack.sim import marvel

    if args.duration is not None:
        scenario = scenario | {"duration_s": args.duration}
    simulation, recording = marvel.simulate_marvel_iq(scenario, seed=args.seed)
    out = marvel.write_marvel_iq_simulation(simulation, recording, args.out)
    duration = float(simulation.scenario["duration_s"])
    size = (Path(out) / "recording.sigmf-data").stat().st_size
    snr = simulation.details["snr_db"]
    say(f"wrote {out}: recording.sigmf-meta/-data, scene.toml, imu.csv, truth.csv, simulation.json")
    say(f"  scenario {scenario.get('name', args.scenario)} (marvel, IQ), seed {simulation.seed}, {duration:g} s, "
        f"{plural(simulation.details['walls'], 'wall')}")
    say(f"  {plural(recording.n_epochs, 'sensing epoch')}, {size / 1e6:.1f} MB of samples; per-sample SNR "
        f"{snr['median']:.1f} dB median ({snr['min']:.1f} to {snr['max']:.1f}); {plural(len(simulation.imu), 'IMU sample')}")
    say(f"  track with: scattertrack track --method marvel --scene {out}/scene.toml --sigmf {out}/recording.sigmf-meta "
        f"--imu {out}/imu.csv --out TRACK.csv")
    return 0


def report_frames(simulation, out: Path, args) -> int:
    """What ``simulate`` says about a turbotrack scenario's frames."""
    frames = simulation.frames
    duration = float(simulation.scenario["duration_s"])
    tags = frames.epcs()
    helper = simulation.scene.extra.get("helper", {})
    receivers = sum(a.role == "rx" for a in simulation.scene.antennas)
    say(f"wrote {out}: scene.toml, frames.csv, truth.csv, simulation.json")
    name = simulation.scenario.get("name", args.scenario)
    say(f"  scenario {name} (turbotrack), seed {simulation.seed}, {duration:g} s")
    say(
        f"  {plural(frames.n_frames, 'frame')} of {plural(len(tags), 'tag')}: "
        f"{read_rates(frames.n_frames, len(tags), duration).replace('reads', 'frames')}; "
        f"{plural(receivers, 'receive antenna')}, {helper.get('n_subcarriers', '?')} subcarriers over "
        f"{helper.get('bandwidth_hz', math.nan) / 1e6:g} MHz"
    )
    return 0


def report_marvel(simulation, out: Path, args) -> int:
    """What ``simulate`` says about a marvel scenario's IMU and features."""
    duration = float(simulation.scenario["duration_s"])
    counts = simulation.details["counts"]
    say(f"wrote {out}: scene.toml, imu.csv, features.csv, truth.csv, simulation.json")
    name = simulation.scenario.get("name", args.scenario)
    say(f"  scenario {name} (marvel), seed {simulation.seed}, {duration:g} s, "
        f"{plural(simulation.details['walls'], 'wall')}")
    say(
        f"  {plural(len(simulation.imu), 'IMU sample')}; {plural(counts['rows'], 'feature row')} of "
        f"{counts['epochs']} epochs ({counts['rows_below_snr']} lost below the decoding SNR, "
        f"{counts['rows_without_yaw']} without yaw)"
    )
    return 0


def read_rates(count: int, tags: int, duration_s: float) -> str:
    """'29.0 reads/s' for one tag; 'x reads/s in all, y per tag' for several."""
    if duration_s <= 0:
        return "no duration"
    if tags <= 1:
        return f"{count / duration_s:.1f} reads/s"
    return f"{count / duration_s:.1f} reads/s in all, {count / duration_s / tags:.1f} per tag"


def command_scenarios(args) -> int:
    from scattertrack import FormatError, sim

    names = sim.list_scenarios("all")
    if not names:
        say(f"no scenarios in {sim.SCENARIOS_DIR}")
        return 0
    width = max(len(name) for name in names)
    pipeline_width = max(len(p) for p in sim.PIPELINES)
    for name in names:
        pipeline = sim.scenario_pipeline(name)
        try:
            description = sim.load_scenario(name).get("description", "")
        except FormatError as error:
            # One broken file must not hide the others.
            description = f"(invalid: {error})"
        say(f"{name.ljust(width)}  {pipeline.ljust(pipeline_width)}  {description}")
    return 0


def command_methods(args) -> int:
    """One line per method (name, description, input); ``--params NAME``: that method's table."""
    from scattertrack.track import methods, parameters

    if args.markdown:
        sys.stdout.write(parameters.markdown())
        return 0
    if args.params:
        methods.method(args.params)  # an unknown name is an error naming the known ones
        for line in parameters.plain_table(args.params):
            say(line)
        return 0
    width = max(len(name) for name in methods.METHODS)
    for m in methods.REGISTRY.values():
        say(f"{m.name.ljust(width)}  {m.description} (input: {m.input_files})")
    return 0


def command_track(args) -> int:
    from scattertrack import io

    from scattertrack import track as tracking
    from scattertrack.track import marvel

    # Before reading anything: an unknown method or a bad value fails at once.
    params = tracker_parameters(args.method, args.param)
    scene = io.read_scene(args.scene)
    if args.method in marvel.MARVEL_METHODS:
        return track_marvel(args, scene, params)
    if args.features or args.imu:
        raise UsageError(f"--features and --imu are inputs of {', '.join(marvel.MARVEL_METHODS)}, not of '{args.method}'")
    if args.revised_out:
        raise UsageError(f"--revised-out is an output of {', '.join(marvel.MARVEL_METHODS)}, not of '{args.method}'")
    # Before reading the input: a typo should not wait for a large file to load.
    check_parameters(args.method, scene, params, args.scene)
    wideband = args.method in tracking.WIDEBAND_METHODS
    if wideband and args.reads:
        raise UsageError(f"method '{args.method}' tracks wideband frames: give --frames or --sigmf, not --reads")
    if not wideband and not args.reads:
        raise UsageError(f"method '{args.method}' tracks phase reads: give --reads")
    if wideband:
        return track_frames(args, scene, params)
    if streams(args) and track_streamed(args, scene, params):
        return 0
    reads = io.read_reads(args.reads, scene)
    say(f"read {plural(len(reads), 'read')} of {plural(len(reads.epcs()), 'tag')} from {args.reads}")
    say(f"  {reads.reordered} rows out of time order (sorted, not dropped)")
    warn_about_geometry(scene, reads)
    ros2_out = bool(args.mcap or args.ros2_bag)
    transform = outputs_command.ros2_transform(args)
    result, wall_s = run_tracker(args.method, scene, reads, params, show_progress(args), covariance=ros2_out)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    io.write_track(out, result)
    say(f"tracked with {args.method}: wrote {plural(len(result), 'row')} of {plural(len(set(result.epc.tolist())), 'tag')} to {out}")
    outputs_command.write_ros2_files(args, result, scene, transform)
    if not len(result):
        say("  no estimates: no tag got past initialisation (it needs a few reads on at least 3 antennas)")
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
    say(f"read {plural(len(reads), 'read')} of {plural(len(reads.tags), 'tag')} from {args.reads}")
    say(f"  {reads.reordered} rows out of time order (sorted, not dropped)")
    warn_about_geometry(scene, reads)
    say(f"tracked with {args.method}: wrote {plural(len(result), 'row')} of {plural(result.tracked_tags, 'tag')} to {Path(args.out)}")
    if not len(result):
        say("  no estimates: no tag got past initialisation (it needs a few reads on at least 3 antennas)")
    print_tracker_summary(result, reads, result.wall_s)
    return True


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
    from scattertrack.check.calibration import calibration_lines

    # What is not calibrated first; the geometry's verdict stays the last line.
    for line in calibration_lines(scene, reads):
        say(line)
    for line in check.check_scene(scene, reads).lines():
        say(line)
    return 0


def track_marvel(args, scene, params: dict) -> int:
    """``track`` for the drone pipeline: IMU plus features.csv (or a LoRa recording)."""
    from scattertrack import io
    from scattertrack.io import summary, timeline
    from scattertrack.track import marvel, methods

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
        from scattertrack.io.sigmf_lora import open_lora_sigmf

        # Validated before the long run: a broken recording fails at once, naming its key.
        epochs = open_lora_sigmf(args.sigmf).epoch_time_s
        timeline.warn_outside_span(args.sigmf, epochs, None, args.imu, imu.time_s, "IMU sample",
                                   column="captures.scattertrack:time_s", noun="epoch")
        result = marvel.run_sigmf(args.method, scene, args.sigmf, imu, progress=show_progress(args), **params)
        epochs = int(result.stats.get("drone", {}).get("epochs", len(result)))
        source = args.sigmf
    else:
        if methods.method(args.method).input == "sigmf+imu":
            raise UsageError(f"method '{args.method}' differs from marvel in the pose sensing: give --sigmf, not --features")
        features = io.read_features(args.features)
        say(summary.features_line(features, args.features))
        timeline.warn_outside_span(args.features, features.time_s, features.line, args.imu, imu.time_s, "IMU sample")
        result = marvel.run_features(args.method, scene, imu, features, progress=show_progress(args), **params)
        epochs = len(features)
        source = args.features
    wall_s = time.perf_counter() - start
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    io.write_track(out, result)
    say(f"tracked with {args.method}: wrote {plural(len(result), 'row')} to {out} (from {source})")
    if not len(result):
        say(f"  no estimates from {plural(epochs, 'epoch')}: what was declined, and why, is below")
    if args.revised_out:
        revised_out = Path(args.revised_out)
        revised_out.parent.mkdir(parents=True, exist_ok=True)
        io.write_track(revised_out, result.revised)
        fallbacks = int(result.stats.get("drone", {}).get("revised_fallbacks", 0))
        say(
            f"  revised (fixed-lag smoothed) track: {plural(len(result.revised), 'row')} to {revised_out}"
            + (f", {fallbacks} of them causal (the smoother restarted while they were in its window)" if fallbacks else "")
        )
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
    return 0


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
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    io.write_track(out, result)
    say(f"tracked with {args.method}: wrote {plural(len(result), 'row')} of {plural(len(set(result.epc.tolist())), 'tag')} to {out}")
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
    return 0


def calibration_for(args) -> Path:
    """The calibration recording of ``--sigmf``: ``--calibration``, else a
    ``calibration.sigmf-meta`` beside the recording (as ``simulate --iq``
    writes it); without either a UsageError (uncalibrated channels carry the
    hardware response, which no tracker can use)."""
    if getattr(args, "calibration", None):
        return Path(args.calibration)
    beside = Path(args.sigmf).with_name("calibration.sigmf-meta")
    if beside.is_file() and beside.resolve() != Path(args.sigmf).resolve():
        say(f"  calibration: {beside}")
        return beside
    raise UsageError("give --calibration: a recording of a tag at rest at a known position (SigMF)")


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
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    io.write_track(out, result.track)
    pacing = "as fast as possible" if speed is None else f"{speed:g} x the recording's timing"
    say(f"streamed {plural(result.replies, 'reply')} from {args.sigmf} ({pacing}), {args.method}: "
        f"wrote {plural(len(result.track), 'row')} to {out}")
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
    outputs_command.finish_outputs(outputs, result.track)
    return 0


def command_eval(args) -> int:
    from scattertrack import eval as evaluation
    from scattertrack import io

    truth = io.read_truth(args.truth)
    result = io.read_track(args.track)
    if args.tag is not None and args.tag not in set(result.epc.tolist()):
        raise UsageError(f"--tag {args.tag}: {args.track} has no rows for this tag")
    report = evaluation.compare(truth, result, convergence_threshold_m=args.threshold_m)
    say(evaluation.format_report(report, title=f"{args.track} against {args.truth}"))
    out_dir = Path(args.out) if args.out else Path(args.track).parent
    for path in save_figures(report, truth, result, out_dir, tag=args.tag):
        say(f"wrote {path}")
    if args.json:
        write_json(Path(args.json), report, truth=str(args.truth), track=str(args.track))
        say(f"wrote {args.json}")
    return 0


def command_demo(args) -> int:
    from scattertrack import eval as evaluation
    from scattertrack import io

    simulation, out = simulate_and_write(args)
    duration = float(simulation.scenario["duration_s"])
    say(f"scattertrack demo: scenario {simulation.scenario['name']}, seed {simulation.seed}")
    description = simulation.scenario.get("description")
    if description:
        say(f"  {description}")

    # Track what was written, read back as a user's files would be.
    scene = io.read_scene(out / "scene.toml")
    reads = io.read_reads(out / "reads.csv", scene)
    tags = reads.epcs()
    say(
        f"simulated {duration:g} s: {plural(len(reads), 'read')} of {plural(len(tags), 'tag')} "
        f"({read_rates(len(reads), len(tags), duration)}) from {plural(len(scene.antennas), 'antenna')}"
    )
    result, wall_s = run_tracker("glac", scene, reads, {}, show_progress(args))
    io.write_track(out / "track.csv", result)

    report = evaluation.compare(simulation.truth, result)
    say()
    say(evaluation.format_report(report, title="accuracy of glac against the simulated truth"))
    say()
    overall = report.overall
    speedup = duration / wall_s if wall_s > 0 else math.inf
    say("summary")
    say(
        f"  accuracy   median 3D error {format_millimetres(overall.median_3d_m)}, "
        f"p90 {format_millimetres(overall.p90_3d_m)} over {plural(overall.n, 'estimate')}"
    )
    threshold_mm = report.convergence_threshold_m * 1e3
    if math.isfinite(overall.convergence_time_s):
        say(
            f"  converged  {overall.convergence_time_s:.2f} s after the motion started "
            f"(3D error below {threshold_mm:g} mm from then on)"
        )
    else:
        say(f"  converged  never (the 3D error did not stay below {threshold_mm:g} mm to the end)")
    # The candidate-level view: from when on the reported trajectory is the
    # true one (error well below the λ/2 ≈ 16 cm between candidates).
    wins = evaluation.compare(simulation.truth, result, convergence_threshold_m=0.05).overall.convergence_time_s
    if math.isfinite(wins):
        say(f"  candidate  the true trajectory won {wins:.2f} s after the motion started (3D error below 50 mm from then on)")
    else:
        say("  candidate  the true trajectory never held the lead to the end (3D error above 50 mm late in the run)")
    say(f"  reads      {len(reads)} ({read_rates(len(reads), len(tags), duration)})")
    say(
        f"  speed      tracked {duration:g} s of reads in {format_duration(wall_s)}: "
        f"{speedup:,.0f}x faster than real time"
    )
    latency = result.latency
    if latency and latency[0]:
        say(
            f"  latency    {format_nanoseconds(latency[1])} mean, {format_nanoseconds(latency[2])} max "
            "per read (tracker step)"
        )
    declined = result.skipped.summary().removeprefix("skipped ") if result.skipped.total else "none"
    say(f"  declined   {declined}")
    say()
    files = [out / "scene.toml", out / "reads.csv", out / "truth.csv", out / "track.csv"]
    files += save_figures(report, simulation.truth, result, out)
    write_json(out / "report.json", report, scenario=simulation.scenario["name"], seed=simulation.seed)
    files.append(out / "report.json")
    say("files")
    for path in files:
        say(f"  {path}")
    return 0


# --- argument parsing -----------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    from scattertrack import __version__

    parser = argparse.ArgumentParser(
        prog="scattertrack",
        description="Track RF backscatter (RFID) tags in 3D: simulate, track, evaluate.",
    )
    parser.add_argument("--version", action="version", version=f"scattertrack {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    simulate = commands.add_parser(
        "simulate",
        help="simulate a reader session: scene.toml, reads.csv, frames.csv or imu.csv + features.csv, truth.csv",
        description="Run a simulation scenario and write scene.toml, reads.csv (a COTS reader, glac "
        "scenarios), frames.csv (a reader + SDR helper, turbotrack scenarios) or imu.csv and features.csv "
        "(a drone with LoRa-backscatter tags, marvel scenarios), truth.csv and simulation.json.",
    )
    simulate.add_argument("--scenario", required=True, help="a named scenario (see 'scattertrack scenarios') or a TOML file")
    simulate.add_argument("--out", required=True, help="output folder")
    simulate.add_argument("--seed", type=ascii_int, help="random seed (default: the scenario's own)")
    simulate.add_argument("--duration", type=ascii_float, metavar="S", help="override the scenario's duration, seconds")
    simulate.add_argument(
        "--pipeline",
        choices=("glac", "turbotrack", "marvel"),
        default=None,
        help="check that the scenario is for this pipeline (default: the scenario's own)",
    )
    simulate.add_argument(
        "--iq",
        action="store_true",
        help="turbotrack scenarios: write the helper's raw IQ as SigMF (recording + calibration) instead of "
        "frames.csv (default duration 1 s: IQ is about 144 MB per second); marvel scenarios: the controller's "
        "LoRa recording (ci16 SigMF, about 4 MB per second) instead of features.csv",
    )
    simulate.set_defaults(run=command_simulate)

    scenarios = commands.add_parser("scenarios", help="list the named simulation scenarios and their pipeline")
    scenarios.set_defaults(run=command_scenarios)

    methods = commands.add_parser(
        "methods",
        help="list the tracking methods, or one method's parameters",
        description="One line per method: its name, what it does and its input. With --params METHOD: "
        "that method's parameters (name, type, default, range, unit, description), as docs/parameters.md.",
    )
    methods.add_argument("--params", metavar="METHOD", help="print this method's parameter table")
    methods.add_argument("--markdown", action="store_true", help="print every table as Markdown (docs/parameters.md)")
    methods.set_defaults(run=command_methods)

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
    track.add_argument("--method", default="glac", help="tracking method (see 'scattertrack methods'; default glac)")
    track.add_argument("--out", required=True, help="track.csv to write")
    track.add_argument(
        "--revised-out",
        help="marvel, ulocate: also write the fixed-lag smoothed track.csv (each epoch as last revised, "
        "about smoother_lag_s (6 s) later; docs/marvel.md section 8)",
    )
    track.add_argument(
        "--param",
        action="append",
        type=parse_parameter,
        metavar="NAME=VALUE",
        help="tracker parameter, repeatable (see 'scattertrack methods --params METHOD' or docs/parameters.md)",
    )
    outputs_command.add_output_options(track, files=True, live=False)
    track.add_argument("--no-progress", action="store_true", help="no progress bar")
    track.set_defaults(run=command_track)

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
    stream.add_argument("--param", action="append", type=parse_parameter, metavar="NAME=VALUE", help="tracker parameter, repeatable")
    outputs_command.add_output_options(stream, files=False)
    stream.set_defaults(run=command_stream)

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

    from scattertrack import import_command  # reader logs -> reads.csv, in its own module

    import_command.add_parser(commands)

    evaluate = commands.add_parser(
        "eval",
        help="compare a track with ground truth: errors, convergence, plots",
        description="Compare track.csv with truth.csv: median/p90 3D and per-axis error, velocity "
        "error, convergence time; saves error_cdf.png and track.png.",
    )
    evaluate.add_argument("--truth", required=True, help="truth.csv")
    evaluate.add_argument("--track", required=True, help="track.csv")
    evaluate.add_argument("--out", help="folder for the figures (default: the track's folder)")
    evaluate.add_argument("--json", help="also write the report as JSON to this file")
    evaluate.add_argument(
        "--threshold-m",
        type=ascii_float,
        default=0.02,
        help="convergence threshold on the 3D error, metres (default 0.02)",
    )
    evaluate.add_argument("--tag", help="the tag (epc) drawn in track.png (default: the first)")
    evaluate.set_defaults(run=command_eval)

    live_command.add_parsers(commands)
    calibrate_command.add_parser(commands)
    locate_command.add_parser(commands)
    batch_command.add_parser(commands)
    dashboard_command.add_parser(commands)

    demo = commands.add_parser(
        "demo",
        help="simulate, track and evaluate in one go",
        description="Simulate a robot arm moving a tagged item in front of a 4-antenna reader, "
        "track it with glac, evaluate, and save track.csv, error_cdf.png and track.png.",
    )
    demo.add_argument("--out", default=DEMO_OUT, help=f"output folder (default {DEMO_OUT})")
    demo.add_argument("--scenario", default=DEMO_SCENARIO, help=f"scenario (default {DEMO_SCENARIO})")
    demo.add_argument("--seed", type=ascii_int, help="random seed (default: the scenario's own)")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    # For tests: a short run. Hidden so that the demo stays a one-liner.
    demo.add_argument("--duration", type=ascii_float, help=argparse.SUPPRESS)
    demo.set_defaults(run=command_demo)
    return parser


def error_message(error: BaseException) -> str:
    """The text after 'scattertrack: error:' for an error caused by the user's input."""
    if isinstance(error, OSError) and error.filename is not None:
        reason = error.strerror or str(error)
        return f"{error.filename}: {reason[0].lower() + reason[1:] if reason else reason}"
    if isinstance(error, KeyError) and error.args:
        return str(error.args[0])  # str(KeyError) would add quotes
    return str(error)


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit:
        # argparse exits for --help (0) and usage errors (2); return the code so
        # that main() can be called in-process.
        return exit.code if isinstance(exit.code, int) else 2
    from scattertrack.io import InputWarning

    try:
        check_options(args)
        with warnings.catch_warnings():
            # Every input warning is shown, each on its own line (Python's default shows a text once).
            warnings.simplefilter("always", category=InputWarning)
            warnings.showwarning = print_warning
            return args.run(args)
    except BrokenPipeError:
        # The reader of our output went away (`scattertrack ... | head`): not an error of ours.
        sys.stdout = open(os.devnull, "w")
        return 0
    except (ValueError, KeyError, OSError) as error:
        # FormatError is a ValueError: its message already names file, line and column.
        print(f"scattertrack: error: {error_message(error)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("scattertrack: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
