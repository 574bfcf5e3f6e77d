"""``scattertrack simulate``: a scenario simulated and written as a recording.

    scattertrack simulate --scenario NAME|FILE --out DIR [--seed N] [--duration S]
                          [--pipeline glac|turbotrack|marvel] [--iq]

A glac scenario writes reads.csv, a turbotrack one frames.csv (or, with
``--iq``, the helper's raw IQ as SigMF), a marvel one imu.csv and
features.csv (or, with ``--iq``, the controller's LoRa recording); each
with scene.toml, truth.csv and simulation.json.
"""

from __future__ import annotations

import math
from pathlib import Path

from scattertrack.arguments import UsageError, ascii_float, ascii_int, plural, say
from scattertrack.reporting import read_rates


def add_parser(commands) -> None:
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
