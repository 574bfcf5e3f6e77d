"""The helper's OFDM channel estimation over a SigMF recording: windows in, frames out.

A recording (:class:`scattertrack.io.sigmf.Recording`, the format read by
:mod:`scattertrack.io.sigmf`) holds the short windows the helper opens
after each reader Query. :func:`estimate_sigmf` runs the Rust DSP
(``scattertrack._core.OfdmDsp``, one-shot wideband estimation: mean of the
reflective symbols minus mean of the non-reflective ones, thesis sec. 4.3)
over every window and returns :class:`Frames` (docs/formats.md section 5)
with per-frame diagnostics; :func:`read_sigmf_frames` returns the frames
alone. :func:`calibrate_sigmf` learns the per-(rx, subcarrier) correction
from a recording of one tag at rest at a known position, against the
reference channel of :mod:`scattertrack.dsp.channel`.

Windows without a detectable preamble, all-NaN windows and failed receive
antennas are skipped and counted in ``Frames.skipped`` (examples: 0-based
window indices). Tracked in a scene, a recording whose antenna positions
differ from the scene's by more than 5 cm is warned
(:mod:`scattertrack.io.sigmf_scene`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scattertrack.dsp.channel import tag_channel
from scattertrack.io.frames import Frames, make_frames
from scattertrack.io.sigmf import NAMESPACE, Recording, read_sigmf
from scattertrack.io.sigmf_scene import check_calibration, finite_vector, warn_scene_disagreement
from scattertrack.io.types import FormatError, Scene, SkipReport

SKIP_NO_PREAMBLE = "no preamble"
SKIP_NON_FINITE = "non-finite window"
SKIP_TOO_SHORT = "window too short"
SKIP_NO_CLEAN = "no clean symbols"
SKIP_RX = "receive antenna failed"
"""Reasons counted in ``Frames.skipped`` (the last per receive antenna of a reply)."""

_SKIP_BY_KIND = {
    "no-preamble": SKIP_NO_PREAMBLE,
    "non-finite": SKIP_NON_FINITE,
    "too-short": SKIP_TOO_SHORT,
    "no-clean-symbols": SKIP_NO_CLEAN,
}


@dataclass
class SigmfCalibration:
    """Per-(rx, subcarrier) correction from a tag at a known position (thesis sec. 4.3)."""

    correction: np.ndarray
    """C (R, F) complex128: calibrated = C x measured."""
    rx_ids: list[int]
    frequencies_hz: np.ndarray
    """Active subcarriers (F,), Hz, ascending."""
    timing_reference: list[int] | None
    """Per-rx symbol timing reference learnt on the calibration windows (see the DSP's ``process``)."""
    tag_position: np.ndarray
    replies: int
    """Replies averaged."""
    source: str


@dataclass
class SigmfEstimate:
    """What :func:`estimate_sigmf` found: the frames and per-reply diagnostics."""

    frames: Frames
    """docs/formats.md section 5 frames; ``frames.skipped`` counts what was declined."""
    window: np.ndarray
    """Window index of each frame (n_frames,), in the order of the recording."""
    score: np.ndarray
    """Normalised preamble correlation of each frame."""
    blf_hz: np.ndarray
    """Estimated tag BLF of each frame, Hz."""
    variance: np.ndarray
    """Variance of each channel estimate, (n_frames, R, F), in calibrated units."""
    symbols_used: np.ndarray
    """Reflective + non-reflective symbols averaged per frame (first rx that worked)."""
    symbols_edge: np.ndarray
    """Symbols discarded by edge-flip elimination per frame."""

    @property
    def skipped(self) -> SkipReport:
        return self.frames.skipped


def ofdm_dsp(recording: Recording, options: dict):
    """The Rust DSP (``_core.OfdmDsp``) for a recording's OFDM design, with the DSP ``options``."""
    from scattertrack import _core

    return _core.OfdmDsp(
        recording.bandwidth_hz, recording.subcarriers, recording.centre_hz, recording.blf_hz,
        recording.known_symbol, encoding=recording.encoding, trext=recording.trext, **options,
    )


def helper_positions(scene: Scene, recording: Recording) -> tuple[np.ndarray, np.ndarray]:
    """tx position (3,) and rx positions (R, 3) from the scene, checking ids and roles; warns where
    the scene disagrees with the recording's metadata (:mod:`scattertrack.io.sigmf_scene`)."""
    where = str(recording.path) if recording.path is not None else "<recording>"
    warn_scene_disagreement(where, scene, recording.meta["global"])
    roles = {int(a.id): a for a in scene.antennas}
    tx = roles.get(recording.tx_id)
    if tx is None or tx.role != "tx":
        raise FormatError(where, None, f"global.{NAMESPACE}:tx_id", f"antenna {recording.tx_id} is not a 'tx' antenna of scene {scene.name!r}")
    rx = []
    for rx_id in recording.channels:
        antenna = roles.get(rx_id)
        if antenna is None or antenna.role != "rx":
            raise FormatError(where, None, f"global.{NAMESPACE}:channels", f"antenna {rx_id} is not an 'rx' antenna of scene {scene.name!r}")
        rx.append(np.asarray(antenna.position, dtype=np.float64))
    return np.asarray(tx.position, dtype=np.float64), np.array(rx)


def calibrate_sigmf(path, scene: Scene, tag_position=None, **options) -> SigmfCalibration:
    """A calibration from a recording of one tag at rest at a known position.

    ``tag_position`` (m) defaults to the recording's
    ``scattertrack:calibration.tag_position``. Every window is processed
    (with the transmitter sample index, so the timing reference is learnt
    too); the replies found are averaged and divided into the reference
    channel :func:`scattertrack.dsp.channel.tag_channel` (direct path, no reflectors: what
    the user knows of the geometry) at that position. ``options``: the DSP
    options of :func:`estimate_sigmf`. Raises ValueError when no reply is
    found, :class:`FormatError` for a bad recording.
    """
    from scattertrack import _core

    recording = path if isinstance(path, Recording) else read_sigmf(path)
    if tag_position is None:
        recorded = recording.calibration
        key = f"global.{NAMESPACE}:calibration.tag_position"
        if not isinstance(recorded, dict) or "tag_position" not in recorded:
            raise FormatError(recording.path, None, key, "missing: a calibration recording names the known position "
                                                         "of its tag at rest (metres)")
        tag_position = recorded["tag_position"]
        if not finite_vector(tag_position):
            raise FormatError(recording.path, None, key, f"must be 3 finite numbers (metres), got {tag_position!r}")
    tag_position = np.asarray(tag_position, dtype=np.float64).reshape(3)
    tx, rx = helper_positions(scene, recording)
    dsp = ofdm_dsp(recording, options)
    n = recording.subcarriers
    measured = []
    for k, window in enumerate(recording.windows):
        phase = None if window.tx_sample_index is None else window.tx_sample_index % n
        try:
            out = dsp.process(recording.window_samples(k), phase)
        except _core.DspError:
            continue
        if np.isfinite(out["tag_channel"]).all():
            measured.append(out["tag_channel"])
    if not measured:
        raise ValueError(f"{recording.path}: no calibration reply found in {len(recording.windows)} windows")
    frequencies = dsp.subcarrier_frequencies()
    reference = tag_channel(tx, rx, tag_position[None, :], frequencies)[0]
    correction = _core.dsp_calibration(np.array(measured), reference)
    return SigmfCalibration(
        correction, recording.channels, frequencies, dsp.timing_reference, tag_position, len(measured), str(recording.path)
    )


def estimate_sigmf(
    path,
    scene: Scene,
    calibration=None,
    *,
    ema_alpha: float | None = None,
    use_tx_index: bool = True,
    **options,
) -> SigmfEstimate:
    """One-shot wideband channel estimation over every window of a recording (thesis sec. 4.3).

    ``calibration``: a :class:`SigmfCalibration`, the path of a calibration
    recording (:func:`calibrate_sigmf` with its recorded tag position), or
    None (uncalibrated channels: the hardware response and the tag's
    modulation phase remain, so the docs/formats.md section 5 convention does
    not hold). ``ema_alpha``: smoothing across each tag's replies
    (``DspEma``; None: off). ``use_tx_index``: use each window's
    transmitter sample index to keep the symbol timing reference fixed
    (recommended; the DSP's ``process`` explains why). ``options``: the
    DSP's keyword options — ``threshold`` (0.5), ``blf_tolerance`` (0.05),
    ``guard_symbols`` (1.0), ``feature`` ("projection" or "magnitude"),
    ``use_payload`` (True), ``payload_bits`` (17), ``decision_margin`` (0.5).

    Windows are skipped and counted in ``frames.skipped`` by reason (no
    preamble, non-finite window, too short, no clean symbols; a failed
    receive antenna drops that antenna's rows). Frame time = the window
    start + the detected preamble start.
    """
    from scattertrack import _core

    recording = path if isinstance(path, Recording) else read_sigmf(path)
    helper_positions(scene, recording)  # the scene must know the recording's antennas
    if calibration is not None and not isinstance(calibration, SigmfCalibration):
        calibration = calibrate_sigmf(calibration, scene, **options)
    dsp = ofdm_dsp(recording, options)
    frequencies = dsp.subcarrier_frequencies()
    if calibration is not None:
        check_calibration(calibration, recording.channels, frequencies)
        if use_tx_index and calibration.timing_reference is not None:
            dsp.timing_reference = calibration.timing_reference
    n = recording.subcarriers
    rx_ids = np.array(recording.channels, dtype=np.int64)
    skipped = SkipReport()
    smoothers: dict[str, object] = {}
    rows = {"time": [], "epc": [], "h": [], "ok": []}
    diagnostics = {"window": [], "score": [], "blf": [], "variance": [], "used": [], "edge": []}
    for k, window in enumerate(recording.windows):
        samples = recording.window_samples(k)
        if not np.isfinite(samples).any():
            skipped.add(SKIP_NON_FINITE, k)
            continue
        phase = window.tx_sample_index % n if (use_tx_index and window.tx_sample_index is not None) else None
        try:
            out = dsp.process(samples, phase)
        except _core.DspError as error:
            kind = str(error).split(":", 1)[0]
            skipped.add(_SKIP_BY_KIND.get(kind, kind), k)
            continue
        h = out["tag_channel"]
        variance = out["variance"]
        if calibration is not None:
            h = h * calibration.correction
            variance = variance * np.abs(calibration.correction) ** 2
        ok = np.isfinite(h).all(axis=1)  # per rx
        if not ok.all():
            skipped.add(SKIP_RX, k, n=int((~ok).sum()))
        if not ok.any():
            continue
        epc = window.epc if window.epc is not None else ""
        if ema_alpha is not None:
            smoother = smoothers.setdefault(epc, _core.DspEma(float(ema_alpha)))
            h = smoother.update(np.ascontiguousarray(h, dtype=np.complex128))
        rows["time"].append(window.time_s + out["start_sample"] / recording.bandwidth_hz)
        rows["epc"].append(epc)
        rows["h"].append(h)
        rows["ok"].append(ok)
        first = int(np.flatnonzero(ok)[0])
        diagnostics["window"].append(k)
        diagnostics["score"].append(out["score"])
        diagnostics["blf"].append(out["blf_hz"])
        diagnostics["variance"].append(variance)
        diagnostics["used"].append(out["counts"]["high"][first] + out["counts"]["low"][first])
        diagnostics["edge"].append(out["counts"]["edge"][first])
    r, f = len(rx_ids), len(frequencies)
    count = len(rows["time"])
    if count:
        ok = np.array(rows["ok"])  # (K, R)
        mask = np.broadcast_to(ok[:, :, None], (count, r, f))
        shape = (count, r, f)
        frames = make_frames(
            time_s=np.broadcast_to(np.array(rows["time"])[:, None, None], shape)[mask],
            epc=np.broadcast_to(np.array(rows["epc"], dtype=str)[:, None, None], shape)[mask],
            tx=np.full(int(mask.sum()), recording.tx_id, dtype=np.int64),
            rx=np.broadcast_to(rx_ids[None, :, None], shape)[mask],
            frequency_hz=np.broadcast_to(frequencies[None, None, :], shape)[mask],
            h=np.array(rows["h"])[mask],
        )
    else:
        empty = np.array([], dtype=np.float64)
        frames = make_frames(empty, np.array([], dtype=str), empty, empty, empty, np.array([], dtype=np.complex128))
    frames.skipped = skipped
    order = np.argsort(np.array(rows["time"]), kind="stable") if count else np.array([], dtype=np.int64)
    return SigmfEstimate(
        frames=frames,
        window=np.array(diagnostics["window"], dtype=np.int64)[order],
        score=np.array(diagnostics["score"], dtype=np.float64)[order],
        blf_hz=np.array(diagnostics["blf"], dtype=np.float64)[order],
        variance=np.array(diagnostics["variance"]).reshape(-1, r, f)[order],
        symbols_used=np.array(diagnostics["used"], dtype=np.int64)[order],
        symbols_edge=np.array(diagnostics["edge"], dtype=np.int64)[order],
    )


def read_sigmf_frames(path, scene: Scene, calibration=None, **options) -> Frames:
    """The wideband frames (docs/formats.md section 5) of a helper recording: :func:`estimate_sigmf`'s ``frames``."""
    return estimate_sigmf(path, scene, calibration, **options).frames
