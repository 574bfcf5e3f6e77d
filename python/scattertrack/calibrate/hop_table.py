"""Which carrier each channel index is: the reader's hop table from reference tags.

A reader reports a channel *index* into its own hop table; when the table
was not logged, the references tell it. Between two reads of one channel
index the channel's own offset cancels, and what is left of the phase
difference is s · 4π f (d_k − d_l) / c: the carrier scales how the phase
follows the range. So each index takes the carrier of the regional plan
under which its reads are most coherent (every other offset as fitted),
and no carrier is given to two indices (an assignment maximising the
summed coherence, Hungarian algorithm).

How well it can work: a neighbouring channel (500 kHz away) changes the
predicted phase by 4π · 500 kHz · Δd / c = 0.021 rad per metre of range
spread among the reads of that index. References spread over a few
metres in range (or one moved along a known path) separate neighbours;
tags bunched within half a metre only place each index to within a few
channels, which the margins reported say.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from scattertrack.calibrate.phase import group_means, round_trip_phase


@dataclass
class HopTableFit:
    frequency_hz: np.ndarray
    """Per channel (in the order of ``channel_keys``): the assigned carrier, Hz."""
    coherence: np.ndarray
    """Per channel: R of its reads under the assigned carrier."""
    margin: np.ndarray
    """Per channel: that R minus the best R any other carrier reaches (> 0: clear)."""


def assign_carriers(
    phase_rad: np.ndarray,
    distance_m: np.ndarray,
    channel: np.ndarray,
    n_channels: int,
    known_rad: np.ndarray,
    sign: int,
    m: int,
    candidates_hz: np.ndarray,
) -> HopTableFit:
    """Carriers for channel indices ``channel`` (per read, < ``n_channels``).

    ``known_rad``: per read, the fitted antenna and tag offsets (on the
    m-circle); the channel offset is left free (it is what each candidate
    fits anew). ``candidates_hz``: the regional plan (at least as many
    carriers as channels).
    """
    candidates = np.asarray(candidates_hz, dtype=np.float64)
    if len(candidates) < n_channels:
        raise ValueError(f"{n_channels} channel indices but only {len(candidates)} carriers in the plan")
    base = np.exp(1j * (m * np.asarray(phase_rad, dtype=np.float64) - known_rad))
    counts = np.bincount(channel, minlength=n_channels).astype(float)
    score = np.empty((n_channels, len(candidates)))
    for j, frequency in enumerate(candidates):
        model = np.exp(-1j * m * sign * round_trip_phase(frequency, distance_m))
        score[:, j] = np.abs(group_means(base * model, channel, n_channels)) / np.maximum(counts, 1.0)
    rows, cols = linear_sum_assignment(-score)
    chosen = np.empty(n_channels, dtype=np.int64)
    chosen[rows] = cols
    best_other = np.array([np.max(np.delete(score[c], chosen[c])) if len(candidates) > 1 else 0.0 for c in range(n_channels)])
    coherence = score[np.arange(n_channels), chosen]
    return HopTableFit(candidates[chosen], coherence, coherence - best_other)
