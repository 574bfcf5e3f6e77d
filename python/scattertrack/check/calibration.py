"""What a COTS scene has not calibrated yet (``check-scene``'s calibration lines).

A scene straight from a tape measure has antenna offsets of 0, no channel
offsets and no hop table; ``scattertrack calibrate`` fills them and
records how well in ``[calibration]``. Each line here names one gap and
what it costs; with reads, it also says whether they hop (channel offsets
then matter) and carry channel indices (then the hop table does).
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import Reads, Scene


def calibration_lines(scene: Scene, reads: Reads | None = None) -> list[str]:
    """One ``calibration:`` line per item, uncalibrated ones first."""
    table = scene.extra.get("calibration") if isinstance(scene.extra.get("calibration"), dict) else None
    lines = []
    hopping = reads is not None and len(np.unique(np.round(np.asarray(reads.frequency_hz) / 1e3))) > 1
    indexed = reads is not None and reads.channel_index is not None and bool(np.any(reads.channel_index > 0))
    if table is None:
        lines.append("calibration: not calibrated (no [calibration] table): phase sign, period and offsets are as written; run scattertrack calibrate with reference tags")
    if all(a.phase_offset_rad == 0.0 for a in scene.antennas):
        lines.append("calibration: antenna phase offsets are all 0: uncalibrated cables and ports put each antenna's ranges off by up to lambda/4")
    if not scene.channel_offsets:
        cost = "the reads hop, so every channel's offset is unknown" if hopping else "needed once the reader hops"
        lines.append(f"calibration: no channel offsets ([[channel_offsets]]): {cost}")
    if not scene.hop_table:
        cost = "the reads carry channel indices whose carriers are then guessed" if indexed else "needed when a reader log has channel indices but no frequencies"
        lines.append(f"calibration: no hop table ([[hop_table]]): {cost}")
    if table is not None:
        usable = "usable" if table.get("phase_usable", True) else "NOT usable (locate and track should rely on RSSI)"
        lines.append(
            f"calibration: calibrated from {table.get('references', '?')} references, {table.get('reads', '?')} reads: "
            f"phase coherence {table.get('phase_coherence', float('nan'))} (random {table.get('chance_coherence', float('nan'))}), phase {usable}; "
            f"calibrated {', '.join(table.get('calibrated', []))}"
        )
        if not table.get("path_loss"):
            lines.append("calibration: no RSSI path loss: locate cannot fall back on RSSI")
    return lines


def reflector_warnings(scene: Scene) -> list[str]:
    """A ``warning:`` line when the scene declares reflectors that ``calibrate`` has not refined.

    A wall stated a few centimetres from where it is predicts a ripple out
    of step with the one in the reads: on our multipath cells, 5 cm off
    gave medians of 20 cm where no wall at all gave 2 cm
    (docs/glac.md, "Known reflectors"). ``calibrate`` refines each declared
    reflector against reference tags, or leaves it out."""
    reflectors = scene.reflectors
    if not reflectors:
        return []
    table = scene.extra.get("calibration") if isinstance(scene.extra.get("calibration"), dict) else {}
    unrefined = len(reflectors)
    if "reflectors" in (table.get("calibrated") or []):
        # The calibration lists every reflector it fitted; the scene keeps the kept ones.
        # More reflectors than it kept were added afterwards.
        fits = table.get("reflectors") or []
        kept = sum(1 for f in fits if isinstance(f, dict) and f.get("kept"))
        unrefined = len(reflectors) - kept
        if unrefined <= 0:
            return []
    count = f"{unrefined} reflector" + ("s" if unrefined > 1 else "")
    return [
        f"warning: the scene declares {count} that scattertrack calibrate has not refined: a wall stated even 5 cm "
        "from where it is makes the tracks worse than no wall at all; run scattertrack calibrate with reference tags "
        "(it refines each reflector to about a millimetre, or leaves it out)"
    ]
