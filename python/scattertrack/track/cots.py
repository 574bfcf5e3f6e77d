"""The COTS pipeline's batch runner: every tag of a ``reads.csv`` through
GLAC or one of its variants (``crates/core/src/track/glac.rs``).

Method names: ``glac`` (the paper's tracker), ``glac-no-velocity``,
``glac-sync``, ``glac-sync-no-velocity`` (sec. 5.2.2 variants) and
``glac-naive`` (unpruned inference, sec. 5.2.3). :func:`run` is a loop over
:meth:`CoreTracker.step <scattertrack.track.core.CoreTracker.step>` done in
Rust, chunk by chunk.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import Reads, Scene, Track
from scattertrack.track import parameters
from scattertrack.track.columns import READS_DECLINED, track_from_columns
from scattertrack.track.core import CoreTracker

# Reasons under which declined reads are reported (Track.skipped).
_DECLINED = READS_DECLINED


def run(method: str, scene: Scene, reads: Reads, *, progress: bool = False, chunk: int = 50_000, covariance: bool = False, **params) -> Track:
    """Tracks every tag in ``reads`` (time-ordered, as the readers return
    them) and returns one estimate row per update, in time order.

    Causal: each row uses only reads at or before its time. The reads'
    own skip report (duplicates) is carried over, and reads the trackers
    declined are added to it by reason. ``covariance=True`` keeps every
    row's full 6×6 covariance in ``Track.covariance`` (for the ROS 2
    writers; 288 bytes a row). Offline, a read's deferred work is done at
    once (:func:`scattertrack.track.parameters.offline`).
    """
    tracker = CoreTracker(method, scene, **parameters.offline(method, params))
    order = np.argsort(reads.time_s, kind="stable")
    # Sort every column once; the chunks below are views into these.
    epcs = reads.epc[order]
    time_s, frequency_hz, phase_rad = reads.time_s[order], reads.frequency_hz[order], reads.phase_rad[order]
    names, tag = np.unique(epcs, return_inverse=True)
    # Tag indices in order of first appearance, so stats line up with epcs().
    tracker._tags = {str(n): int(i) for i, n in enumerate(names)}
    antenna_index = np.array([tracker._antennas.get(int(a), -1) for a in reads.antenna[order]], dtype=np.int64)
    if np.any(antenna_index < 0):
        bad = int(reads.antenna[order][antenna_index < 0][0])
        raise ValueError(f"reads name antenna {bad}, which the scene does not define")
    columns = {k: [] for k in ("row", "time_s", "position", "velocity", "covariance")}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(order), unit="read", desc=method, leave=False)
    for start in range(0, len(order), chunk):
        sl = slice(start, start + chunk)
        out = tracker._engine.run(
            tag[sl].astype(np.int64),
            time_s[sl],
            antenna_index[sl],
            frequency_hz[sl],
            phase_rad[sl],
        )
        for k in columns:
            columns[k].append(out[k] + start if k == "row" else out[k])
        if bar is not None:
            bar.update(len(time_s[sl]))
    if bar is not None:
        bar.close()
    stats = {str(n): tracker.stats(str(n)) for n in names}
    track = track_from_columns(columns, epcs, reads.skipped, stats, _DECLINED, keep_covariance=covariance)
    track.latency = tracker.latency()
    return track


__all__ = ["run", "track_from_columns"]
