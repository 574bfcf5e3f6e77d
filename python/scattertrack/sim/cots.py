"""A commercial (COTS, LLRP) UHF RFID reader: read schedule and phase model.

What it reproduces (every impairment a documented, seeded parameter; the
defaults are in :data:`READER_MODEL_DEFAULTS`, the user guide is
``docs/simulator.md``):

Schedule
    One antenna is active at a time; antennas take turns in
    ``antenna_order`` (round-robin), ``rounds_per_antenna`` inventory rounds
    each. An inventory round reads every tag in the field once, in random
    order; it lasts ``(round_overhead_s + n_tags * slot_s) * G`` seconds with
    ``G`` gamma distributed (mean 1, coefficient of variation
    ``round_jitter_cv``). The tag ranked ``j`` in a round is reported at the
    end of its slot. With one tag the defaults give 1 / 0.033 s = 30.3 reads/s
    (29.4 after 3 % misses); with more tags the rounds get longer and each tag
    gets fewer reads (the read budget is shared). A read is missed with
    probability ``miss_probability``, and longer dropout bursts (a Poisson
    process of rate ``dropout_burst_rate_hz``, exponential durations of mean
    ``dropout_burst_mean_s``) silence one tag (``dropout_burst_scope =
    "tag"``) or one tag-antenna link (``"link"``); scheduled outages
    (``dropout_windows``, ``[start_s, end_s]`` pairs) silence every tag.
    Time stamps are rounded to 1 microsecond, as LLRP reports them.

Carrier
    One fixed channel (``frequency_hz``, default 915.25 MHz) or, with
    ``hopping = true``, a pseudo-random hop table over ``channels_hz``
    (default the 50 US channels 902.75 + 0.5 k MHz, k = 0..49), one channel per
    ``hop_dwell_s`` (0.2 s), the table repeating.

Phase (docs/formats.md section 1)
    ``phase = (phase_sign * 4 pi f d / c + multipath + antenna offset
    + channel offset(f) + tag offset + white noise + wander) mod P``, then an
    outlier (with probability ``outlier_probability``) is replaced by a
    uniform value in ``[0, P)``, and the result is rounded to steps of
    ``phase_step_units * 2 pi / 4096`` (Impinj reports 0-4095 in units of
    2 pi / 4096; 0 switches rounding off).

Multipath
    Reflectors add paths: image sources for planes, point scatterers. With
    one-way path lengths ``d_p`` and amplitudes ``a_p = coefficient_p / d_p``
    (``a_0 = 1 / d`` for the direct path), the monostatic round-trip channel
    is ``h = (sum_p a_p exp(-j 2 pi f d_p / c))^2`` (reciprocity: the same
    paths out and back). For the direct path alone ``arg h = -4 pi f d / c``,
    so the phase term is ``phase_sign * (-arg h)``, which we evaluate as
    ``phase_sign * (4 pi f d / c + excess)`` with the multipath excess
    ``excess = -arg(h * exp(+j 4 pi f d / c))`` (numerically clean, and zero
    without reflectors).

RSSI
    Monostatic radar equation: ``tx_power_dbm + 2 antenna_gain_dbi
    + 2 tag_gain_dbi - backscatter_loss_db + 20 log10(|h| (c / 4 pi f)^2)``,
    which for the direct path is the free-space ``-40 log10(d)`` round trip;
    plus Gaussian noise ``rssi_noise_db`` and rounding to ``rssi_step_db``.

Doppler
    ``f_D = -2 v_r f / c`` with ``v_r`` the radial velocity of the tag away
    from the antenna (d d / d t, direct path): positive when the tag
    approaches, negative when it recedes (the physical Doppler shift of the
    reflected carrier, whatever the reader's ``phase_sign``); plus Gaussian
    noise ``doppler_noise_hz`` and rounding to ``doppler_step_hz`` (Impinj
    reports 1/16 Hz units).

Units: seconds, metres, hertz, radians, dBm / dB.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.hop_table import US_PLAN_HZ
from scattertrack.io.types import Reads
from scattertrack.physics import SPEED_OF_LIGHT, round_trip_channel
from scattertrack.sim.trajectory import positions_velocities

US_CHANNELS_HZ = US_PLAN_HZ
"""The 50 FCC UHF RFID channels, Hz: 902.75 + 0.5 k MHz, k = 0..49 (io.hop_table's plan)."""

PHASE_UNIT_RAD = 2.0 * np.pi / 4096.0
"""One Impinj phase unit (12 bits over 2 pi), radians."""

NOISE_PROFILES = {
    # The default: white noise as in the papers' simulations plus a modest
    # slow wander, so trackers meet both.
    "default": {"white_noise_rad": 0.1, "wander_rad": 0.05, "wander_time_s": 0.5},
    # The GLAC paper's assumption: sigma_phi = 0.1 rad white, no wander.
    "paper": {"white_noise_rad": 0.1, "wander_rad": 0.0, "wander_time_s": 0.5},
    # Static-tag logs from real readers: read-to-read jitter is small
    # (~0.015 rad), but the phase wanders by 0.05-0.1 rad over ~0.5 s.
    "measured": {"white_noise_rad": 0.015, "wander_rad": 0.07, "wander_time_s": 0.5},
}
"""Shortcuts for the phase noise keys (``noise_profile``); explicit keys override them."""

READER_MODEL_DEFAULTS = {
    # schedule
    "antenna_order": None,  # list of antenna ids; None: the scene's order
    "rounds_per_antenna": 1,  # inventory rounds before switching antenna
    "round_overhead_s": 0.027,  # s, Query / antenna switch / round bookkeeping
    "slot_s": 0.006,  # s per tag singulated in a round
    "round_jitter_cv": 0.3,  # coefficient of variation of the gamma round-length factor
    "miss_probability": 0.03,  # per read
    "dropout_burst_rate_hz": 0.0,  # bursts per second per tag (or per link)
    "dropout_burst_mean_s": 0.3,  # s, mean burst length (exponential)
    "dropout_burst_scope": "tag",  # "tag" or "link"
    "dropout_windows": [],  # list of [start_s, end_s]: scheduled outages, no reads of any tag
    # carrier
    "frequency_hz": 915.25e6,  # Hz, the fixed channel when not hopping
    "hopping": False,
    "channels_hz": None,  # list of Hz; None: US_CHANNELS_HZ
    "hop_dwell_s": 0.2,  # s per channel
    "report_channel_index": False,  # write the reader's channel_index (1-based into its shuffled hop table)
    "log_frequency": True,  # False: frequency_hz is the plan in index order, as an importer without the hop table writes it
    # offsets
    "antenna_phase_offsets": "random",  # "random" (uniform [0, 2 pi)) or "zero"
    "antenna_offset_calibration_error_rad": 0.0,  # 1-sigma error of the written offsets
    "write_antenna_offsets": True,  # False: scene.toml states 0 (an uncalibrated installation)
    "channel_phase_offsets": "random",  # when hopping: "random" or "zero"
    "write_channel_offsets": True,  # write [[channel_offsets]] to scene.toml when hopping
    "channel_offset_calibration_error_rad": 0.0,  # 1-sigma error of the written offsets
    "tag_phase_offset_rad": 0.0,  # rad, or "random" (uniform [0, 2 pi) per tag)
    # noise
    "noise_profile": "default",  # see NOISE_PROFILES
    "white_noise_rad": None,  # 1-sigma, rad; None: from the profile
    "wander_rad": None,  # stationary 1-sigma of the Ornstein-Uhlenbeck wander, rad
    "wander_time_s": None,  # correlation time of the wander, s
    "wander_scope": "antenna",  # "antenna" (one process per port) or "link" (per tag-antenna pair)
    "phase_step_units": 1,  # rounding step in units of 2 pi / 4096; 0: none
    "outlier_probability": 0.0,  # per read: phase replaced by uniform [0, P)
    "reflectors": [],  # list of {kind = "plane"|"point", ...}
    # RSSI
    "report_rssi": True,
    "tag_gain_spread_db": 0.0,  # 1-sigma per tag and antenna RSSI offset, dB (tag orientation under CP antennas)
    "tx_power_dbm": 30.0,
    "antenna_gain_dbi": 6.0,
    "tag_gain_dbi": 0.0,
    "backscatter_loss_db": 10.0,  # modulation and tag losses, dB
    "rssi_noise_db": 1.0,  # 1-sigma, dB
    "rssi_step_db": 0.5,  # dB; 0: no rounding
    # Doppler
    "report_doppler": True,
    "doppler_noise_hz": 2.0,  # 1-sigma, Hz
    "doppler_step_hz": 0.0625,  # Hz; 0: no rounding
}
"""Every ``[reader_model]`` key with its default (units in the comments)."""



def resolve_noise(model: dict) -> dict:
    """The model with ``white_noise_rad``, ``wander_rad``, ``wander_time_s`` filled from its profile."""
    resolved = dict(model)
    profile = NOISE_PROFILES[model["noise_profile"]]
    for key, value in profile.items():
        if resolved.get(key) is None:
            resolved[key] = value
    return resolved


def read_schedule(
    duration_s: float, antenna_order: np.ndarray, n_tags: int, model: dict, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read attempts of an LLRP reader before misses: (time_s, antenna slot, tag index).

    ``antenna_order`` holds indices into the scene's antennas in the order the
    reader visits them. Returns arrays sorted by time: read time (s, in
    ``[0, duration_s)``, rounded to 1 us), the antenna index (into the
    scene's antennas) and the tag index. Every round reads every tag once.
    """
    nominal = model["round_overhead_s"] + n_tags * model["slot_s"]  # s per round
    cv = model["round_jitter_cv"]
    n_rounds = int(np.ceil(duration_s / nominal * 1.3)) + 20
    start_offset = rng.uniform(0.0, nominal)  # the reader was started at an arbitrary moment
    while True:
        if cv > 0.0:
            # Gamma with shape k = 1/cv^2 and scale cv^2 has mean 1 and the given cv.
            factor = rng.gamma(1.0 / cv**2, cv**2, size=n_rounds)
        else:
            factor = np.ones(n_rounds)
        length = nominal * factor
        round_start = start_offset + np.concatenate([[0.0], np.cumsum(length)[:-1]])
        if round_start[-1] + length[-1] >= duration_s:
            break
        n_rounds *= 2  # rare: an unlucky run of long rounds; draw again, longer
    round_index = np.arange(n_rounds)
    antenna = antenna_order[(round_index // model["rounds_per_antenna"]) % len(antenna_order)]
    # Random singulation order within each round (the Q algorithm's slots).
    rank = np.argsort(rng.random((n_rounds, n_tags)), axis=1).argsort(axis=1)
    fraction = (model["round_overhead_s"] + (rank + 1) * model["slot_s"]) / nominal
    time = round_start[:, None] + length[:, None] * fraction
    time = np.round(time * 1e6) / 1e6
    tag = np.broadcast_to(np.arange(n_tags), (n_rounds, n_tags))
    antenna = np.broadcast_to(antenna[:, None], (n_rounds, n_tags))
    time, antenna, tag = time.ravel(), antenna.ravel(), tag.ravel()
    order = np.argsort(time, kind="stable")
    time, antenna, tag = time[order], antenna[order], tag[order]
    keep = time < duration_s
    return time[keep], antenna[keep], tag[keep]


def dropout_mask(
    time_s: np.ndarray,
    antenna: np.ndarray,
    tag: np.ndarray,
    n_antennas: int,
    n_tags: int,
    duration_s: float,
    model: dict,
    miss_rng: np.random.Generator,
    burst_rng: np.random.Generator,
) -> np.ndarray:
    """Boolean mask of read attempts that succeed (not missed, not in a dropout burst)."""
    keep = miss_rng.random(len(time_s)) >= model["miss_probability"]
    rate = model["dropout_burst_rate_hz"]
    if rate > 0.0:
        mean = model["dropout_burst_mean_s"]
        per_link = model["dropout_burst_scope"] == "link"
        group = tag * n_antennas + antenna if per_link else tag
        n_groups = n_tags * n_antennas if per_link else n_tags
        # Bursts may start before t = 0 and still cover its beginning.
        lead = 5.0 * mean
        for g in range(n_groups):
            count = burst_rng.poisson(rate * (duration_s + lead))
            starts = burst_rng.uniform(-lead, duration_s, size=count)
            ends = starts + burst_rng.exponential(mean, size=count)
            in_group = group == g
            for start, end in zip(starts, ends):
                keep &= ~(in_group & (time_s >= start) & (time_s < end))
    return keep


def hop_table(model: dict, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """Channels in hop order (Hz) and the hop clock's offset at t = 0 (s).

    Without hopping the table is the single ``frequency_hz``.
    """
    if not model["hopping"]:
        return np.array([float(model["frequency_hz"])]), 0.0
    channels = np.asarray(model["channels_hz"] if model["channels_hz"] is not None else US_CHANNELS_HZ, float)
    return rng.permutation(channels), float(rng.uniform(0.0, model["hop_dwell_s"]))


def channel_index(time_s: np.ndarray, n_channels: int, dwell_s: float, clock_offset_s: float) -> np.ndarray:
    """Index into the hop table of the channel in use at each time."""
    if n_channels == 1:
        return np.zeros(len(time_s), dtype=np.int64)
    return (np.floor((time_s + clock_offset_s) / dwell_s).astype(np.int64)) % n_channels


def ornstein_uhlenbeck(
    time_s: np.ndarray, group: np.ndarray, sigma: float, correlation_s: float, rng: np.random.Generator
) -> np.ndarray:
    """Slow phase wander (rad) at each read: one stationary OU process per group.

    Sampled exactly at irregular times: ``x_k = x_{k-1} e^{-dt/tau} +
    sigma sqrt(1 - e^{-2 dt/tau}) n_k``, ``x_0 ~ N(0, sigma^2)``; ``time_s``
    must be sorted within each group.
    """
    wander = np.zeros(len(time_s))
    if sigma <= 0.0 or len(time_s) == 0:
        return wander
    innovations = rng.standard_normal(len(time_s))
    for g in np.unique(group):
        index = np.flatnonzero(group == g)
        decay = np.exp(-np.diff(time_s[index]) / correlation_s)
        scale = sigma * np.sqrt(1.0 - decay**2)
        value = sigma * innovations[index[0]]
        values = np.empty(len(index))
        values[0] = value
        for k in range(1, len(index)):
            value = value * decay[k - 1] + scale[k - 1] * innovations[index[k]]
            values[k] = value
        wander[index] = values
    return wander


def quantise_phase(phase_rad: np.ndarray, period_rad: float, step_units: int) -> np.ndarray:
    """Wrap to ``[0, P)`` and round to steps of ``step_units * 2 pi / 4096`` (0: wrap only)."""
    if step_units == 0:
        wrapped = np.mod(phase_rad, period_rad)
        # np.mod can return P itself for tiny negative inputs.
        return np.where(wrapped >= period_rad, 0.0, wrapped)
    step = step_units * PHASE_UNIT_RAD
    n_steps = int(round(period_rad / step))
    index = np.mod(np.round(phase_rad / step).astype(np.int64), n_steps)
    return index * step


def rssi_dbm(amplitude: np.ndarray, frequency_hz: np.ndarray, model: dict, rng: np.random.Generator) -> np.ndarray:
    """Peak RSSI (dBm) from the round-trip channel amplitude ``|h|`` (1/m^2)."""
    wavelength = SPEED_OF_LIGHT / frequency_hz
    link_budget = (
        model["tx_power_dbm"]
        + 2.0 * model["antenna_gain_dbi"]
        + 2.0 * model["tag_gain_dbi"]
        - model["backscatter_loss_db"]
    )
    # 20 log10(|h| (lambda / 4 pi)^2) = -40 log10(4 pi d / lambda) for the direct path.
    value = link_budget + 20.0 * np.log10(amplitude * (wavelength / (4.0 * np.pi)) ** 2)
    value = value + model["rssi_noise_db"] * rng.standard_normal(len(value))
    if model["rssi_step_db"] > 0.0:
        value = np.round(value / model["rssi_step_db"]) * model["rssi_step_db"]
    return value


def doppler_hz(
    antenna_position: np.ndarray,
    tag_position: np.ndarray,
    tag_velocity: np.ndarray,
    frequency_hz: np.ndarray,
    model: dict,
    rng: np.random.Generator,
) -> np.ndarray:
    """Reported Doppler shift (Hz): ``-2 v_r f / c`` + noise, positive when approaching."""
    offset = tag_position - antenna_position
    radial_velocity = np.sum(offset * tag_velocity, axis=1) / np.linalg.norm(offset, axis=1)  # m/s, + receding
    value = -2.0 * radial_velocity * frequency_hz / SPEED_OF_LIGHT
    value = value + model["doppler_noise_hz"] * rng.standard_normal(len(value))
    if model["doppler_step_hz"] > 0.0:
        value = np.round(value / model["doppler_step_hz"]) * model["doppler_step_hz"]
    return value


STREAMS = (
    "offsets",
    "schedule",
    "misses",
    "bursts",
    "hopping",
    "white_noise",
    "wander",
    "outliers",
    "rssi",
    "doppler",
)
"""Independent random streams, one per impairment, so that switching one
impairment on or off leaves the others' draws unchanged."""


def generate_reads(
    *,
    duration_s: float,
    antenna_ids: np.ndarray,
    antenna_positions: np.ndarray,
    antenna_offsets_rad: np.ndarray,
    epcs: list[str],
    trajectories: list[dict],
    tag_offsets_rad: np.ndarray,
    channels_hz: np.ndarray,
    channel_offsets_rad: np.ndarray,
    hop_clock_offset_s: float,
    phase_sign: int,
    period_rad: float,
    model: dict,
    rngs: dict[str, np.random.Generator],
) -> tuple[Reads, dict]:
    """Simulate the reads of one COTS reader session.

    Arguments: session length (s); antennas (ids, positions (k, 3) m, true
    phase offsets rad); tags (epc strings, trajectory dicts, true tag offsets
    rad); the hop table (Hz, in hop order) with the true offset of each
    channel (rad) and the hop clock offset (s); the reader's phase sign and
    period (rad); the resolved reader model (``READER_MODEL_DEFAULTS`` keys,
    noise filled in by :func:`resolve_noise`); one generator per name in
    :data:`STREAMS`. Returns the reads (sorted by time) and counts for the
    record (read attempts, misses, outliers, reads per tag).
    """
    n_tags, n_antennas = len(epcs), len(antenna_ids)
    order_ids = model["antenna_order"] if model["antenna_order"] is not None else list(antenna_ids)
    antenna_order = np.array([int(np.flatnonzero(antenna_ids == i)[0]) for i in order_ids])
    time, antenna, tag = read_schedule(duration_s, antenna_order, n_tags, model, rngs["schedule"])
    attempts = len(time)
    keep = dropout_mask(
        time, antenna, tag, n_antennas, n_tags, duration_s, model, rngs["misses"], rngs["bursts"]
    )
    # Scheduled outages (e.g. the reader paused, every tag shielded) come
    # after the random draws, so a window leaves every other read as it was.
    for start_s, end_s in model["dropout_windows"]:
        keep &= ~((time >= start_s) & (time < end_s))
    time, antenna, tag = time[keep], antenna[keep], tag[keep]
    n = len(time)

    position = np.empty((n, 3))
    velocity = np.empty((n, 3))
    for index, trajectory in enumerate(trajectories):
        rows = tag == index
        position[rows], velocity[rows] = positions_velocities(trajectory, time[rows])

    channel = channel_index(time, len(channels_hz), model["hop_dwell_s"], hop_clock_offset_s)
    frequency = channels_hz[channel]
    distance, excess, amplitude = round_trip_channel(
        antenna_positions[antenna], position, frequency, model["reflectors"]
    )
    geometric = 4.0 * np.pi * frequency * distance / SPEED_OF_LIGHT + excess
    phase = (
        phase_sign * geometric
        + antenna_offsets_rad[antenna]
        + channel_offsets_rad[channel]
        + tag_offsets_rad[tag]
    )
    phase = phase + model["white_noise_rad"] * rngs["white_noise"].standard_normal(n)
    group = antenna if model["wander_scope"] == "antenna" else tag * n_antennas + antenna
    phase = phase + ornstein_uhlenbeck(time, group, model["wander_rad"], model["wander_time_s"], rngs["wander"])
    outlier = rngs["outliers"].random(n) < model["outlier_probability"]
    replacement = rngs["outliers"].uniform(0.0, period_rad, size=n)
    phase = np.where(outlier, replacement, phase)
    phase = quantise_phase(phase, period_rad, int(model["phase_step_units"]))

    rssi = rssi_dbm(amplitude, frequency, model, rngs["rssi"]) if model["report_rssi"] else np.full(n, np.nan)
    if model["report_rssi"] and model["tag_gain_spread_db"] > 0.0:
        # Drawn after the noise, so that rooms without it keep their draws.
        gains = model["tag_gain_spread_db"] * rngs["rssi"].standard_normal((len(epcs), len(antenna_ids)))
        rssi = rssi + gains[tag, antenna]
    doppler = (
        doppler_hz(antenna_positions[antenna], position, velocity, frequency, model, rngs["doppler"])
        if model["report_doppler"]
        else np.full(n, np.nan)
    )
    epc_array = np.asarray(epcs, dtype=str)
    written_frequency = frequency.astype(float)
    if not model["log_frequency"]:
        # The reader logged only its channel index: the plan in index order is a guess.
        written_frequency = np.sort(np.asarray(channels_hz, dtype=float))[channel]
    reads = Reads(
        time_s=time,
        epc=epc_array[tag] if n else np.array([], dtype=epc_array.dtype),
        antenna=np.asarray(antenna_ids, dtype=np.int64)[antenna],
        frequency_hz=written_frequency,
        phase_rad=phase,
        rssi_dbm=rssi,
        doppler_hz=doppler,
        channel_index=(channel + 1).astype(np.int64) if model["report_channel_index"] else None,
    )
    counts = {
        "read_attempts": int(attempts),
        "reads": int(n),
        "dropped": int(attempts - n),
        "outliers": int(outlier.sum()),
        "reads_per_tag": {epc: int(np.sum(tag == i)) for i, epc in enumerate(epcs)},
    }
    return reads, counts
