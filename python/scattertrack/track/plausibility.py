"""Tracks that contradict their reads: a static tag tracked as moving, a track its reads did not resolve.

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

from scattertrack.physics import SPEED_OF_LIGHT

PAIR_GAP_S = 0.5
MARGIN_M_S = 0.05
MIN_PAIRS = 10
MIN_ROWS = 20

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
            lines.append(unresolved_line(str(epcs[k]), float(share[k]), float(widest[k])))
    return lines


def unresolved_line(epc: str, share: float, widest_m: float, sigma_m: float = UNRESOLVED_SIGMA_M) -> str:
    """The ``warning:`` line of a tag whose track ends unresolved: ``share`` of its rows above ``sigma_m``."""
    return (
        f"warning: tag {epc}: the reads did not resolve its position: "
        f"{share * 100:.0f} % of its rows, the last included, have a sigma above "
        f"{sigma_m * 100:.0f} cm (up to {widest_m * 100:.0f} cm); "
        "the sigmas cover the competing candidates, the position is the likeliest of them"
    )


def static_line(epc: str, speed_m_s: float, bound_m_s: float) -> str:
    """The ``warning:`` line of a tag tracked at ``speed_m_s`` whose reads allow at most ``bound_m_s``."""
    return (
        f"warning: tag {epc}: its track moves at a median {speed_m_s:.2f} m/s, but its reads' phases allow at most "
        f"about {bound_m_s:.3f} m/s of radial speed on any antenna: the tag is most likely static, which GLAC cannot "
        "resolve without motion; locate it with scattertrack locate"
    )


def implausible(speed_m_s: float, bound_m_s: float) -> bool:
    """Whether a median track speed exceeds what the reads' phase turns allow (module docstring)."""
    return bool(np.isfinite(bound_m_s) and speed_m_s > 3.0 * bound_m_s + MARGIN_M_S)


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
    # Rows grouped per tag once (a recording may hold 10,000 tags; comparing
    # every row per tag would be quadratic).
    track_names, track_tag = np.unique(np.asarray(track.epc).astype(str), return_inverse=True)
    read_names, read_tag = np.unique(np.asarray(reads.epc).astype(str), return_inverse=True)
    track_rows = np.split(np.argsort(track_tag, kind="stable"), np.cumsum(np.bincount(track_tag, minlength=len(track_names)))[:-1])
    read_rows = np.split(np.argsort(read_tag, kind="stable"), np.cumsum(np.bincount(read_tag, minlength=len(read_names)))[:-1])
    read_index = {name: k for k, name in enumerate(read_names.tolist())}
    first = np.array([rows[0] for rows in track_rows])
    for k in np.argsort(first, kind="stable").tolist():  # in order of first appearance
        rows, name = track_rows[k], str(track_names[k])
        if len(rows) < MIN_ROWS:
            continue
        speed = np.linalg.norm(track.velocity[rows], axis=1)
        if not np.isfinite(speed).any():
            continue
        tracked = float(np.nanmedian(speed))
        mine = read_rows[read_index[name]] if name in read_index else np.zeros(0, dtype=np.int64)
        bound = radial_speed_bound(reads, mine, period_rad)
        if implausible(tracked, bound):
            lines.append(static_line(name, tracked, bound))
    return lines
