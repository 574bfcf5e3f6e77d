"""``scattertrack demo``: simulate, track with glac and evaluate in one go (``make demo``).

    scattertrack demo [--out DIR] [--scenario NAME] [--seed N]
"""

from __future__ import annotations

import argparse
import math

from scattertrack.arguments import ascii_float, ascii_int, plural, say, show_progress
from scattertrack.reporting import format_duration, format_millimetres, format_nanoseconds, read_rates, save_figures, write_json
from scattertrack.simulate_command import simulate_and_write
from scattertrack.track_command import run_tracker

DEMO_SCENARIO = "glac-3d-arm"
"""The scenario ``scattertrack demo`` (and so ``make demo``) runs by default."""


DEMO_OUT = "out/demo"
"""Where ``scattertrack demo`` writes its files by default."""


def add_parser(commands) -> None:
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


def command_demo(args) -> int:
    """``demo``: a scenario simulated, read back, tracked with glac, evaluated; a summary and the files."""
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
    print_demo_summary(report, simulation, result, reads, wall_s)
    say()
    files = [out / "scene.toml", out / "reads.csv", out / "truth.csv", out / "track.csv"]
    files += save_figures(report, simulation.truth, result, out)
    write_json(out / "report.json", report, scenario=simulation.scenario["name"], seed=simulation.seed)
    files.append(out / "report.json")
    say("files")
    for path in files:
        say(f"  {path}")
    return 0


def print_demo_summary(report, simulation, result, reads, wall_s: float) -> None:
    """The demo's summary: accuracy, convergence, when the true candidate won, reads, speed, latency, declined."""
    from scattertrack import eval as evaluation

    duration = float(simulation.scenario["duration_s"])
    tags = reads.epcs()
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
