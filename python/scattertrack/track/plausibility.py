"""Tracks that contradict their reads: a static tag tracked as moving.

GLAC's premise is mobility; a static tag gives it none, and on real
static-tag logs it has reported speeds of 1 m/s for tags that did not
move. The reads say otherwise, and cheaply: between two reads of one
antenna on one channel less than :data:`PAIR_GAP_S` apart, the phase turns
by 4π v_r Δt / λ for a radial speed v_r, and by its noise alone when the
tag is still. Per antenna the median of |Δφ| λ / (4π Δt) bounds the radial
speed the reads allow. A tag moving at v has a radial speed of at least
v/√3 on one of three or more well-spread antennas, so a track whose
median speed exceeds 3 × the largest bound + :data:`MARGIN_M_S` is
implausible: a ``warning:`` line says so and points to ``scattertrack
locate``.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import SPEED_OF_LIGHT

PAIR_GAP_S = 0.5
MARGIN_M_S = 0.05
MIN_PAIRS = 10
MIN_ROWS = 20


def radial_speed_bound(reads, rows: np.ndarray, period_rad: float) -> float:
    """The largest, over antennas, of the median radial speed the phase
    changes between close reads of one channel allow (m/s); nan if too few pairs."""
    bounds = []
    antenna = np.asarray(reads.antenna)[rows]
    for a in np.unique(antenna):
        mine = rows[antenna == a]
        order = np.lexsort((reads.time_s[mine], np.round(reads.frequency_hz[mine])))
        mine = mine[order]
        f, t, phase = reads.frequency_hz[mine], reads.time_s[mine], reads.phase_rad[mine]
        same = (np.abs(np.diff(f)) < 1e3) & (np.diff(t) > 0) & (np.diff(t) < PAIR_GAP_S)
        if np.count_nonzero(same) < MIN_PAIRS:
            continue
        turn = np.diff(phase)[same]
        turn = np.abs((turn + 0.5 * period_rad) % period_rad - 0.5 * period_rad)
        wavelength = SPEED_OF_LIGHT / f[1:][same]
        scale = 2.0 * np.pi / period_rad  # a mod-pi reader's phase turns half as fast
        bounds.append(float(np.median(turn * wavelength / (4.0 * np.pi * scale * np.diff(t)[same]))))
    return max(bounds) if bounds else float("nan")


def implausible_speed_warnings(track, reads, period_rad: float = 2.0 * np.pi) -> list[str]:
    """One ``warning:`` line per tag whose track moves faster than its reads allow."""
    if len(track) == 0 or track.velocity is None:
        return []
    lines = []
    track_epc = np.asarray(track.epc).astype(str)
    read_epc = np.asarray(reads.epc).astype(str)
    for name in dict.fromkeys(track_epc.tolist()):
        rows = np.flatnonzero(track_epc == name)
        if len(rows) < MIN_ROWS:
            continue
        speed = np.linalg.norm(track.velocity[rows], axis=1)
        if not np.isfinite(speed).any():
            continue
        tracked = float(np.nanmedian(speed))
        bound = radial_speed_bound(reads, np.flatnonzero(read_epc == name), period_rad)
        if np.isfinite(bound) and tracked > 3.0 * bound + MARGIN_M_S:
            lines.append(
                f"warning: tag {name}: its track moves at a median {tracked:.2f} m/s, but its reads' phases allow at most "
                f"about {bound:.3f} m/s of radial speed on any antenna: the tag is most likely static, which GLAC cannot "
                "resolve without motion; locate it with scattertrack locate"
            )
    return lines
