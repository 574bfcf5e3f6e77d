"""``scattertrack calibrate``: offsets, sign, period, hop table, path loss and walls from reference tags.

    scattertrack calibrate --scene S --reads R --reference EPC=x,y,z [EPC=x,y,z ...]
                           [--truth truth.csv] [--reflector-search-m 0.3]
                           [--find-walls [--wall-reach-m 2]] --out calibrated.toml

Prints what it estimated and how well the calibrated model explains the
references (docs/calibration.md says how to read it), writes the
calibrated scene, and a ``warning:`` line for what the references could
not decide (phase unusable in this room, a barely decided sign, channel
indices a neighbouring carrier fits as well, a declared reflector the
references do not pin down).
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from scattertrack.arguments import ascii_float, plural, say
from scattertrack.reporting import output_path


def reference(text: str) -> tuple[str, np.ndarray]:
    """``EPC=x,y,z`` (metres)."""
    epc, equals, position = text.partition("=")
    parts = position.split(",")
    if not equals or not epc.strip() or len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected EPC=x,y,z (metres), got {text!r}")
    try:
        values = np.array([ascii_float(p.strip()) for p in parts])
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(f"{text!r}: {error}") from None
    if not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"{text!r}: the position must be finite")
    return epc.strip(), values


def search_distance(text: str) -> float:
    """A reflector search half-width: 0.01-2 m (beyond 2 m the wall is not the one declared)."""
    value = ascii_float(text)
    if not 0.01 <= value <= 2.0:
        raise argparse.ArgumentTypeError(f"must be between 0.01 and 2 m, got {text}")
    return value


def reach_distance(text: str) -> float:
    """How far to look for walls: 0.1-5 m."""
    value = ascii_float(text)
    if not 0.1 <= value <= 5.0:
        raise argparse.ArgumentTypeError(f"must be between 0.1 and 5 m, got {text}")
    return value


def add_parser(commands) -> None:
    calibrate = commands.add_parser(
        "calibrate",
        help="estimate phase offsets, sign, period, hop table and RSSI path loss from reference tags",
        description="Calibrate a scene from reads of reference tags at known positions (--reference) or on a "
        "known trajectory (--truth): per-antenna and per-channel phase offsets (identifiable only as sums), the "
        "phase sign, a mod-pi reader, the hop table when the reads carry channel indices and the scene has none, "
        "and per-antenna RSSI path loss; refines the reflectors the scene declares ([[reflectors]]: each plane's offset "
        "along its normal and each coefficient) or leaves out those the references cannot pin down, and with "
        "--find-walls looks for walls nobody declared. Prints residuals "
        "and the phase coherence; writes the calibrated scene.",
    )
    calibrate.add_argument("--scene", required=True, help="scene.toml (positions are used; its offsets and sign are not)")
    calibrate.add_argument("--reads", required=True, help="reads.csv with the reference tags' reads")
    calibrate.add_argument("--reference", action="extend", nargs="+", type=reference, default=[], metavar="EPC=x,y,z", help="a static reference tag and its position, m (several after one flag, or the flag repeated)")
    calibrate.add_argument("--truth", help="truth.csv: reference tags moved along known trajectories")
    calibrate.add_argument(
        "--reflector-search-m", type=search_distance, default=None, metavar="M",
        help="how far from where the scene declares a plane reflector its refined offset may be, m (default 0.3)",
    )
    calibrate.add_argument(
        "--find-walls", action="store_true",
        help="also look for walls nobody declared: planes parallel to the region's faces, beyond the region and the antennas",
    )
    calibrate.add_argument(
        "--wall-reach-m", type=reach_distance, default=None, metavar="M",
        help="with --find-walls, how far beyond the region and the antennas to look, m (default 2)",
    )
    calibrate.add_argument("--out", required=True, help="calibrated scene.toml to write")
    calibrate.set_defaults(run=command_calibrate)


def command_calibrate(args) -> int:
    from scattertrack import io
    from scattertrack.calibrate import calibrate

    if not args.reference and not args.truth:
        raise ValueError("give the reference tags: --reference EPC=x,y,z ... or --truth truth.csv")
    references = dict(args.reference)
    if len(references) < len(args.reference):
        raise ValueError("a reference EPC is given twice")
    scene = io.read_scene(args.scene)
    if scene.reader.kind != "cots":
        raise ValueError(f"calibrate calibrates monostatic reader scenes ([reader] kind = \"cots\"), not {scene.reader.kind!r}")
    reads = io.read_reads(args.reads, scene)
    truth = io.read_truth(args.truth) if args.truth else None
    missing = [epc for epc in references if not np.any(np.asarray(reads.epc).astype(str) == epc)]
    if missing:
        warnings.warn(io.InputWarning(args.reads, None, "epc", f"no reads of reference {', '.join(missing)}"), stacklevel=1)
    from scattertrack.calibrate.reflectors import DISCOVERY_REACH_M, SEARCH_M

    if args.wall_reach_m is not None and not args.find_walls:
        raise ValueError("--wall-reach-m goes with --find-walls")
    if args.find_walls and scene.region is None:
        raise ValueError(f"{args.scene}: --find-walls needs a [region]: walls are looked for beyond it")
    search = SEARCH_M if args.reflector_search_m is None else args.reflector_search_m
    reach = DISCOVERY_REACH_M if args.wall_reach_m is None else args.wall_reach_m
    result = calibrate(scene, reads, references, truth, reflector_search_m=search, find_walls=args.find_walls, wall_reach_m=reach)
    report(result)
    if args.find_walls and not any(f.discovered for f in result.reflectors):
        say(f"  no wall found within {reach:g} m beyond the region and the antennas")
    for message in result.warnings:
        warnings.warn(io.InputWarning(args.reads, None, None, message), stacklevel=1)
    out = output_path(args.out)
    result.scene().save(out)
    say(f"wrote the calibrated scene to {out}")
    return 0


def report(result) -> None:
    """The calibration's figures, for a person to read."""
    say(f"calibrated from {plural(result.reads, 'read')} of {plural(len(result.references), 'reference tag')}: {', '.join(result.references[:6])}")
    say(f"  phase period: {'pi (the reader reports phase mod pi)' if result.phase_period == 'pi' else '2pi'}")
    say(f"  phase sign: {result.phase_sign:+d} (coherence {result.coherence:.3f}; the other sign {result.other_sign_coherence:.3f})")
    usable = "usable" if result.phase_usable else "NOT usable"
    say(f"  phase coherence {result.coherence:.3f} against {result.chance:.3f} for random phases: phase is {usable} here")
    say("  residual phase RMS per antenna: " + ", ".join(f"{a}: {r:.3f} rad" for a, r in sorted(result.residual_rad.items())))
    if len(result.channel_residual_rad) > 1:
        worst = sorted(result.channel_residual_rad.items(), key=lambda item: -item[1])[:3]
        say(f"  {plural(len(result.channel_residual_rad), 'channel')} calibrated; worst residuals: " + ", ".join(f"{f / 1e6:.2f} MHz {r:.3f} rad" for f, r in worst))
    if result.hop_table_hz:
        clear = sum(1 for v in result.hop_table_margin.values() if v > 0)
        say(f"  hop table: {len(result.hop_table_hz)} channel indices assigned to the US plan, {clear} clearly")
    for fit in result.reflectors:
        if fit.discovered:
            axis = int(np.argmax(np.abs(fit.reflector["normal"])))
            plane = f"{'xyz'[axis]} = {fit.reflector['point'][axis]:.4f} m"
            say(f"  wall found: the plane {plane} (within {100 * (fit.interval_m[1] - fit.interval_m[0]) / 2:.2f} cm), "
                f"coefficient {fit.coefficient:+.2f}, explains the references by {fit.gain_nats:.0f} nats")
            continue
        where = f"moved {100 * fit.shift_m:+.1f} cm along its normal (within {100 * fit.interval_m[0]:+.2f} to {100 * fit.interval_m[1]:+.2f} cm)" if fit.kind == "plane" else "position as declared"
        verdict = "kept" if fit.kept else "LEFT OUT"
        say(f"  reflector {fit.index} ({fit.kind}): {where}, coefficient {fit.coefficient:+.2f}, explains the references by {fit.gain_nats:.0f} nats: {verdict}")
    for antenna, loss in sorted(result.path_loss.items()):
        exponent = f"exponent {loss.exponent:.2f}" if loss.fitted_exponent else f"exponent {loss.exponent:.1f} (free space: the references' ranges do not spread enough to fit it)"
        say(f"  RSSI antenna {antenna}: {loss.reference_dbm:.1f} dBm at 1 m, {exponent}, spread {loss.sigma_db:.2f} dB")
