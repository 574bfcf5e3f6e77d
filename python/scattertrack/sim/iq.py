"""The SDR localization helper at IQ level: raw baseband windows, as the helper records them.

Where :mod:`scattertrack.sim.wideband` jumps straight to the channel
estimates, this simulator produces what the helper's receivers sample
(thesis ch. 4 and 6), so that the DSP (``crates/dsp``, reached through
:func:`scattertrack.dsp.read_sigmf_frames`) can be tested end to end.

What it models (every random draw from ``numpy.random.default_rng(seed)``,
split into independent streams; defaults in :data:`IQ_MODEL_DEFAULTS`):

Helper transmission (sec. 4.2)
    One known OFDM symbol ``X[k]`` of ``N`` bins at sample rate ``B``
    (unit magnitude, random phases, DC bin empty), sent back to back from
    ``t = 0`` on, so every symbol is the next one's cyclic prefix. Bin ``k``
    sits at ``f_k = centre + k' B / N`` (``k'`` the signed bin: ``k`` below
    ``N - N // 2``, else ``k - N``); the ``N - 1`` non-DC bins are the
    subcarriers of the frames (note: :func:`wideband.subcarrier_frequencies`
    uses a symmetric grid without a DC bin instead).
Reader timing (sec. 4.3, last paragraph)
    The reader ends a Query every ``reply_period_s`` (plus a uniform jitter
    of ``reply_jitter`` periods), tags in turn. The tag answers after
    ``T1 = max(RTcal, 10 / BLF)`` scaled by ``1 + U(-t1_tolerance,
    t1_tolerance)``. The helper opens a window of ``window_s`` at
    ``T1 (1 - t1_tolerance) - window_lead_s`` after the Query and records
    only that window (all rx antennas at once).
Tag reply (EPC Gen2)
    FM0 or Miller (M = 2, 4, 8), optional TRext pilot, the preamble, a random
    RN16 (16 bits) or 128 random bits standing in for PC + EPC + CRC, and the
    dummy 1. The tag's BLF misses the commanded one by a factor
    ``1 + U(-blf_tolerance, blf_tolerance)`` (per tag) times
    ``1 + N(0, blf_jitter)`` (per reply). The reflective state is the
    waveform's level 1; the tag idles at ``idle_level`` outside its reply
    and switches with a linear ramp of ``transition_s``. With
    ``miss_probability`` a queried tag does not answer (the window is still
    recorded: the DSP must report "no preamble").
Propagation
    Per rx antenna the received baseband is
    ``G_r(f) [S_r(f) + s(t) Gamma T_r(f)] X(f)``: ``S`` the static channel
    (tx -> rx leakage and clutter, :func:`wideband.static_channel`), ``T``
    the tag channel at the tag's true position (:func:`wideband.tag_channel`,
    docs/formats.md section 5 convention), ``Gamma = exp(j psi)`` the tag's
    modulation phase (one per recording: all tags are of one model), ``G``
    the hardware response of each receive chain: a gain
    (``hardware_gain_db`` spread), smooth gain and phase ripple across the
    band (``hardware_ripple_db``, ``hardware_ripple_rad``), a constant phase
    and a delay of ``U(hardware_delay_samples)`` samples. Calibration (a tag
    at a known position) must remove ``G`` and ``Gamma``. Not modelled: tag
    motion within one window (300 us at 1 m/s is 0.3 mm), the propagation
    delay of the tag's switching (a few ns), antenna patterns.
Noise and ADC
    White complex Gaussian noise of standard deviation
    ``10^(-snr_db / 20)``: ``snr_db`` is the per-sample (and, with the
    unitary FFT, per-symbol per-subcarrier) SNR of a tag ``d_ref = 1 m``
    from both antennas (``|T| = 1``); with both legs at 2 m it is 12 dB
    lower. One reply of the default set-up averages about 1300 clean
    symbols, so its channel estimate has about 25 dB more. Samples are then
    scaled so the strongest receive channel's RMS sits ``adc_headroom_db``
    below full scale and stored as ``ci16`` (rounded, clipped, clipped
    samples counted) or ``cf32``.

Data volume: ``window_s B`` complex samples per rx per reply; the default
(300 us at 100 MS/s, 4 rx, ci16) is 30 000 x 4 x 4 bytes = 480 kB per reply,
144 MB per second at 300 replies/s (against 1.6 GB/s for continuous
recording: the windowing saves 91 %). Keep simulated recordings short
(:func:`simulate_iq` defaults to 0.03 s, about 9 replies).

Output (:func:`write_iq_simulation`): ``recording.sigmf-meta/-data`` and
``calibration.sigmf-meta/-data`` (layout and metadata keys in
:mod:`scattertrack.io.sigmf`), ``scene.toml`` (with a ``[helper]`` table),
``truth.csv`` and ``simulation.json`` (seed, model, hidden truth).
Units: metres, seconds, hertz, radians, dB.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.sigmf import NAMESPACE, Recording, make_recording_metadata, write_sigmf
from scattertrack.io.types import Scene, Truth
from scattertrack.sim import wideband
from scattertrack.sim.trajectory import positions_velocities

IQ_MODEL_DEFAULTS = {
    # OFDM (thesis ch. 6): N = 20 over 100 MHz, BLF 40 kHz
    "centre_frequency_hz": 915e6,  # Hz, the DC bin
    "bandwidth_hz": 100e6,  # Hz, B = complex sample rate; subcarriers B / N apart
    "n_subcarriers": 20,  # N = FFT size; N - 1 subcarriers (DC dropped); N < B / (2 BLF)
    "blf_hz": 40e3,  # Hz, the BLF the reader commands
    # Gen2 link
    "encoding": "fm0",  # "fm0", "miller2", "miller4", "miller8"
    "trext": False,  # extended pilot before the preamble
    "payload": "rn16",  # "rn16" (16 bits) or "epc" (128 bits)
    "blf_tolerance": 0.02,  # fraction: each tag's BLF is off by U(-tol, tol)
    "blf_jitter": 0.0005,  # fraction, 1-sigma per reply
    "rtcal_s": 34.4e-6,  # s, RTcal (2.75 Tari at Tari = 12.5 us)
    "t1_tolerance": 0.05,  # fraction: T1 varies by U(-tol, tol)
    "reply_period_s": 1.0 / 300.0,  # s between Queries (the paper's 300 replies/s)
    "reply_jitter": 0.1,  # fraction of a period, uniform
    "miss_probability": 0.0,  # a queried tag does not answer
    "idle_level": 0.0,  # tag state outside its reply (0: non-reflective)
    "transition_s": 0.1e-6,  # s, duration of a state change (linear ramp)
    # helper window
    "window_s": 300e-6,  # s recorded per reply
    "window_lead_s": 20e-6,  # s the window opens before the earliest T1
    # channel and hardware
    "leakage": wideband.DIRECT_LEAKAGE,  # direct tx -> rx amplitude at d_ref (static_channel)
    "reflectors": [],  # multipath (wideband module docstring)
    "hardware_gain_db": 3.0,  # dB, per-rx gain spread, uniform +-
    "hardware_ripple_db": 1.0,  # dB, gain ripple across the band (peak)
    "hardware_ripple_rad": 0.3,  # rad, phase ripple across the band (peak)
    "hardware_delay_samples": [0.5, 4.0],  # samples, per-rx delay range (uniform)
    # noise and ADC
    "snr_db": 0.0,  # dB per sample for a tag d_ref from tx and rx
    "datatype": "ci16_le",  # "ci16_le" or "cf32_le"
    "adc_headroom_db": 12.0,  # dB between full scale and the strongest channel's RMS
    # calibration recording
    "calibration_replies": 4,  # replies of the calibration tag
}
"""Every IQ model key with its default (units in the comments)."""

STREAMS = ("symbol", "schedule", "hardware", "tags", "payload", "noise", "calibration")
"""Independent random streams (switching one process off leaves the others' draws unchanged)."""

ENCODINGS = ("fm0", "miller2", "miller4", "miller8")


@dataclass
class IqSimulation:
    """The outcome of :func:`simulate_iq`: two recordings, the scene, the truth and the record."""

    scene: Scene
    """The helper's scene (one ``tx``, the ``rx`` antennas; a ``[helper]`` table with the OFDM keys)."""
    recording: Recording
    """The tag replies' windows (in memory until written)."""
    calibration: Recording
    """The calibration tag's windows, at ``details["calibration_position"]``."""
    truth: Truth
    """Every tag's position at each reply (the frame times' ground truth) and on a 200 Hz grid."""
    model: dict
    """The resolved model (every default filled in)."""
    seed: int
    details: dict = field(default_factory=dict)
    """Hidden truth: hardware response, tag BLF factors, who answered, clipping counts."""


# --------------------------------------------------------------------------
# model


def resolve_iq_model(model: dict | None = None) -> dict:
    """Defaults of :data:`IQ_MODEL_DEFAULTS` updated by ``model``, validated.

    Raises ValueError for an unknown key or a bad value, including a
    design that breaks ``N < B / (2 BLF)`` (thesis sec. 4.2; the message
    comes from the DSP crate and names the largest N allowed).
    """
    from scattertrack import _core

    given = dict(model or {})
    unknown = sorted(set(given) - set(IQ_MODEL_DEFAULTS))
    if unknown:
        raise ValueError(f"unknown IQ model key(s) {unknown} (known: {', '.join(sorted(IQ_MODEL_DEFAULTS))})")
    resolved = {**IQ_MODEL_DEFAULTS, **given}
    if resolved["encoding"] not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS}, got {resolved['encoding']!r}")
    if resolved["payload"] not in ("rn16", "epc"):
        raise ValueError(f"payload must be 'rn16' or 'epc', got {resolved['payload']!r}")
    if resolved["datatype"] not in ("ci16_le", "cf32_le"):
        raise ValueError(f"datatype must be 'ci16_le' or 'cf32_le', got {resolved['datatype']!r}")
    positive = ("bandwidth_hz", "blf_hz", "rtcal_s", "reply_period_s", "window_s")
    for key in positive:
        if not (np.isfinite(resolved[key]) and resolved[key] > 0):
            raise ValueError(f"{key} must be a positive number, got {resolved[key]!r}")
    fractions = ("blf_tolerance", "blf_jitter", "t1_tolerance", "reply_jitter", "miss_probability", "idle_level")
    for key in fractions:
        if not (0.0 <= resolved[key] <= 1.0):
            raise ValueError(f"{key} must be in [0, 1], got {resolved[key]!r}")
    low, high = resolved["hardware_delay_samples"]
    if not (0.0 <= low <= high):
        raise ValueError(f"hardware_delay_samples must be [low, high] with 0 <= low <= high, got {[low, high]}")
    if int(resolved["calibration_replies"]) < 1:
        raise ValueError("calibration_replies must be at least 1")
    try:
        _core.dsp_subcarrier_frequencies(
            float(resolved["bandwidth_hz"]),
            int(resolved["n_subcarriers"]),
            float(resolved["centre_frequency_hz"]),
            float(resolved["blf_hz"]),
        )
    except ValueError as error:
        raise ValueError(str(error)) from None
    return resolved


def fft_bin_frequencies(model: dict) -> np.ndarray:
    """RF frequency of every FFT bin ``k = 0 .. N-1`` (FFT order, bin 0 = DC), Hz."""
    n = int(model["n_subcarriers"])
    k = np.arange(n)
    signed = np.where(k < n - n // 2, k, k - n)
    return model["centre_frequency_hz"] + signed * model["bandwidth_hz"] / n


def active_bins(n: int) -> np.ndarray:
    """FFT bins of the ``N - 1`` subcarriers in ascending frequency (DC dropped)."""
    signed = np.arange(-(n // 2), n - n // 2)
    signed = signed[signed != 0]
    return np.mod(signed, n)


# --------------------------------------------------------------------------
# Gen2 waveforms (independent of the DSP crate's encoder, so each checks the other)

FM0_PREAMBLE = np.array([1, 1, 0, 1, 0, 0, 1, 0, 0, 0, 1, 1], dtype=np.uint8)
"""FM0 ``1 0 1 0 v 1`` as chips (half BLF periods), starting high."""


def reply_chips(encoding: str, trext: bool, bits) -> np.ndarray:
    """Chip levels (0/1, one per half BLF period) of a Gen2 reply: pilot, preamble, ``bits``, dummy 1.

    FM0: every bit boundary inverts the level, a data-0 also inverts mid-bit;
    TRext adds 12 data-0 before the preamble. Miller M: baseband inverts
    mid-bit for a data-1 and between two data-0, times a square subcarrier of
    M cycles per bit; the preamble is a pilot of 4 (16 with TRext) data-0
    then ``010111``.
    """
    bits = [1 if b else 0 for b in bits] + [1]
    if encoding == "fm0":
        chips = [1, 0] * 12 if trext else []
        chips += FM0_PREAMBLE.tolist()
        level = 1
        for bit in bits:
            level ^= 1
            chips += [level, level] if bit else [level, level ^ 1]
            if not bit:
                level ^= 1
        return np.array(chips, dtype=np.uint8)
    m = int(encoding.removeprefix("miller"))
    sequence = [0] * (16 if trext else 4) + [0, 1, 0, 1, 1, 1] + bits
    halves = []
    phase, previous = 1, None
    for bit in sequence:
        if previous == 0 and bit == 0:
            phase = -phase
        first = phase
        if bit:
            phase = -phase
        halves += [first, phase]
        previous = bit
    baseband = np.repeat(np.array(halves), m)  # m chips per half bit
    subcarrier = np.where(np.arange(len(baseband)) % 2 == 0, 1, -1)
    return (baseband * subcarrier > 0).astype(np.uint8)


def tag_levels(chips: np.ndarray, n_samples: int, reply_sample: float, chip_samples: float, idle: float, ramp: float) -> np.ndarray:
    """The tag state at every sample of a window (float in [0, 1]).

    ``reply_sample``: the reply's start in window samples (fractional);
    ``chip_samples``: chip length in samples; outside the reply the state is
    ``idle``; ``ramp``: samples of a linear transition (a moving average).
    """
    position = (np.arange(n_samples) + 0.5 - reply_sample) / chip_samples
    index = np.floor(position).astype(np.int64)
    inside = (index >= 0) & (index < len(chips))
    levels = np.full(n_samples, float(idle))
    levels[inside] = chips[index[inside]]
    width = int(round(ramp))
    if width > 1:
        padded = np.concatenate([np.full(width, levels[0]), levels, np.full(width, levels[-1])])
        smooth = np.convolve(padded, np.ones(width) / width, mode="same")
        levels = smooth[width:-width]
    return levels


# --------------------------------------------------------------------------
# the simulator


def simulate_iq(
    scene: Scene,
    tags: dict,
    model: dict | None = None,
    seed: int = 0,
    *,
    duration_s: float = 0.03,
    calibration_position=None,
    calibration_epc: str | None = None,
) -> IqSimulation:
    """Simulate the helper's recordings of tag replies: ``IqSimulation``.

    ``scene``: a helper scene (one ``role = "tx"`` antenna, ``role = "rx"``
    ones). ``tags``: ``{epc: trajectory dict}`` (kinds of
    :mod:`scattertrack.sim.trajectory`); the reader queries them in turn.
    ``model``: keys of :data:`IQ_MODEL_DEFAULTS`. ``duration_s``: the
    session length (replies every ``reply_period_s``). The calibration
    recording has ``calibration_replies`` replies of ``calibration_epc``
    (default: the first tag) at rest at ``calibration_position`` (default:
    the centre of the scene's region, or 0.8 m above the antennas' centroid;
    on the plane for 2D scenes). Same inputs and seed: identical output.
    """
    model = resolve_iq_model(model)
    if not tags:
        raise ValueError("no tags to simulate")
    streams = dict(zip(STREAMS, np.random.default_rng(seed).spawn(len(STREAMS))))
    tx_id, tx, rx_ids, rx = wideband.helper_geometry(scene)
    n = int(model["n_subcarriers"])
    frequencies = fft_bin_frequencies(model)

    # The known symbol: unit-magnitude random phases, DC empty.
    symbol = np.exp(2j * np.pi * streams["symbol"].random(n))
    symbol[0] = 0.0

    hardware, hardware_details = _hardware_response(len(rx), n, model, streams["hardware"])
    static = wideband.static_channel(tx, rx, frequencies, model["reflectors"], leakage=model["leakage"])  # (R, N)
    modulation_phase = float(streams["tags"].uniform(0.0, 2.0 * np.pi))
    gamma = np.exp(1j * modulation_phase)
    epcs = [str(e) for e in tags]
    trajectories = [dict(tags[e]) for e in epcs]
    for params in trajectories:
        if params.get("kind") == "random":
            params.setdefault("seed", int(streams["tags"].integers(2**31)))
    blf_factor = 1.0 + streams["tags"].uniform(-model["blf_tolerance"], model["blf_tolerance"], len(epcs))

    # Scale so the strongest channel's RMS sits adc_headroom_db below full scale.
    base = _periodic(symbol, hardware * static)  # (R, N) one symbol of the static part
    rms = float(np.sqrt(np.max(np.mean(np.abs(base) ** 2, axis=1))))
    full_scale = 32767.0 if model["datatype"] == "ci16_le" else 1.0
    scale = full_scale * 10.0 ** (-model["adc_headroom_db"] / 20.0) / rms

    context = _Context(model, symbol, hardware, static, gamma, base, scale, tx, rx, streams)
    count = int(np.floor(duration_s / model["reply_period_s"] + 1e-9))
    if count < 1:
        raise ValueError(f"duration_s = {duration_s} s is shorter than one reply period ({model['reply_period_s']} s)")
    query_end = 1e-3 + np.arange(count) * model["reply_period_s"]
    query_end += streams["schedule"].uniform(0.0, model["reply_jitter"] * model["reply_period_s"], count)
    tag_index = np.arange(count) % len(epcs)
    answered = streams["schedule"].random(count) >= model["miss_probability"]
    positions = np.empty((count, 3))
    for index, params in enumerate(trajectories):
        rows = tag_index == index
        positions[rows] = positions_velocities(params, query_end[rows])[0]
    recording, record = _record(context, query_end, [epcs[i] for i in tag_index], positions, blf_factor[tag_index], answered)

    # Calibration: one tag at rest at a known position.
    calibration_epc = epcs[0] if calibration_epc is None else str(calibration_epc)
    position = _calibration_position(scene, rx, tx) if calibration_position is None else np.asarray(calibration_position, float)
    position = position.reshape(3)
    k = int(model["calibration_replies"])
    calibration_times = query_end[-1] + 0.1 + np.arange(k) * model["reply_period_s"]
    calibration_context = _Context(model, symbol, hardware, static, gamma, base, scale, tx, rx, streams, calibration=True)
    calibration, calibration_record = _record(
        calibration_context, calibration_times, [calibration_epc] * k, np.tile(position, (k, 1)),
        np.full(k, blf_factor[epcs.index(calibration_epc)] if calibration_epc in epcs else 1.0), np.ones(k, bool),
    )

    common = _common_metadata(model, symbol, scene, tx_id, tx, rx_ids, rx, scale, seed)
    recording.meta["global"].update(common)
    calibration.meta["global"].update(common)
    calibration.meta["global"][f"{NAMESPACE}:calibration"] = {"epc": calibration_epc, "tag_position": position.tolist()}

    helper_scene = _helper_scene(scene, model)
    truth = _truth(epcs, trajectories, query_end, duration_s)
    details = {
        "modulation_phase_rad": modulation_phase,
        "tag_blf_factor": {e: float(f) for e, f in zip(epcs, blf_factor)},
        "answered": answered.tolist(),
        "reply_positions": positions.tolist(),
        "calibration_position": position.tolist(),
        "calibration_epc": calibration_epc,
        **hardware_details,
        "recording": record,
        "calibration": calibration_record,
    }
    return IqSimulation(helper_scene, recording, calibration, truth, model, int(seed), details)


@dataclass
class _Context:
    model: dict
    symbol: np.ndarray
    hardware: np.ndarray
    static: np.ndarray
    gamma: complex
    base: np.ndarray
    scale: float
    tx: np.ndarray
    rx: np.ndarray
    streams: dict
    calibration: bool = False


def _periodic(symbol: np.ndarray, channel: np.ndarray) -> np.ndarray:
    """One period of the steady-state received signal ``IDFT(X H)`` (unitary), shape (R, N)."""
    n = len(symbol)
    return np.fft.ifft(symbol[None, :] * channel, axis=1) * np.sqrt(n)


def _hardware_response(n_rx: int, n: int, model: dict, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """``G`` (R, N) in FFT order: gain, smooth ripple, constant phase, delay; and its parameters."""
    signed = np.where(np.arange(n) < n - n // 2, np.arange(n), np.arange(n) - n) / n  # in [-0.5, 0.5)
    gain_db = rng.uniform(-model["hardware_gain_db"], model["hardware_gain_db"], n_rx)
    phase = rng.uniform(0.0, 2.0 * np.pi, n_rx)
    low, high = model["hardware_delay_samples"]
    delay = rng.uniform(low, high, n_rx)
    # Ripple: three cosines across the band with random phases, scaled to the peak.
    harmonics = np.arange(1, 4)
    ripple_phase = rng.uniform(0.0, 2.0 * np.pi, (2, n_rx, 3))
    shapes = np.cos(2.0 * np.pi * harmonics * signed[:, None, None, None] + ripple_phase[None]).sum(-1)  # (N, 2, R)
    shapes /= np.max(np.abs(shapes), axis=0, keepdims=True)
    gain = 10.0 ** ((gain_db[None, :] + model["hardware_ripple_db"] * shapes[:, 0]) / 20.0)  # (N, R)
    angle = phase[None, :] + model["hardware_ripple_rad"] * shapes[:, 1] - 2.0 * np.pi * signed[:, None] * delay[None, :]
    response = (gain * np.exp(1j * angle)).T  # (R, N)
    return response, {"hardware_gain_db": gain_db.tolist(), "hardware_delay_samples": delay.tolist(),
                      "hardware_phase_rad": phase.tolist()}


def _calibration_position(scene: Scene, rx: np.ndarray, tx: np.ndarray) -> np.ndarray:
    """Default calibration point: the region's centre, else 0.8 m above the antennas' centroid."""
    if scene.region is not None:
        point = (np.asarray(scene.region.min, float) + np.asarray(scene.region.max, float)) / 2.0
    else:
        point = np.vstack([rx, tx[None, :]]).mean(axis=0) + np.array([0.0, 0.0, 0.8])
    if scene.dimensions == 2 and scene.plane_z is not None:
        point[2] = scene.plane_z
    return point


def _record(context: _Context, query_end, epcs, positions, blf_factor, answered) -> tuple[Recording, dict]:
    """Windows of a sequence of replies as one in-memory Recording, and what happened."""
    model = context.model
    n = int(model["n_subcarriers"])
    bandwidth = float(model["bandwidth_hz"])
    length = int(round(model["window_s"] * bandwidth))
    rng_noise = context.streams["calibration" if context.calibration else "noise"]
    rng_payload = context.streams["payload"]
    rng_timing = context.streams["schedule"]
    t1_nominal = max(model["rtcal_s"], 10.0 / model["blf_hz"])
    tol = model["t1_tolerance"]
    sigma = 10.0 ** (-model["snr_db"] / 20.0)
    frequencies = fft_bin_frequencies(model)
    n_rx = len(context.rx)
    stored_complex = model["datatype"] == "cf32_le"
    data = np.empty((len(query_end) * length, n_rx, 2), dtype=np.int16) if not stored_complex else \
        np.empty((len(query_end) * length, n_rx), dtype=np.complex64)
    captures, annotations = [], []
    clipped = 0
    reply_start_s, blf_actual = [], []
    payload_bits = 16 if model["payload"] == "rn16" else 128
    for i, t_query in enumerate(query_end):
        start_index = int(np.ceil((t_query + t1_nominal * (1.0 - tol) - model["window_lead_s"]) * bandwidth))
        window_time = start_index / bandwidth
        t_reply = t_query + t1_nominal * (1.0 + rng_timing.uniform(-tol, tol))
        blf = model["blf_hz"] * blf_factor[i] * (1.0 + model["blf_jitter"] * rng_timing.standard_normal())
        bits = rng_payload.integers(0, 2, payload_bits)
        chips = reply_chips(model["encoding"], model["trext"], bits)
        chip_samples = bandwidth / (2.0 * blf)
        reply_sample = (t_reply - window_time) * bandwidth
        if answered[i]:
            levels = tag_levels(chips, length, reply_sample, chip_samples, model["idle_level"],
                                model["transition_s"] * bandwidth)
        else:
            levels = np.full(length, float(model["idle_level"]))
        tag = wideband.tag_channel(context.tx, context.rx, positions[i][None, :], frequencies, model["reflectors"])[0]
        tag_signal = _periodic(context.symbol, context.hardware * context.gamma * tag)  # (R, N)
        phase_index = (np.arange(length) + start_index) % n
        window = context.base[:, phase_index] + levels[None, :] * tag_signal[:, phase_index]
        noise = rng_noise.standard_normal((n_rx, length, 2)) * (sigma / np.sqrt(2.0))
        window = (window + noise[..., 0] + 1j * noise[..., 1]) * context.scale
        rows = slice(i * length, (i + 1) * length)
        if stored_complex:
            data[rows] = window.T.astype(np.complex64)
        else:
            parts = np.stack([window.real.T, window.imag.T], axis=-1)
            rounded = np.rint(parts)
            clipped += int(np.count_nonzero(np.abs(rounded) > 32767))
            data[rows] = np.clip(rounded, -32768, 32767).astype(np.int16)
        captures.append({
            "core:sample_start": i * length,
            "core:frequency": float(model["centre_frequency_hz"]),
            f"{NAMESPACE}:time_s": float(window_time),
            f"{NAMESPACE}:tx_sample_index": int(start_index),
        })
        annotations.append({
            "core:sample_start": i * length,
            "core:sample_count": length,
            "core:label": "tag reply",
            f"{NAMESPACE}:epc": epcs[i],
            f"{NAMESPACE}:query_end_s": float(t_query),
        })
        reply_start_s.append(float(t_reply))
        blf_actual.append(float(blf))
    meta = {"global": {}, "captures": captures, "annotations": annotations}
    recording = Recording(path=None, data_path=None, meta=meta, data=data, datatype=model["datatype"])
    record = {"reply_start_s": reply_start_s, "blf_hz": blf_actual, "clipped_components": clipped,
              "window_samples": length, "bytes": int(data.nbytes)}
    return recording, record


def _common_metadata(model, symbol, scene, tx_id, tx, rx_ids, rx, scale, seed) -> dict:
    """The global metadata both recordings share (see :func:`make_recording_metadata`)."""
    from scattertrack import __version__

    antennas = [{"id": int(tx_id), "position": tx.tolist(), "role": "tx"}]
    antennas += [{"id": int(i), "position": p.tolist(), "role": "rx"} for i, p in zip(rx_ids, rx)]
    resolved = {k: (list(v) if isinstance(v, tuple) else v) for k, v in model.items()}
    return make_recording_metadata(
        datatype=model["datatype"],
        bandwidth_hz=float(model["bandwidth_hz"]),
        subcarriers=int(model["n_subcarriers"]),
        centre_hz=float(model["centre_frequency_hz"]),
        blf_hz=float(model["blf_hz"]),
        encoding=model["encoding"],
        trext=bool(model["trext"]),
        known_symbol=symbol,
        tx_id=int(tx_id),
        channels=[int(i) for i in rx_ids],
        antennas=antennas,
        scale=float(scale),
        window_s=float(model["window_s"]),
        extra={"seed": int(seed), "model": resolved, "generator": "scattertrack.sim.iq", "version": __version__,
               "scene": scene.name},
    )


def _helper_scene(scene: Scene, model: dict) -> Scene:
    """The scene with a ``[helper]`` table of the OFDM keys (as :mod:`wideband` writes it)."""
    import copy

    out = copy.deepcopy(scene)
    out.reader.kind = "sdr-helper"
    out.extra = dict(out.extra)
    out.extra["helper"] = {
        "centre_frequency_hz": float(model["centre_frequency_hz"]),
        "bandwidth_hz": float(model["bandwidth_hz"]),
        "n_subcarriers": int(model["n_subcarriers"]),
        "blf_hz": float(model["blf_hz"]),
    }
    return out


def _truth(epcs, trajectories, query_end, duration_s) -> Truth:
    """Every tag's position and velocity on a 200 Hz grid covering the session (docs/formats.md 3)."""
    return wideband.truth_grid(epcs, trajectories, float(max(duration_s, query_end[-1] + 1e-3)), 200.0)


def write_iq_simulation(sim: IqSimulation, out_dir) -> Path:
    """Write ``recording.sigmf-*``, ``calibration.sigmf-*``, ``scene.toml``, ``truth.csv`` and ``simulation.json``."""
    from scattertrack.io import write_scene, write_truth
    from scattertrack.sim.simulation import write_record

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_sigmf(out / "recording", sim.recording)
    write_sigmf(out / "calibration", sim.calibration)
    write_scene(out / "scene.toml", sim.scene)
    write_truth(out / "truth.csv", sim.truth)
    write_record(out, "scattertrack.sim.iq", sim.seed, model=sim.model, details=sim.details)
    return out


IQ_DEFAULT_DURATION_S = 1.0
"""Seconds of IQ a scenario is simulated for unless told otherwise (IQ is
bulky: 480 kB per reply, about 144 MB per second at 300 replies/s)."""


def simulate_iq_scenario(scenario: dict, seed: int | None = None, duration_s: float | None = None, model: dict | None = None) -> IqSimulation:
    """A turbotrack scenario at IQ level: its helper, antennas, region and
    tag trajectories, the OFDM design (``centre_frequency_hz``,
    ``bandwidth_hz``, ``n_subcarriers``, ``blf_hz``) and reflectors of its
    ``[helper_model]``, every other IQ key at :data:`IQ_MODEL_DEFAULTS`
    unless the scenario has an ``[iq_model]`` table or ``model`` overrides
    it. ``duration_s``: default :data:`IQ_DEFAULT_DURATION_S` (not the
    scenario's, usually tens of seconds). Same inputs, same output.
    """
    from scattertrack.sim.scenario import _simulate_helper
    from scattertrack.sim.scenario_resolve import resolve_scenario

    if seed is not None:
        scenario = {**scenario, "seed": seed}
    data = resolve_scenario(scenario)
    if data["pipeline"] != "turbotrack":
        raise ValueError(f"scenario {data.get('name', '?')!r} is for the {data['pipeline']} pipeline; IQ needs a turbotrack scenario")
    # The frame-level run builds the helper scene and seeds random trajectories.
    frame_level = _simulate_helper({**data, "duration_s": min(float(data["duration_s"]), 0.05)})
    helper = data["helper_model"]
    iq_model = {key: helper[key] for key in wideband.OFDM_KEYS}
    if helper.get("reflectors"):
        iq_model["reflectors"] = helper["reflectors"]
    iq_model.update(scenario.get("iq_model", {}))
    iq_model.update(model or {})
    tags = {tag["epc"]: tag["trajectory"] for tag in data["tags"]}
    duration = IQ_DEFAULT_DURATION_S if duration_s is None else float(duration_s)
    return simulate_iq(frame_level.scene, tags, iq_model, int(data["seed"]), duration_s=duration)
