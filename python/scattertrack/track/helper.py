"""The helper pipeline (a reader plus an SDR localization helper):
TurboTrack and its comparison variants over the Rust core
(``crates/core/src/track/turbotrack.rs``), fed wideband frames
(``frames.csv``, docs/formats.md section 5).

Method names: ``turbotrack`` (thesis ch. 5, Algorithm 1), ``gaussian-pf``
(single broad Gaussian likelihood, bootstrap proposal: thesis §7.2(a)) and
``uniform-pf`` (uniform initial particles over the region, bootstrap
proposal, the mixture likelihood: §7.2(b)), ``ellipse-intersection``
(per frame, strongest candidates only: §7.2(a)) and ``rfind`` (a static
tag localised from frames pooled over a few seconds, RFind-style: Table 7.1).
"""

from __future__ import annotations

import numpy as np

from scattertrack import _core
from scattertrack.io.frames import Frames
from scattertrack.io.types import Scene, Track
from scattertrack.track import parameters
from scattertrack.track.columns import track_from_columns
from scattertrack.track.methods import WIDEBAND_METHODS

_DECLINED = {
    "out_of_order": "frame out of time order (declined by tracker)",
    "invalid": "frame without enough usable receivers (declined by tracker)",
    "outliers": "outlier frame (particles kept, estimate extrapolated)",
}


def default_params(method: str = "turbotrack") -> dict:
    """The method's default parameters (names accepted by ``make``), SI units."""
    return parameters.default_params(method)


def engine(method: str, scene: Scene, params: dict) -> _core.Engine:
    """A core engine for a helper scene (one ``tx``, several ``rx`` antennas)."""
    if scene.reader.kind != "sdr-helper":
        raise ValueError(f"method '{method}' needs a localization-helper scene (kind = 'sdr-helper'), got '{scene.reader.kind}'")
    # The binding reads the helper scene's antenna roles (one tx, the rx).
    return _core.Engine(_core.Scene(scene), method, dict(params))


def run_frames(method: str, scene: Scene, frames: Frames, *, progress: bool = False, chunk: int = 2_000, **params) -> Track:
    """Tracks every tag in ``frames`` and returns one estimate row per
    accepted frame, in time order. Causal: each row uses only frames at or
    before its time. Frames the tracker declined are counted in
    ``Track.skipped`` by reason; ``Track.smoothed`` holds each tag's
    backtracked MAP trajectory (Algorithm 1's output) as ``epc -> (times,
    positions)``.
    """
    core = engine(method, scene, params)
    index = {a.id: i for i, a in enumerate(scene.antennas)}
    n_frames = frames.n_frames
    starts = np.asarray(frames.frame_start, dtype=np.int64)
    first = starts[:-1]
    frame_time = frames.time_s[first] if n_frames else np.zeros(0)
    frame_epc = frames.epc[first] if n_frames else np.zeros(0, dtype=str)
    names, tag = np.unique(frame_epc, return_inverse=True)
    tx_index = np.array([index[int(t)] for t in frames.tx[first]], dtype=np.int64) if n_frames else np.zeros(0, dtype=np.int64)
    rx_index = np.array([index[int(r)] for r in frames.rx], dtype=np.int64) if len(frames) else np.zeros(0, dtype=np.int64)
    h_re = np.ascontiguousarray(frames.h.real, dtype=float)
    h_im = np.ascontiguousarray(frames.h.imag, dtype=float)
    columns = {k: [] for k in ("row", "time_s", "position", "velocity", "covariance")}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_frames, unit="frame", desc=method, leave=False)
    for lo in range(0, n_frames, chunk):
        hi = min(lo + chunk, n_frames)
        r0, r1 = starts[lo], starts[hi]
        out = core.run_frames(
            tag[lo:hi].astype(np.int64),
            np.ascontiguousarray(frame_time[lo:hi], dtype=float),
            tx_index[lo:hi],
            starts[lo : hi + 1] - r0,
            rx_index[r0:r1],
            np.ascontiguousarray(frames.frequency_hz[r0:r1], dtype=float),
            h_re[r0:r1],
            h_im[r0:r1],
        )
        for k in columns:
            columns[k].append(out[k] + lo if k == "row" else out[k])
        if bar is not None:
            bar.update(hi - lo)
    if bar is not None:
        bar.close()
    stats = {str(n): dict(core.stats(i)) for i, n in enumerate(names)}
    track = track_from_columns(columns, frame_epc, frames.skipped, stats, _DECLINED)
    track.latency = core.latency()
    p50, p99 = core.latency_percentiles([0.5, 0.99])
    track.latency_quantiles_ns = {"p50": p50, "p99": p99}
    track.smoothed = {}
    for i, n in enumerate(names):
        pairs = core.trajectory(i)
        track.smoothed[str(n)] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]).reshape(-1, 3))
    return track
