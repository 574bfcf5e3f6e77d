"""The layout check of a localization-helper scene (bistatic: one tx, several rx).

A helper frame measures, per receive antenna, the path sum
``|tx - tag| + |tag - rx|``: the tag lies on an ellipsoid with foci at the
transmitter and that receiver, symmetric about the line through the two.
Receivers on one line through the transmitter share that axis: turning
the tag about it changes none of their path sums. With every receiver on
the line the position is fixed only up to a circle about it (no number of
frames can tell where on the circle); with all but one on it, only that
one tells where, from its phase alone, so a lobe error there (one
wavelength of path sum) goes uncorrected: the outside case
``helper-static-8db`` has three of four on the line. Two or more receivers
off every such line (the project's cross layout: two pairs on two lines)
check each other, and the layout is not warned.

Pure geometry: the findings are the :class:`scattertrack.check.Finding`
lines of the COTS check (``warning:`` / ``note:``), naming the antennas by
their scene ids, the line's direction and the remedy.
"""

from __future__ import annotations

import numpy as np

from scattertrack.check.geometry import Finding, GeometryCheck
from scattertrack.io.types import Scene

IN_LINE_M = 0.01
"""A receiver closer than this to the line through the transmitter and another receiver, metres,
is in line with them: 1 cm is a few percent of a UHF wavelength (33 cm), too little to
break the symmetry about the line against phase noise."""


def _ids(antennas) -> str:
    ids = [str(a.id) for a in antennas]
    return ids[0] if len(ids) == 1 else ", ".join(ids[:-1]) + " and " + ids[-1]


def _direction(vector: np.ndarray) -> str:
    """'along x' for an axis, else the unit vector."""
    unit = vector / np.linalg.norm(vector)
    for axis, name in enumerate("xyz"):
        if abs(abs(unit[axis]) - 1.0) < 1e-6:
            return f"along {name}"
    return "along (" + ", ".join(f"{v:.2f}" for v in unit) + ")"


def lines_through_tx(scene: Scene, tolerance_m: float = IN_LINE_M) -> list[list[int]]:
    """Groups (2 or more) of indices into ``scene.antennas`` of receivers on one line through the
    transmitter, each group in scene order; a receiver at the transmitter's place is on every line
    and in no group."""
    tx = next(a for a in scene.antennas if a.role == "tx")
    origin = np.asarray(tx.position, dtype=float)
    receivers = [i for i, a in enumerate(scene.antennas) if a.role == "rx"]
    offsets = {i: np.asarray(scene.antennas[i].position, dtype=float) - origin for i in receivers}
    groups: list[list[int]] = []
    placed: set[int] = set()
    for i in receivers:
        length = np.linalg.norm(offsets[i])
        if i in placed or length <= tolerance_m:
            continue
        unit = offsets[i] / length
        group = [j for j in receivers if np.linalg.norm(np.cross(unit, offsets[j])) <= tolerance_m
                 and np.linalg.norm(offsets[j]) > tolerance_m]
        placed.update(group)
        if len(group) >= 2:
            groups.append(group)
    return groups


def check_helper_scene(scene: Scene, tolerance_m: float = IN_LINE_M) -> GeometryCheck:
    """The findings on a ``kind = "sdr-helper"`` scene's layout and a summary line."""
    antennas = scene.antennas
    tx = next(a for a in antennas if a.role == "tx")
    receivers = [a for a in antennas if a.role == "rx"]
    findings = []
    for group in lines_through_tx(scene, tolerance_m):
        on_line = [antennas[i] for i in group]
        off = [a for a in receivers if a not in on_line]
        if len(off) >= 2:
            continue  # they check each other: the turn about this line is fixed twice over
        direction = _direction(np.asarray(on_line[0].position, dtype=float) - np.asarray(tx.position, dtype=float))
        where = f"receive antennas {_ids(on_line)} lie on one line with the transmitter {tx.id} ({direction})"
        if len(on_line) == len(receivers):
            text = (f"{where}: every path sum tx -> tag -> rx stays the same as the tag turns about that line, so no "
                    "frame tells where on a circle about it the tag is; move a receive antenna off the line "
                    "(a quarter wavelength or more)")
        else:
            text = (f"{where}: their path sums stay the same as the tag turns about that line, so only receive "
                    f"antenna {_ids(off)} tells where on a circle about it the tag is, and a lobe error there "
                    f"(one wavelength of path sum) goes uncorrected; moving one of {_ids(on_line)} off the line "
                    "(a quarter wavelength or more) lets two receivers check each other")
        findings.append(Finding("warning", text, {"antennas": group}))
    if findings:
        summary = (f"the helper layout fixes the turn about {len(findings)} line{'s' if len(findings) > 1 else ''} "
                   f"through the transmitter with at most one receive antenna (tolerance {tolerance_m * 100:g} cm)")
    else:
        summary = ("the helper layout fixes the position: no line through the transmitter has all but one receive "
                   f"antenna on it (tolerance {tolerance_m * 100:g} cm)")
    return GeometryCheck(findings, summary, {"lines": [f.details["antennas"] for f in findings]})
