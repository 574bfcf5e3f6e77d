"""Real-time TurboTrack over a helper recording: the runtime pipeline of
``crates/runtime`` (thesis sec. 6, "Real-time processing").

Where :func:`scattertrack.io.sigmf.read_sigmf_frames` + :func:`scattertrack.track.run`
process a recording in two offline passes, :func:`stream_sigmf` hands the
recorded replies one by one to the multi-threaded runtime, as the helper's
capture would:

    capture (paced at the recording's timing, or as fast as possible)
      -> per-antenna DSP workers (symbol timing, FFT per symbol, detection feature)
      -> fusion (joint preamble search, edge-flip elimination, tag channel,
         calibration, optional EMA), in reply order
      -> tracker (``turbotrack`` or a comparison variant)

and measures every reply's latency from the moment capture hands it over
to the moment its position comes out. Units: s, ns for latencies.

Frame times are the windows' start times (the reply starts within the
window's first few tens of microseconds: at 1 m/s that is well under a
millimetre of motion).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scattertrack.dsp.ofdm import SigmfCalibration, calibrate_sigmf, helper_positions as _positions, ofdm_dsp as _dsp
from scattertrack.io.sigmf import read_sigmf, Recording
from scattertrack.io.sigmf_scene import check_calibration
from scattertrack.io.types import Scene, SkipReport, Track
from scattertrack.track import helper
from scattertrack.track.columns import track_from_columns

SKIP_DSP = "reply without a usable tag channel (DSP: {})"
SKIP_UNREADABLE = "reply window that could not be read from the data file"


@dataclass
class StreamResult:
    """What one streaming run produced."""

    track: Track
    """One row per reply with a position (docs/formats.md section 4)."""
    latency_ns: np.ndarray
    """Per reply, from its arrival to its output, ns (capture order)."""
    stage_ns: np.ndarray
    """(replies, len(stages)): where each reply's latency went, ns."""
    receivers: np.ndarray
    """Receive antennas with a tag channel, per reply."""
    wall_s: float
    """From the first arrival to the last output, s."""
    replies: int
    declined: dict = field(default_factory=dict)
    """Replies without any tag channel, by reason."""
    stages: tuple = ()
    """Names of the ``stage_ns`` columns: dispatch (arrival to the last
    antenna worker starting), antenna (the slowest worker), hand-off (last
    worker done to fusion starting), fusion, tracker."""

    @property
    def frames_per_s(self) -> float:
        """Replies through the whole pipeline per second of wall clock."""
        return self.replies / self.wall_s if self.wall_s > 0 else 0.0

    def latency_percentile_ns(self, q: float) -> float:
        """Nearest-rank quantile (0-1) of the per-reply latency, ns."""
        if not self.latency_ns.size:
            return 0.0
        values = np.sort(self.latency_ns)
        rank = int(np.clip(np.ceil(q * values.size), 1, values.size))
        return float(values[rank - 1])


def stream_sigmf(
    recording,
    scene: Scene,
    calibration=None,
    method: str = "turbotrack",
    *,
    speed: float | None = None,
    workers: int | None = None,
    layout: str = "team",
    prewake_s: float = 1e-3,
    queue_depth: int = 64,
    ema_alpha: float | None = None,
    dsp_options: dict | None = None,
    **params,
) -> StreamResult:
    """Streams a helper recording through the real-time runtime.

    ``recording``: a path or :class:`Recording`; ``calibration``: a
    :class:`SigmfCalibration` or the path of a calibration recording
    (None: uncalibrated channels, which no tracker can use: a warning is
    not enough, so it raises ValueError). ``speed``: None as fast as
    possible, else a multiple of the recording's own timing (1 = live).
    A recording read from disk is streamed from its data file (one reply's
    windows read at a time, so any length fits in memory); one in memory
    from its array.
    ``layout``: how antenna jobs meet threads (``crates/runtime``,
    ``Workers``): "team" (default), ``workers`` threads (None: one per
    core) taking any antenna's job, the one completing a reply fusing and
    tracking it; "per-antenna", ``workers`` threads per receive antenna
    (None: 1, the thesis's layout) and a fusion thread; "shared", one pool
    of ``workers`` (None: one per core) and a fusion thread.
    ``prewake_s``: with "team" at a paced speed, how long before a reply is
    due the idle workers are woken to poll for it (0: they sleep until it
    arrives; a wake-up costs 0.1–0.3 ms on a virtual machine).
    ``params``: the tracker's parameters.
    Windows are cut to the shortest window's length (the helper records
    equal windows).
    """
    if method not in helper.WIDEBAND_METHODS:
        raise ValueError(f"method '{method}' does not track helper recordings (one of {', '.join(helper.WIDEBAND_METHODS)})")
    recording = recording if isinstance(recording, Recording) else read_sigmf(recording)
    _positions(scene, recording)
    options = dict(dsp_options or {})
    if calibration is None:
        raise ValueError("streaming needs a calibration (a calibration recording of a tag at a known position)")
    if not isinstance(calibration, SigmfCalibration):
        calibration = calibrate_sigmf(calibration, scene, **options)
    dsp = _dsp(recording, options)
    frequencies = dsp.subcarrier_frequencies()
    check_calibration(calibration, recording.channels, frequencies)

    count = len(recording.windows)
    length = min((w.sample_count for w in recording.windows), default=0)
    n = recording.subcarriers
    epcs = np.array([w.epc or "" for w in recording.windows], dtype=str)
    names, tag = np.unique(epcs, return_inverse=True)
    time_s = np.array([w.time_s for w in recording.windows], dtype=np.float64)
    tx_phase = np.array([-1 if w.tx_sample_index is None else w.tx_sample_index % n for w in recording.windows], dtype=np.int64)

    index = {a.id: i for i, a in enumerate(scene.antennas)}
    core = helper.engine(method, scene, params)
    settings = dict(
        timing_reference=calibration.timing_reference,
        correction=np.ascontiguousarray(calibration.correction, dtype=np.complex128),
        ema_alpha=ema_alpha,
        workers=None if workers is None else int(workers),
        layout=str(layout),
        prewake_s=float(prewake_s),
        queue_depth=int(queue_depth),
        speed=speed,
    )
    headers = (tag.astype(np.int64), time_s, tx_phase, dsp, index[recording.tx_id], [index[r] for r in recording.channels])
    if recording.data_path is not None and isinstance(recording.data, np.memmap):
        # Capture reads each reply's windows from the file when it is due.
        starts = np.array([w.sample_start for w in recording.windows], dtype=np.int64)
        source = {"file": (str(recording.data_path), recording.datatype, len(recording.channels),
                           float(recording.scale), int(length), starts)}
    else:
        windows = np.empty((count, len(recording.channels), length), dtype=np.complex64)
        for k in range(count):
            windows[k] = recording.window_samples(k)[:, :length]
        source = {"windows": windows}
    out = core.run_stream(*headers, **source, **settings)
    skipped = SkipReport()
    for reason, number in dict(out["declined"]).items():
        skipped.add(SKIP_DSP.format(reason), n=int(number))
    if out["unreadable"]:
        skipped.add(SKIP_UNREADABLE, n=int(out["unreadable"]))
    columns = {k: [out[k]] for k in ("row", "time_s", "position", "velocity", "covariance")}
    stats = {str(name): dict(core.stats(i)) for i, name in enumerate(names)}
    track = track_from_columns(columns, epcs, skipped, stats, helper._DECLINED, keep_covariance=True)  # for the ROS 2 outputs
    return StreamResult(
        track=track,
        latency_ns=np.asarray(out["latency_ns"], dtype=np.int64),
        stage_ns=np.asarray(out["stage_ns"], dtype=np.int64),
        stages=tuple(out["stages"]),
        receivers=np.asarray(out["receivers"], dtype=np.int64),
        wall_s=float(out["wall_s"]),
        replies=count,
        declined=dict(out["declined"]),
    )
