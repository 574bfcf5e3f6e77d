"""GLAC and its variants over the Rust core (``crates/core/src/track/glac.rs``).

Method names: ``glac`` (the paper's tracker), ``glac-no-velocity``,
``glac-sync``, ``glac-sync-no-velocity`` (sec. 5.2.2 variants) and
``glac-naive`` (unpruned inference, sec. 5.2.3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scattertrack import _core
from scattertrack.io.types import Reads, Scene, SkipReport, Track
from scattertrack.track import methods as registry
from scattertrack.track import parameters

METHODS: list[str] = list(registry.METHODS)
"""Every registered method (the registry in the Rust core)."""


def default_params(method: str = "glac") -> dict:
    """GLAC's default parameters (names accepted by :func:`make`), SI units."""
    return parameters.default_params(method)


@dataclass
class Estimate:
    """One tracker output."""

    time_s: float
    epc: str
    position: np.ndarray
    """Metres, (3,)."""
    velocity: np.ndarray
    """m/s, (3,); nan for methods without velocity."""
    covariance: np.ndarray
    """(6, 6) covariance of [p, v] (m², m²/s, m²/s²)."""
    hypotheses: int
    """Live candidate trajectories."""
    weight: float
    """Normalised likelihood of the reported trajectory."""


def _engine(method: str, scene: Scene, params: dict) -> _core.Engine:
    from scattertrack.track import wideband

    entry = registry.method(method)  # ValueError naming the known methods
    if entry.input == "frames":
        return wideband.engine(method, scene, params)
    if entry.estimator != "core":
        raise ValueError(f"method '{method}' is the drone pipeline: use scattertrack.track.marvel (imu + features or a recording)")
    if scene.reader.kind != "cots":
        raise ValueError(f"method '{method}' needs a monostatic reader scene (kind = 'cots'), got '{scene.reader.kind}'")
    # Parameters cross as one dict; the core's table checks every one
    # (ValueError naming the parameter).
    return _core.Engine(_core.Scene(scene), method, dict(params))


class Tracker:
    """A streaming tracker for any number of tags (one per EPC)."""

    def __init__(self, method: str, scene: Scene, **params):
        self.method = method
        self.scene = scene
        self.params = params
        self._engine = _engine(method, scene, params)
        self._tags: dict[str, int] = {}
        self._antennas = {a.id: i for i, a in enumerate(scene.antennas)}

    def _tag(self, epc: str) -> int:
        return self._tags.setdefault(str(epc), len(self._tags))

    def step(self, time_s: float, epc: str, antenna: int, frequency_hz: float, phase_rad: float) -> Estimate | None:
        """One read (``antenna`` is the port id as in the scene)."""
        if antenna not in self._antennas:
            raise ValueError(f"antenna {antenna} is not in the scene")
        out = self._engine.step(self._tag(epc), float(time_s), self._antennas[antenna], float(frequency_hz), float(phase_rad))
        if out is None:
            return None
        t, position, velocity, covariance, hypotheses, weight = out
        return Estimate(t, str(epc), np.array(position), np.array(velocity), np.array(covariance).reshape(6, 6), hypotheses, weight)

    def step_frame(self, time_s: float, epc: str, tx: int, rx, frequency_hz, h) -> Estimate | None:
        """One wideband frame (wideband methods): ``rx`` (n,) receive antenna
        ids, ``frequency_hz`` (n,) and complex ``h`` (n,), sorted by receiver
        then frequency, every receiver with the same subcarriers; ``tx`` is
        the transmit antenna id."""
        rx = np.asarray(rx)
        for antenna in [tx, *np.unique(rx).tolist()]:
            if antenna not in self._antennas:
                raise ValueError(f"antenna {antenna} is not in the scene")
        h = np.asarray(h, dtype=complex)
        out = self._engine.run_frames(
            np.array([self._tag(epc)], dtype=np.int64),
            np.array([float(time_s)]),
            np.array([self._antennas[tx]], dtype=np.int64),
            np.array([0, len(rx)], dtype=np.int64),
            np.array([self._antennas[int(r)] for r in rx], dtype=np.int64),
            np.asarray(frequency_hz, dtype=float),
            np.ascontiguousarray(h.real),
            np.ascontiguousarray(h.imag),
        )
        if len(out["row"]) == 0:
            return None
        return Estimate(
            float(out["time_s"][0]),
            str(epc),
            out["position"][0].copy(),
            out["velocity"][0].copy(),
            out["covariance"][0].reshape(6, 6).copy(),
            int(out["hypotheses"][0]),
            float(out["weight"][0]),
        )

    def stats(self, epc: str) -> dict:
        """What the tag's tracker did with its reads, by reason."""
        return dict(self._engine.stats(self._tags[str(epc)])) if str(epc) in self._tags else {}

    def hypotheses(self, epc: str) -> list[tuple[np.ndarray, float]]:
        """Live candidate trajectories of a tag: (position m, normalised log-likelihood)."""
        if str(epc) not in self._tags:
            return []
        return [(np.array(p), w) for p, w in self._engine.hypotheses(self._tags[str(epc)])]

    def latency(self) -> tuple[int, float, int]:
        """(steps, mean ns, max ns) of the Rust step calls."""
        return self._engine.latency()


def make(method: str, scene: Scene, **params) -> Tracker:
    """A tracker by name; ``params`` override :func:`default_params`."""
    return Tracker(method, scene, **params)


# Reasons under which declined reads are reported (Track.skipped).
_DECLINED = {
    "out_of_order": "read out of time order (declined by tracker)",
    "invalid": "invalid read (declined by tracker)",
    "outliers": "outlier read (3-sigma gate: replaced by prediction)",
}


def track_from_columns(columns: dict, epcs: np.ndarray, input_skipped: SkipReport, stats: dict, declined: dict, keep_covariance: bool = False) -> Track:
    """A Track from the engine's output columns (lists of chunks; ``row``
    indexes ``epcs``), carrying the input's skip report plus what the
    trackers declined (``stats`` per tag, ``declined``: counter → reason)."""
    rows = np.concatenate(columns["row"]) if columns["row"] else np.zeros(0, dtype=np.int64)
    covariance = np.concatenate(columns["covariance"]) if rows.size else np.zeros((0, 36))
    skipped = SkipReport(dict(input_skipped.counts), {k: list(v) for k, v in input_skipped.examples.items()})
    for tag_stats in stats.values():
        for key, reason in declined.items():
            if tag_stats.get(key, 0):
                skipped.add(reason, n=int(tag_stats[key]))
    sigma = np.sqrt(np.clip(covariance[:, [0, 7, 14]], 0.0, None)) if rows.size else np.zeros((0, 3))
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


def run(method: str, scene: Scene, reads: Reads, *, progress: bool = False, chunk: int = 50_000, covariance: bool = False, **params) -> Track:
    """Tracks every tag in ``reads`` (time-ordered, as the readers return
    them) and returns one estimate row per update, in time order.

    Causal: each row uses only reads at or before its time. The reads'
    own skip report (duplicates) is carried over, and reads the trackers
    declined are added to it by reason. ``covariance=True`` keeps every
    row's full 6×6 covariance in ``Track.covariance`` (for the ROS 2
    writers; 288 bytes a row).
    """
    tracker = Tracker(method, scene, **params)
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
