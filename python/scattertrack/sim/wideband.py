"""The SDR localization helper at frame level: wideband channel physics and a fast simulator.

TurboTrack's helper (thesis ch. 4 and 6) has one transmit antenna and several
receive antennas. It sends OFDM symbols (``N`` subcarriers over a bandwidth
``B``) while a tag replies to the reader; every reply gives, per receive
antenna, the tag's channel ``h(f)`` at every subcarrier ("one-shot wideband
estimation": mean of the reflective symbols minus mean of the non-reflective
ones, sec. 4.3). One such set of channels is a *frame* (docs/formats.md section 5).

The channel physics (:func:`bistatic_path_lengths`,
:func:`subcarrier_frequencies`, :func:`tag_channel`, :func:`static_channel`,
the channel convention and the multipath model) lives in
:mod:`scattertrack.dsp.channel`, which the helper's DSP calibrates against;
this module imports it (so ``sim.wideband.tag_channel`` still names it) and
adds

Calibration residuals (pure numpy)
    :func:`calibration_path_errors_m`, :func:`calibration_shift_m`,
    :func:`drawn_calibration_shift_m`: where a calibration error alone moves
    a static tag.

Frame-level simulator
    :func:`simulate_frames` turns tag trajectories into frames as the
    helper's DSP would output them after calibration, with the impairments
    of :data:`HELPER_MODEL_DEFAULTS`, without simulating IQ samples (fast:
    a 20 s session at 300 frames/s takes well under a second).

Units: metres, seconds, hertz, radians; SNRs and powers in dB.
"""

from __future__ import annotations

import copy

import numpy as np

from scattertrack.dsp.channel import (  # noqa: F401 - the helper's channel physics, exported by scattertrack.sim
    DIRECT_LEAKAGE,
    REFERENCE_DISTANCE_M,
    bent_leg_lengths,
    bistatic_path_lengths,
    static_channel,
    subcarrier_frequencies,
    tag_channel,
)
from scattertrack.io.frames import Frames, make_frames
from scattertrack.io.types import Truth
from scattertrack.physics import SPEED_OF_LIGHT
from scattertrack.sim import cots
from scattertrack.sim.scenario_checks import Checker, check_reflectors
from scattertrack.sim.trajectory import positions_velocities


# --------------------------------------------------------------------------
# calibration residuals


def calibration_path_errors_m(frequencies_hz, phase_rad, delay_s) -> np.ndarray:
    """The path error, metres, that each rx's calibration residual puts on a tag's distance, shape (R,).

    The residual turns the channel ``exp(-j 2 pi f L / c)`` into
    ``exp(-j (2 pi f L / c + phi_r + 2 pi f tau_r))`` (see
    :func:`channel_estimates`). A distance that fits the phase over every
    subcarrier (least squares through the origin: no free phase constant,
    the calibration removed it) sees
    ``dL_r = c tau_r + c phi_r sum(f) / (2 pi sum(f^2))``:
    the delay adds ``c tau_r`` of path at every frequency, the phase about
    ``phi_r lambda / (2 pi)`` at the centre frequency.
    ``frequencies_hz`` (F,); ``phase_rad``, ``delay_s`` (R,).
    """
    f = np.asarray(frequencies_hz, dtype=np.float64).reshape(-1)
    phase = np.asarray(phase_rad, dtype=np.float64).reshape(-1)
    delay = np.asarray(delay_s, dtype=np.float64).reshape(-1)
    return SPEED_OF_LIGHT * (delay + phase * f.sum() / (2.0 * np.pi * np.sum(f * f)))


def calibration_shift_m(tx, rx, tag, path_errors_m, iterations: int = 5) -> np.ndarray:
    """Where a calibration residual alone moves a static tag: the position error, metres, (3,).

    The position ``p`` whose bistatic path lengths best match the true ones
    plus ``path_errors_m`` (R,), by unweighted least squares (Gauss-Newton
    from the true position ``tag`` (3,); ``tx`` (3,), ``rx`` (R, 3) m),
    minus the true position. A tracker given noiseless frames with this
    residual cannot do better: the residual is a constant bias that no
    number of frames averages away, and with R = 4 receivers in 3D only one
    path is redundant. It is the floor under a static tag's error in the
    frame-level simulator (docs/turbotrack.md, "Measured").
    """
    tx = np.asarray(tx, dtype=np.float64).reshape(3)
    rx = np.asarray(rx, dtype=np.float64).reshape(-1, 3)
    truth = np.asarray(tag, dtype=np.float64).reshape(3)
    target = bistatic_path_lengths(tx, rx, truth)[0] + np.asarray(path_errors_m, dtype=np.float64).reshape(-1)
    p = truth.copy()
    for _ in range(int(iterations)):
        # d L_r / d p = unit(p - tx) + unit(p - rx_r)
        jacobian = (p - tx) / np.linalg.norm(p - tx) + (p - rx) / np.linalg.norm(p - rx, axis=1)[:, None]
        residual = target - bistatic_path_lengths(tx, rx, p)[0]
        p = p + np.linalg.lstsq(jacobian, residual, rcond=None)[0]
    return p - truth


def drawn_calibration_shift_m(scene, details: dict, tag) -> np.ndarray:
    """:func:`calibration_shift_m` of the residuals a frame-level simulation
    drew: ``details`` as :func:`frames_from_trajectories` returns it (its
    subcarriers and ``true_calibration_*`` per rx id), the scene's helper
    antennas, a tag at ``tag`` (3,) m. The position error, metres, (3,)."""
    _, tx, rx_ids, rx = helper_geometry(scene)
    errors = calibration_path_errors_m(
        details["subcarriers_hz"],
        [details["true_calibration_phase_error_rad"][int(i)] for i in rx_ids],
        [details["true_calibration_delay_error_s"][int(i)] for i in rx_ids],
    )
    return calibration_shift_m(tx, rx, tag, errors)


# --------------------------------------------------------------------------
# the frame-level simulator

HELPER_MODEL_DEFAULTS = {
    # OFDM and the reader link (thesis ch. 6: N = 20 over 100 MHz, BLF 40 kHz)
    "centre_frequency_hz": 915e6,  # Hz, midway between the two middle subcarriers
    "bandwidth_hz": 100e6,  # Hz, the OFDM sample rate B (subcarriers B / N apart)
    "n_subcarriers": 20,  # N; must satisfy N < B / (2 BLF) (sec. 4.2)
    "blf_hz": 40e3,  # Hz, the tag's backscatter link frequency set by the reader
    # reply schedule (cots.read_schedule with one "antenna": every rx listens at once)
    "round_overhead_s": 0.0003,  # s per inventory round (Query)
    "slot_s": 0.003,  # s per tag reply slot: one tag gets 1 / 3.3 ms = 303 attempts/s
    "round_jitter_cv": 0.3,  # coefficient of variation of the gamma round-length factor
    "miss_probability": 0.02,  # a reply lost on every antenna (collision, no preamble found)
    "rx_miss_probability": 0.01,  # one receive antenna loses a reply the others decode
    "dropout_burst_rate_hz": 0.0,  # 1/s, Poisson bursts silencing one tag
    "dropout_burst_mean_s": 0.3,  # s, mean burst length (exponential)
    # channel estimate
    "snr_db": 23.0,  # dB per subcarrier for a tag d_ref = 1 m from tx and rx (see channel_estimates)
    "calibration_phase_error_rad": 0.05,  # rad, 1-sigma residual phase per rx after calibration
    "calibration_delay_error_s": 1e-11,  # s, 1-sigma residual delay per rx (1e-11 s = 3 mm of path)
    "outlier_probability": 0.005,  # chance a frame is hit by an interference burst
    "outlier_power_db": 3.0,  # dB, burst power per subcarrier relative to a tag at d_ref (|h| = 1)
    "reflectors": [],  # multipath: point scatterers and plane mirrors (module docstring)
}
"""Every ``[helper_model]`` key with its default (units in the comments).

Why these values: the schedule gives the paper's 300 frames/s for one tag
(sec. 7.1 (b)), shared between tags. The SNR: a tag 1 m from both antennas
gives 23 dB per subcarrier after the reply's symbols are averaged, so the
per-subcarrier phase noise ``1 / sqrt(2 SNR)`` is 0.05 rad at 1 m and
0.2 rad with both legs 2 m (amplitude 1/4, 11 dB); the helper's effective
SNR is limited less by thermal noise than by the residual of the 50-60 dB
stronger direct leakage and oscillator phase noise. The calibration
residuals are those of a one-time calibration with a tag at a known
position (sec. 4.3): a few millimetres of path. These values are not tuned
to any tracker."""

OFDM_KEYS = ("centre_frequency_hz", "bandwidth_hz", "n_subcarriers", "blf_hz")
"""The model keys a helper scene records in its ``[helper]`` table (what a user's hardware sets)."""

STREAMS = ("schedule", "misses", "bursts", "rx_misses", "calibration", "noise", "outliers", "trajectories")
"""Independent random streams, one per process, so switching one impairment
on or off leaves the others' draws unchanged."""


def helper_streams(seed: int) -> dict[str, np.random.Generator]:
    """One generator per name in :data:`STREAMS`, split from ``numpy.random.default_rng(seed)``."""
    return dict(zip(STREAMS, np.random.default_rng(seed).spawn(len(STREAMS))))


def helper_geometry(scene) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The helper's antennas: ``(tx id, tx position (3,) m, rx ids (R,), rx positions (R, 3) m)``.

    Receive antennas in scene order. Raises ValueError unless the scene has
    exactly one ``role = "tx"`` antenna and at least one ``role = "rx"``.
    """
    tx = [a for a in scene.antennas if a.role == "tx"]
    rx = [a for a in scene.antennas if a.role == "rx"]
    if len(tx) != 1 or not rx:
        raise ValueError(
            f"scene {scene.name!r}: a helper needs exactly one antenna with role 'tx' and at least one "
            f"with role 'rx', found {len(tx)} and {len(rx)}"
        )
    return (
        int(tx[0].id),
        np.asarray(tx[0].position, dtype=np.float64).copy(),
        np.array([a.id for a in rx], dtype=np.int64),
        np.array([a.position for a in rx], dtype=np.float64).reshape(-1, 3),
    )


def model_frequencies(model: dict) -> np.ndarray:
    """The subcarriers (Hz) of a helper model's OFDM parameters (:func:`subcarrier_frequencies`)."""
    return subcarrier_frequencies(model["centre_frequency_hz"], model["bandwidth_hz"], model["n_subcarriers"])


def reply_schedule(
    duration_s: float, n_tags: int, model: dict, rngs: dict[str, np.random.Generator]
) -> tuple[np.ndarray, np.ndarray, int]:
    """Tag replies the helper decodes: ``(time_s (K,), tag index (K,), attempts)``, sorted by time.

    The reader singulates every tag once per inventory round in random order
    (:func:`scattertrack.sim.cots.read_schedule` with one antenna slot: the
    helper's receive antennas all listen to every reply); a round lasts
    ``(round_overhead_s + n_tags slot_s) G``, G gamma with mean 1 and
    coefficient of variation ``round_jitter_cv``. Replies are then lost with
    ``miss_probability`` and during dropout bursts. Times in
    ``[0, duration_s)``, rounded to 1 microsecond.
    """
    schedule_model = {**model, "rounds_per_antenna": 1, "dropout_burst_scope": "tag"}
    one_slot = np.zeros(1, dtype=np.int64)  # every rx hears every reply: one "antenna" in the round model
    time, antenna, tag = cots.read_schedule(duration_s, one_slot, n_tags, schedule_model, rngs["schedule"])
    keep = cots.dropout_mask(
        time, antenna, tag, 1, n_tags, duration_s, schedule_model, rngs["misses"], rngs["bursts"]
    )
    return time[keep], tag[keep], len(time)


def channel_estimates(
    tx,
    rx,
    tag_positions,
    frequencies_hz,
    model: dict,
    calibration_phase_rad: np.ndarray,
    calibration_delay_s: np.ndarray,
    rngs: dict[str, np.random.Generator],
) -> tuple[np.ndarray, np.ndarray]:
    """Calibrated channel estimates (K, R, F) of K replies, and which frames are outliers (K,).

    ``h = tag_channel(...) * exp(-j (phi_r + 2 pi f tau_r)) + n + i``: the
    residual calibration error of each rx (phase ``phi_r`` rad, delay
    ``tau_r`` s: a positive delay looks like ``c tau_r`` more path), white
    complex Gaussian noise ``n ~ CN(0, sigma^2)`` independent per frame, rx
    and subcarrier with ``sigma = 10^(-snr_db / 20)`` (so ``snr_db`` is the
    per-subcarrier SNR of a tag at d_ref, ``|h| = 1``; a tag with both legs
    at 2 m has ``|h| = 1/4``, 12 dB less), and on outlier frames an
    interference burst ``i ~ CN(0, 10^(outlier_power_db / 10))`` on every rx
    and subcarrier.
    """
    frequencies_hz = np.asarray(frequencies_hz, dtype=np.float64)
    h = tag_channel(tx, rx, tag_positions, frequencies_hz, model["reflectors"])
    residual = calibration_phase_rad[:, None] + 2.0 * np.pi * frequencies_hz[None, :] * calibration_delay_s[:, None]
    h *= np.exp(-1j * residual)[None, :, :]
    sigma = 10.0 ** (-model["snr_db"] / 20.0)
    h += _complex_gaussian(rngs["noise"], h.shape, sigma)
    outlier = rngs["outliers"].random(len(h)) < model["outlier_probability"]
    burst_sigma = 10.0 ** (model["outlier_power_db"] / 20.0)
    burst = _complex_gaussian(rngs["outliers"], (int(outlier.sum()),) + h.shape[1:], burst_sigma)
    h[outlier] += burst
    return h, outlier


def _complex_gaussian(rng: np.random.Generator, shape, sigma: float) -> np.ndarray:
    """Circular complex Gaussian samples with E|n|^2 = sigma^2 (sigma / sqrt 2 per component)."""
    draws = rng.standard_normal(tuple(shape) + (2,)) * (sigma / np.sqrt(2.0))
    return draws[..., 0] + 1j * draws[..., 1]


def simulate_frames(
    scene,
    tags,
    model: dict | None = None,
    seed: int = 0,
    *,
    duration_s: float | None = None,
    truth_rate_hz: float = 200.0,
) -> tuple[Frames, Truth]:
    """Simulate the frames a reader + localization helper would output: ``(Frames, Truth)``.

    ``scene``: a helper scene (one ``role = "tx"`` antenna, ``role = "rx"``
    ones; its ``[helper]`` table, if any, gives the OFDM parameters).
    ``tags``: either ``{epc: trajectory dict}`` (kinds of
    :mod:`scattertrack.sim.trajectory`, evaluated exactly at every frame
    time; truth sampled at ``truth_rate_hz`` over ``[0, duration_s]``,
    ``duration_s`` default 20 s) or a :class:`~scattertrack.io.Truth`
    (interpolated linearly at the frame times; frames span the truth's time
    range, and it is returned as given). ``model``: keys of
    :data:`HELPER_MODEL_DEFAULTS` overriding the defaults (and the scene's
    ``[helper]`` values). Every random draw comes from
    ``numpy.random.default_rng(seed)`` split into :data:`STREAMS`: the same
    inputs and seed give identical frames.

    What happens: :func:`reply_schedule` draws the replies (about 300
    frames/s for one tag, shared between tags, random gaps, misses and
    dropouts); :func:`channel_estimates` gives each reply's channel on every
    rx and subcarrier; a (frame, rx) pair is lost with
    ``rx_miss_probability``. Not modelled: the EMA smoothing of the DSP, tag
    motion within one reply (about 1 ms), antenna and tag radiation
    patterns, second-order (two-bounce) multipath.
    """
    rngs = helper_streams(seed)
    if isinstance(tags, Truth):
        frames, truth, _ = frames_from_truth(scene, tags, model, rngs)
        return frames, truth
    duration_s = 20.0 if duration_s is None else float(duration_s)
    epcs = [str(epc) for epc in tags]
    trajectories = [dict(tags[epc]) for epc in tags]
    for params in trajectories:
        if params.get("kind") == "random":
            params.setdefault("seed", int(rngs["trajectories"].integers(2**31)))
    frames, _ = frames_from_trajectories(scene, epcs, trajectories, duration_s, model, rngs)
    return frames, truth_grid(epcs, trajectories, duration_s, truth_rate_hz)


def resolve_helper_model(given: dict, source: str = "<helper_model>", key: str = "") -> dict:
    """A helper model with every default of :data:`HELPER_MODEL_DEFAULTS` filled in, validated.

    Raises :class:`FormatError` naming ``source`` and the key (prefixed by
    ``key``, e.g. ``"helper_model."``) for an unknown key or a bad value,
    including OFDM symbols too long for the tag's switching: the thesis's
    rule ``N < B / (2 BLF)`` (sec. 4.2).
    """
    check = Checker(source)
    defaults = HELPER_MODEL_DEFAULTS
    check.table(given, key.rstrip(".") or "helper_model")
    check.keys(given, defaults, key.rstrip("."))
    model = {name: copy.deepcopy(given.get(name, default)) for name, default in defaults.items()}
    for name in ("centre_frequency_hz", "bandwidth_hz", "blf_hz", "slot_s", "dropout_burst_mean_s"):
        model[name] = check.number(model[name], key + name, 0.0, strict=True)
    for name in (
        "round_overhead_s",
        "round_jitter_cv",
        "dropout_burst_rate_hz",
        "calibration_phase_error_rad",
        "calibration_delay_error_s",
    ):
        model[name] = check.number(model[name], key + name, 0.0)
    for name in ("miss_probability", "rx_miss_probability"):
        model[name] = check.number(model[name], key + name, 0.0, maximum=0.99)
    model["outlier_probability"] = check.number(
        model["outlier_probability"], key + "outlier_probability", 0.0, maximum=1.0
    )
    for name in ("snr_db", "outlier_power_db"):
        model[name] = check.number(model[name], key + name)
    model["n_subcarriers"] = check.integer(model["n_subcarriers"], key + "n_subcarriers", 1)
    if model["centre_frequency_hz"] <= model["bandwidth_hz"] / 2.0:
        check.fail(key + "centre_frequency_hz", "must exceed half the bandwidth (every subcarrier above 0 Hz)")
    longest = model["bandwidth_hz"] / (2.0 * model["blf_hz"])
    if not model["n_subcarriers"] < longest:
        check.fail(
            key + "n_subcarriers",
            f"an OFDM symbol of {model['n_subcarriers']} samples at {model['bandwidth_hz']:g} samples/s is longer "
            f"than half the tag's switching period 1 / (2 BLF): need N < B / (2 BLF) = {longest:g}",
        )
    check_reflectors(check, model["reflectors"], key)
    return model


def resolved_model(scene, model: dict | None) -> dict:
    """Defaults, then the scene's ``[helper]`` OFDM values, then ``model``; validated."""

    recorded = scene.extra.get("helper", {}) if isinstance(scene.extra.get("helper"), dict) else {}
    given = {key: recorded[key] for key in OFDM_KEYS if key in recorded}
    given.update(model or {})
    return resolve_helper_model(given)


def frames_from_trajectories(scene, epcs, trajectories, duration_s, model, rngs) -> tuple[Frames, dict]:
    """Frames of tags on trajectories over ``[0, duration_s)`` seconds: ``(Frames, details)``.

    ``epcs`` and ``trajectories`` (dicts of :mod:`scattertrack.sim.trajectory`)
    pair up; ``model`` as in :func:`simulate_frames`; ``rngs`` from
    :func:`helper_streams`. ``details`` holds the subcarriers (Hz), the true
    calibration residual of each rx id (rad, s) and counts (reply attempts,
    replies, frames, dropped, rx misses, outlier frames, frames per tag).
    """

    def positions(index, times):
        return positions_velocities(trajectories[index], times)[0]

    return _frames(scene, epcs, positions, 0.0, float(duration_s), model, rngs)


def frames_from_truth(scene, truth, model, rngs) -> tuple[Frames, Truth, dict]:
    """Frames of tags following a ground truth: ``(Frames, truth, details)``.

    Positions are interpolated linearly at the frame times; frames span the
    truth's time range (each tag only within its own rows' range). Otherwise
    as :func:`frames_from_trajectories`.
    """
    epcs = list(dict.fromkeys(str(e) for e in truth.epc.tolist()))
    # Each tag's rows in time order (np.interp needs increasing times).
    rows = []
    for epc in epcs:
        index = np.flatnonzero(truth.epc == epc)
        rows.append(index[np.argsort(truth.time_s[index], kind="stable")])
    start, end = float(np.min(truth.time_s)), float(np.max(truth.time_s))

    def positions(index, times):
        t, p = truth.time_s[rows[index]], truth.position[rows[index]]
        return np.column_stack([np.interp(times, t, p[:, k]) for k in range(3)])

    def covered(index, times):
        t = truth.time_s[rows[index]]
        return (times >= t[0]) & (times <= t[-1])

    frames, details = _frames(scene, epcs, positions, start, end - start, model, rngs, covered)
    return frames, truth, details


def _frames(scene, epcs, positions, start_s, duration_s, model, rngs, covered=None):
    """The simulator's core: schedule, channels, losses, rows. Returns ``(Frames, details)``."""
    model = resolved_model(scene, model)
    tx_id, tx, rx_ids, rx = helper_geometry(scene)
    frequencies = model_frequencies(model)
    n_rx = len(rx_ids)
    time, tag, attempts = reply_schedule(duration_s, len(epcs), model, rngs)
    time = np.round((time + start_s) * 1e6) / 1e6
    if covered is not None:  # a truth may not cover every tag over the whole span
        keep = np.ones(len(time), dtype=bool)
        for index in range(len(epcs)):
            rows = tag == index
            keep[rows] = covered(index, time[rows])
        time, tag = time[keep], tag[keep]
    tag_positions = np.empty((len(time), 3))
    for index in range(len(epcs)):
        rows = tag == index
        tag_positions[rows] = positions(index, time[rows])

    calibration = rngs["calibration"]
    phase_error = model["calibration_phase_error_rad"] * calibration.standard_normal(n_rx)
    delay_error = model["calibration_delay_error_s"] * calibration.standard_normal(n_rx)
    h, outlier = channel_estimates(tx, rx, tag_positions, frequencies, model, phase_error, delay_error, rngs)

    heard = rngs["rx_misses"].random((len(time), n_rx)) >= model["rx_miss_probability"]  # (K, R)
    rows = np.broadcast_to(heard[:, :, None], h.shape)
    shape = h.shape
    epc_array = np.asarray(epcs, dtype=str)
    frames = make_frames(
        time_s=np.broadcast_to(time[:, None, None], shape)[rows],
        epc=np.broadcast_to(epc_array[tag][:, None, None], shape)[rows] if len(time) else np.array([], dtype=str),
        tx=np.full(int(rows.sum()), tx_id, dtype=np.int64),
        rx=np.broadcast_to(rx_ids[None, :, None], shape)[rows],
        frequency_hz=np.broadcast_to(frequencies[None, None, :], shape)[rows],
        h=h[rows],
    )
    silent = ~heard.any(axis=1)
    details = {
        "subcarriers_hz": [float(f) for f in frequencies],
        "true_calibration_phase_error_rad": {int(i): float(v) for i, v in zip(rx_ids, phase_error)},
        "true_calibration_delay_error_s": {int(i): float(v) for i, v in zip(rx_ids, delay_error)},
        "counts": {
            "reply_attempts": int(attempts),
            "replies": int(len(time)),
            "frames": int(frames.n_frames),
            "dropped": int(attempts - len(time)),
            "rx_misses": int((~heard).sum()),
            "frames_lost_on_every_rx": int(silent.sum()),
            "outlier_frames": int(outlier[~silent].sum()),
            "frames_per_tag": {epc: int(np.sum(frames.frame_epc == epc)) for epc in epcs},
        },
    }
    return frames, details


def truth_grid(epcs: list[str], trajectories: list[dict], duration_s: float, rate_hz: float) -> Truth:
    """Every tag's true position and velocity on a regular grid over ``[0, duration_s]``, time-major."""
    times = np.arange(int(np.floor(duration_s * rate_hz + 1e-9)) + 1) / rate_hz
    position = np.empty((len(times), len(epcs), 3))
    velocity = np.empty((len(times), len(epcs), 3))
    for index, params in enumerate(trajectories):
        position[:, index], velocity[:, index] = positions_velocities(params, times)
    return Truth(
        time_s=np.repeat(times, len(epcs)),
        epc=np.tile(np.asarray(epcs, dtype=str), len(times)),
        position=position.reshape(-1, 3),
        velocity=velocity.reshape(-1, 3),
    )
