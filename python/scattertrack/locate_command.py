"""``scattertrack locate``: static tags located from a calibrated scene, every candidate listed.

    scattertrack locate --scene S --reads R --out positions.csv
"""

from __future__ import annotations

import time

import numpy as np

from scattertrack.arguments import plural, say
from scattertrack.reporting import output_path


def add_parser(commands) -> None:
    locate = commands.add_parser(
        "locate",
        help="locate static tags from a calibrated scene: positions.csv with every competing candidate",
        description="Locate every tag of a reads.csv as a static tag, from the cues the (calibrated) scene supports: "
        "carrier phase across antennas and hop channels, and RSSI path loss (calibrate's [calibration] table). "
        "Writes one best row per tag (candidate = 1) and the competing candidates (2, 3, ...); the best row's "
        "sigmas cover them.",
    )
    locate.add_argument("--scene", required=True, help="scene.toml, calibrated (scattertrack calibrate)")
    locate.add_argument("--reads", required=True, help="reads.csv of static tags")
    locate.add_argument("--out", required=True, help="positions.csv to write")
    locate.set_defaults(run=command_locate)


def command_locate(args) -> int:
    from scattertrack import io
    from scattertrack.io.positions import write_positions
    from scattertrack.locate import locate

    scene = io.read_scene(args.scene)
    if scene.reader.kind != "cots":
        raise ValueError(f"locate locates tags of monostatic reader scenes ([reader] kind = \"cots\"), not {scene.reader.kind!r}")
    if "calibration" not in scene.extra:
        say("  the scene has no [calibration] table: its offsets are taken as they are and RSSI is not used (see scattertrack calibrate)")
    from scattertrack.check.calibration import reflector_warnings

    for line in reflector_warnings(scene):
        say(line)
    if scene.reflectors:
        say(f"  the phase model includes the scene's {plural(len(scene.reflectors), 'reflector')} (each read's apparent range)")
    reads = io.read_reads(args.reads, scene)
    start = time.perf_counter()
    locations = locate(scene, reads)
    wall_s = time.perf_counter() - start
    rows = []
    for location in locations:
        for number, candidate in enumerate(location.candidates, start=1):
            sigma = np.sqrt(np.clip(np.diag(candidate.covariance), 0, None))
            rows.append((location.epc, candidate.position, sigma, number, candidate.weight, candidate.cue))
    out = output_path(args.out)
    write_positions(out, rows)
    say(f"located {plural(len(locations), 'tag')} from {plural(len(reads), 'read')} in {wall_s:.2f} s: wrote {plural(len(rows), 'row')} to {out}")
    ambiguous = [loc for loc in locations if len(loc.candidates) > 1]
    if ambiguous:
        say(f"  {plural(len(ambiguous), 'tag')} with competing candidates (the reads do not decide; the best row's sigma covers them)")
    cues = {}
    for loc in locations:
        cues[loc.candidates[0].cue] = cues.get(loc.candidates[0].cue, 0) + 1
    say("  located by: " + ", ".join(f"{cue} {n}" for cue, n in sorted(cues.items())))
    for loc in locations[:10]:
        best = loc.candidates[0]
        sigma = float(np.sqrt(np.max(np.diag(best.covariance))))
        note = f"; {loc.note}" if loc.note else ""
        say(f"  tag {loc.epc}: {plural(loc.reads, 'read')}, ({best.position[0]:.3f}, {best.position[1]:.3f}, {best.position[2]:.3f}) m, sigma up to {sigma * 1e3:.1f} mm, {plural(len(loc.candidates), 'candidate')}, by {best.cue}{note}")
    return 0
