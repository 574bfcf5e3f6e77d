"""A :class:`Track` from a core engine's output columns: the one place both
batch runners (:mod:`scattertrack.track.cots` for reads,
:mod:`scattertrack.track.helper` for frames, and the helper's streaming
runtime) turn the engine's rows and counters into a track.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import SkipReport, Track


READS_DECLINED = {
    "out_of_order": "read out of time order (declined by tracker)",
    "invalid": "invalid read (declined by tracker)",
    "outliers": "outlier read (beyond the gate_sigmas innovation gate: replaced by prediction)",
}
"""A reads tracker's counters reported as skipped reads: counter -> reason."""


def declined_skips(input_skipped: SkipReport, stats: dict, declined: dict) -> SkipReport:
    """The input's skip report plus what the trackers declined (``stats`` per tag, ``declined``: counter -> reason)."""
    skipped = SkipReport(dict(input_skipped.counts), {k: list(v) for k, v in input_skipped.examples.items()})
    for tag_stats in stats.values():
        for key, reason in declined.items():
            if tag_stats.get(key, 0):
                skipped.add(reason, n=int(tag_stats[key]))
    return skipped


def position_sigma(covariance: np.ndarray) -> np.ndarray:
    """(n, 3) 1-sigma of x, y, z (m) from the engine's (n, 36) row-major [p, v] covariances."""
    return np.sqrt(np.clip(covariance[:, [0, 7, 14]], 0.0, None))


def track_from_columns(columns: dict, epcs: np.ndarray, input_skipped: SkipReport, stats: dict, declined: dict, keep_covariance: bool = False) -> Track:
    """A Track from the engine's output columns (lists of chunks; ``row``
    indexes ``epcs``), carrying the input's skip report plus what the
    trackers declined (``stats`` per tag, ``declined``: counter → reason)."""
    rows = np.concatenate(columns["row"]) if columns["row"] else np.zeros(0, dtype=np.int64)
    covariance = np.concatenate(columns["covariance"]) if rows.size else np.zeros((0, 36))
    skipped = declined_skips(input_skipped, stats, declined)
    sigma = position_sigma(covariance) if rows.size else np.zeros((0, 3))
    track = Track(
        time_s=np.concatenate(columns["time_s"]) if rows.size else np.zeros(0),
        epc=epcs[rows] if rows.size else np.zeros(0, dtype=str),
        position=np.concatenate(columns["position"]) if rows.size else np.zeros((0, 3)),
        velocity=np.concatenate(columns["velocity"]) if rows.size else np.zeros((0, 3)),
        sigma=sigma,
        skipped=skipped,
    )
    track.stats = stats
    if keep_covariance:
        track.covariance = covariance.reshape(-1, 6, 6)
    return track
