"""Static-tag positions, ``positions.csv`` (written by ``scattertrack locate``).

Columns: ``epc``; ``x, y, z`` (m); ``sx, sy, sz`` (1-sigma, m); ``candidate``
(1 for a tag's best position, 2, 3 ... for competing ones, likeliest
first); ``weight`` (the candidate's share of the likelihood, 0-1); ``cue``
(what located it: ``phase``, ``phase+rssi``, ``rssi`` or ``region`` when
nothing could). One ``candidate = 1`` row per tag; its sigmas cover the
competing candidates (the spread of all of them about it), the other rows'
sigmas are their own.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.csvutil import quote_text

HEADER = ["epc", "x", "y", "z", "sx", "sy", "sz", "candidate", "weight", "cue"]


def write_positions(path, rows) -> None:
    """Write ``rows`` of (epc, position (3,), sigma (3,), candidate, weight, cue)."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(HEADER) + "\n")
        for epc, position, sigma, candidate, weight, cue in rows:
            cells = [quote_text(str(epc))]
            cells += [f"{float(v):.6f}" for v in np.asarray(position, dtype=float)]
            cells += ["inf" if not np.isfinite(v) else f"{float(v):.6f}" for v in np.asarray(sigma, dtype=float)]
            cells += [str(int(candidate)), f"{float(weight):.4f}", cue]
            f.write(",".join(cells) + "\n")
