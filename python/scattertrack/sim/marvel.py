"""Marvel scenarios at the feature level: IMU + backscatter pose features (docs/marvel.md section 9).

:func:`simulate_marvel` runs a ``pipeline = "marvel"`` scenario: a drone
flight (:mod:`scattertrack.sim.drone`), its IMU (:mod:`scattertrack.sim.imu`)
and the pose features the controller's LoRa-backscatter sensing would give
(``features.csv``, docs/formats.md section 7) with a physics-derived noise model,
without simulating the chirps (the IQ-level chain is
:mod:`scattertrack.sim.lora`). The controller's position is hidden from the
estimator: it is only in ``Simulation.details``.

Feature model (every constant in :data:`FEATURE_MODEL_DEFAULTS`, with its
unit and source; the derivations are in docs/marvel.md section 9):

1. **Link budget.** Backscatter radar equation, round trip:
   ``P_rx = P_tx + G_tx + G_rx + 2 G_tag - 2 FSPL(r) - L_bs - 2 W L_wall + s``
   (dBm), ``FSPL(r) = 20 log10(4 pi r f / c)``, ``W`` walls crossed twice,
   ``s`` a slowly varying shadowing (dB). Noise ``N = -174 dBm/Hz + 10
   log10(BW) + NF``. Per-sample SNR ``P_rx - N``; the dechirp adds ``10
   log10(2^SF)`` = 36.1 dB; the result is capped at ``snr_ceiling_db``
   (the receiver's phase noise and carrier leakage, not thermal noise,
   limit a strong tone).
2. **Decoding.** An epoch whose per-sample SNR is below ``decode_snr_db``
   (-20 dB: Semtech's SF12 demodulator limit) gives no row; such epochs are
   counted (``details["counts"]["rows_below_snr"]``).
3. **Range.** Thermal part: the phase-slope bound over the 8 received
   channels ``f_j + s_k / 2`` and 3 antennas, ``sigma = c / (4 pi)
   sigma_phi / sqrt(M sum (f_i - mean f)^2)`` with ``sigma_phi = 1 /
   sqrt(2 SNR)``. Multipath part: a correlated error (``range_multipath_m``
   plus ``range_multipath_per_wall_m`` per wall), which the 26 MHz aperture
   cannot resolve. Walls also delay the signal: ``(sqrt(eps_r) - 1) *
   thickness`` per wall, an unmodelled bias (not in the reported sigma).
4. **Angle.** Thermal part: the array's phase bound over 8 channels,
   ``sigma = lambda / (2 pi) sigma_phi / sqrt(N_ch sum_m (e . x_m)^2)``
   along each tangent axis ``e`` of the direction (``x_m`` the antenna
   offsets from the array centre); multipath part ``angle_multipath_rad``
   (+ per wall). The measured direction is ``u + e_az n_az + e_el n_el``
   normalised; ``angle_sigma_rad`` is the RMS of the two axes' sigmas (so
   ``sigma_az ~ angle_sigma / cos(el)``, ``sigma_el ~ angle_sigma``).
5. **Yaw.** An opposing pair's rotational shift has amplitude ``A = f D
   |omega_z| cos(el) / c`` Hz; the tone-frequency bound ``sqrt(6) / (2 pi
   T sqrt(SNR))`` per chirp, averaged over 3 antennas x 2 chirps and halved
   by the pair difference, plus a multipath floor ``doppler_floor_hz``
   (+ per wall), divided by ``A``; the azimuth error adds in (yaw is solved
   relative to the azimuth, eq. 8). No yaw when ``|omega_z| <
   min_yaw_rate`` or when its sigma exceeds ``max_yaw_sigma_rad``.

At IQ level, :func:`simulate_marvel_iq` gives the same flight, IMU and
truth with the controller's LoRa recording (:mod:`scattertrack.sim.lora`,
the scenario's optional ``[lora_model]``) instead of feature rows;
:func:`write_marvel_iq_simulation` writes it as SigMF beside ``imu.csv``.

Multipath errors and shadowing are first-order Gauss-Markov processes over
epochs with correlation ``exp(-|dp| / multipath_distance_m - dt /
multipath_time_s)``: frozen while the drone hovers (a stationary bias, as
the paper's stationary results show), fresh after it moves a few
decimetres. Thermal errors are white.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io.types import Features, Imu, Reader, Region, Scene, Truth
from scattertrack.physics import SPEED_OF_LIGHT, wrap_angle
from scattertrack.sim.drone import DEFAULT_TAGS, TAG_DIAMETER_M, flight
from scattertrack.sim.imu import simulate_imu
from scattertrack.sim.marvel_model import (  # noqa: F401 - exported by scattertrack.sim.marvel
    ARRAYS,
    CHANNEL_BASE_HZ,
    CHANNEL_SPACING_HZ,
    DEFAULT_REGION,
    FEATURE_MODEL_DEFAULTS,
    resolve_feature_model,
)
from scattertrack.sim.rotation import rotate
from scattertrack.sim.scenario_resolve import resolve_scenario
from scattertrack.sim.simulation import Simulation, write_simulation

# --------------------------------------------------------------------------
# geometry and the link budget


def array_offsets(array: str = "triangle", side_m: float = 0.16) -> np.ndarray:
    """Receive antenna offsets (3, 3) from the array centre, metres (docs/marvel.md section 4).

    ``side_m``: the triangle's side, or the linear array's spacing.
    """
    d = side_m
    if array == "triangle":
        return np.array(
            [
                [-d / 2.0, 0.0, -d / (2.0 * math.sqrt(3.0))],
                [d / 2.0, 0.0, -d / (2.0 * math.sqrt(3.0))],
                [0.0, 0.0, d / math.sqrt(3.0)],
            ]
        )
    if array == "linear":
        return np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]])
    raise ValueError(f"unknown array {array!r}; expected one of {', '.join(ARRAYS)}")


def channel_frequencies(model: dict, layout=DEFAULT_TAGS) -> np.ndarray:
    """The received channel frequencies ``f_j + s_k / 2`` (hertz), excitation-major (docs section 6)."""
    excitation = CHANNEL_BASE_HZ + CHANNEL_SPACING_HZ * np.asarray(model["channels"], dtype=float)
    return (excitation[:, None] + np.asarray(layout.shifts_hz)[None, :] / 2.0).reshape(-1)


def dechirped_snr_db(range_m, walls: int, model: dict, shadowing_db=0.0) -> np.ndarray:
    """Post-dechirp SNR (dB) of a tag at ``range_m`` metres through ``walls`` walls, before the ceiling.

    Round-trip radar equation (section 1 of the module docstring); the
    dechirp gain is ``10 log10(2^SF)``.
    """
    range_m = np.maximum(np.asarray(range_m, dtype=float), 1e-3)
    frequency = float(np.mean(channel_frequencies(model)))
    path_loss = 20.0 * np.log10(4.0 * math.pi * range_m * frequency / SPEED_OF_LIGHT)
    received = (
        model["tx_power_dbm"]
        + model["tx_gain_dbi"]
        + model["rx_gain_dbi"]
        + 2.0 * model["tag_gain_dbi"]
        - 2.0 * path_loss
        - model["backscatter_loss_db"]
        - 2.0 * walls * model["wall_loss_db"]
        + shadowing_db
    )
    noise = -174.0 + 10.0 * math.log10(model["bandwidth_hz"]) + model["noise_figure_db"]
    return received - noise + 10.0 * math.log10(2 ** model["spreading_factor"])


def decode_threshold_db(model: dict) -> float:
    """The post-dechirp SNR (dB) below which an epoch is lost: ``decode_snr_db + 10 log10(2^SF)``."""
    return model["decode_snr_db"] + 10.0 * math.log10(2 ** model["spreading_factor"])


def direction_angles(position, controller) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range (m), azimuth and elevation (rad) of ``position`` (n, 3) seen from ``controller`` (3,).

    docs/formats.md section 7: ``u = (p - rho) / |p - rho|``, azimuth
    ``atan2(u_y, u_x)``, elevation ``asin(u_z)``.
    """
    delta = np.asarray(position, dtype=float) - np.asarray(controller, dtype=float)
    distance = np.linalg.norm(delta, axis=1)
    u = delta / distance[:, None]
    return distance, np.arctan2(u[:, 1], u[:, 0]), np.arcsin(np.clip(u[:, 2], -1.0, 1.0))


def noise_sigmas(distance_m, elevation_rad, azimuth_rad, yaw_rate, walls: int, model: dict, array: str,
                 side_m: float, shadowing_db=0.0) -> dict:
    """Per-epoch noise levels (arrays) of the feature model, before any draw.

    Returns ``snr_db`` (post-dechirp, capped), and the thermal and multipath
    1-sigmas: ``range_thermal_m``, ``range_multipath_m``, ``az_axis_thermal``
    and ``el_axis_thermal`` (rad, along the tangent axes), ``angle_multipath``
    (rad), ``doppler_thermal_hz``, ``doppler_floor_hz`` and the pair
    amplitude ``doppler_amplitude_hz``.
    """
    snr_db = np.minimum(dechirped_snr_db(distance_m, walls, model, shadowing_db), model["snr_ceiling_db"])
    snr = 10.0 ** (snr_db / 10.0)
    phase_sigma = 1.0 / np.sqrt(2.0 * snr)  # rad, phase of one dechirped tone (high-SNR bound)
    offsets = array_offsets(array, side_m)
    offsets = offsets - offsets.mean(axis=0)
    n_antennas = len(offsets)
    frequencies = channel_frequencies(model)
    spread = float(np.sum((frequencies - frequencies.mean()) ** 2))
    range_thermal = SPEED_OF_LIGHT / (4.0 * math.pi) * phase_sigma / math.sqrt(n_antennas * spread)
    wavelength = SPEED_OF_LIGHT / float(frequencies.mean())
    az = np.asarray(azimuth_rad, dtype=float)
    el = np.asarray(elevation_rad, dtype=float)
    e_az = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], axis=-1)
    e_el = np.stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)], axis=-1)

    def axis_sigma(axis):
        # Fisher information of a tangent rotation from the phases of all antennas and channels;
        # an axis the array cannot see (endfire) is floored at a projection of 1 cm.
        aperture = np.maximum(np.sum((axis @ offsets.T) ** 2, axis=-1), 1e-4)
        sigma = wavelength / (2.0 * math.pi) * phase_sigma / np.sqrt(len(frequencies) * aperture)
        return np.minimum(sigma, math.pi / 2.0)

    walls_f = float(walls)
    chirp_s = 2 ** model["spreading_factor"] / model["bandwidth_hz"]
    tone_sigma = math.sqrt(6.0) / (2.0 * math.pi * chirp_s * np.sqrt(snr))  # Hz, one chirp at one antenna
    n_chirps = len(model["channels"])
    centre = float(frequencies.mean())
    return {
        "snr_db": snr_db,
        "range_thermal_m": range_thermal,
        "range_multipath_m": model["range_multipath_m"] + walls_f * model["range_multipath_per_wall_m"],
        "az_axis_thermal": axis_sigma(e_az),
        "el_axis_thermal": axis_sigma(e_el),
        "angle_multipath": model["angle_multipath_rad"] + walls_f * model["angle_multipath_per_wall_rad"],
        # The pair's half-difference halves the variance; 3 antennas x 2 chirps average it.
        "doppler_thermal_hz": tone_sigma / math.sqrt(2.0 * n_antennas * n_chirps),
        "doppler_floor_hz": model["doppler_floor_hz"] + walls_f * model["doppler_floor_per_wall_hz"],
        "doppler_amplitude_hz": centre * TAG_DIAMETER_M * np.abs(yaw_rate) * np.cos(el) / SPEED_OF_LIGHT,
    }


def _gauss_markov(rng, correlation: np.ndarray, sigma, width: int) -> np.ndarray:
    """(n, width) first-order Gauss-Markov sequences of unit variance times ``sigma``.

    ``x[k] = c[k] x[k-1] + sqrt(1 - c[k]^2) w[k]`` with ``c`` the
    ``correlation`` to the previous epoch, stationary from the first epoch.
    A loop over epochs (10 Hz, a few thousand), not samples.
    """
    n = len(correlation)
    white = rng.standard_normal((n, width))
    out = np.empty((n, width))
    if n == 0:
        return out
    out[0] = white[0]
    gain = np.sqrt(1.0 - correlation**2)
    for k in range(1, n):
        out[k] = correlation[k] * out[k - 1] + gain[k] * white[k]
    return out * np.asarray(sigma, dtype=float)


# --------------------------------------------------------------------------
# the simulator


def simulate_features(flight_params: dict, controller: dict, model: dict, duration_s: float, rng):
    """Feature rows (:class:`Features`) and counts for one flight, and the SNR of every epoch.

    ``controller``: resolved ``[controller]`` table (``position`` m,
    ``array``, ``walls``). Returns ``(features, counts,
    snr_db)`` where ``snr_db`` covers every epoch, decoded or not.
    """
    rate = model["rate_hz"]
    # Epoch k is stamped at its middle, (k + 1/2) / rate (the two chirps straddle it).
    times = (np.arange(int(math.ceil(duration_s * rate))) + 0.5) / rate
    times = times[times < duration_s]
    truth = flight(flight_params, times)
    rho = np.asarray(controller["position"], dtype=float)
    walls = int(controller["walls"])
    distance, azimuth, elevation = direction_angles(truth.position, rho)
    yaw_rate_world = _world_yaw_rate(truth)
    n = len(times)

    # Correlation of the slow (multipath, shadowing) errors between epochs.
    moved = np.concatenate([[0.0], np.linalg.norm(np.diff(truth.position, axis=0), axis=1)])
    elapsed = np.concatenate([[0.0], np.diff(times)])
    correlation = np.exp(-moved / model["multipath_distance_m"] - elapsed / model["multipath_time_s"])
    shadow_sigma = model["shadowing_db"] + walls * model["shadowing_per_wall_db"]
    # Draw order is fixed: shadowing, multipath (range, az, el, doppler), thermal (range, az, el, doppler).
    shadowing = _gauss_markov(rng, correlation, shadow_sigma, 1)[:, 0]
    slow = _gauss_markov(rng, correlation, 1.0, 4)
    white = rng.standard_normal((n, 4))

    sig = noise_sigmas(distance, elevation, azimuth, yaw_rate_world, walls, model, controller["array"],
                       model["array_side_m"], shadowing)
    decoded = sig["snr_db"] >= decode_threshold_db(model)

    # Range: truth + wall delay bias + multipath + thermal.
    wall_bias = walls * (math.sqrt(model["wall_permittivity"]) - 1.0) * model["wall_thickness_m"]
    range_m = distance + wall_bias + sig["range_multipath_m"] * slow[:, 0] + sig["range_thermal_m"] * white[:, 0]
    range_sigma = np.hypot(sig["range_thermal_m"], sig["range_multipath_m"])

    # Direction: tangent-plane errors along e_az and e_el, renormalised.
    az_axis_sigma = np.hypot(sig["az_axis_thermal"], sig["angle_multipath"])
    el_axis_sigma = np.hypot(sig["el_axis_thermal"], sig["angle_multipath"])
    error_az_axis = sig["angle_multipath"] * slow[:, 1] + sig["az_axis_thermal"] * white[:, 1]
    error_el_axis = sig["angle_multipath"] * slow[:, 2] + sig["el_axis_thermal"] * white[:, 2]
    u = np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)], 1)
    e_az = np.stack([-np.sin(azimuth), np.cos(azimuth), np.zeros(n)], axis=1)
    e_el = np.stack([-np.sin(elevation) * np.cos(azimuth), -np.sin(elevation) * np.sin(azimuth), np.cos(elevation)], 1)
    measured = u + error_az_axis[:, None] * e_az + error_el_axis[:, None] * e_el
    measured /= np.linalg.norm(measured, axis=1, keepdims=True)
    azimuth_m = np.arctan2(measured[:, 1], measured[:, 0])
    elevation_m = np.arcsin(np.clip(measured[:, 2], -1.0, 1.0))
    angle_sigma = np.sqrt((az_axis_sigma**2 + el_axis_sigma**2) / 2.0)

    # Yaw: relative to the measured azimuth (eq. 8), so the azimuth error carries over.
    amplitude = np.maximum(sig["doppler_amplitude_hz"], 1e-12)
    yaw_true = truth.yaw
    azimuth_error = wrap_angle(azimuth_m - azimuth)
    doppler_error = sig["doppler_floor_hz"] * slow[:, 3] + sig["doppler_thermal_hz"] * white[:, 3]
    yaw_m = wrap_angle(yaw_true + azimuth_error + doppler_error / amplitude)
    cos_el = np.maximum(np.cos(elevation), 1e-3)
    yaw_sigma = np.sqrt(
        (np.hypot(sig["doppler_thermal_hz"], sig["doppler_floor_hz"]) / amplitude) ** 2
        + (az_axis_sigma / cos_el) ** 2
    )
    has_yaw = (np.abs(yaw_rate_world) >= model["min_yaw_rate"]) & (yaw_sigma <= model["max_yaw_sigma_rad"])
    yaw_m = np.where(has_yaw, yaw_m, np.nan)
    yaw_sigma_out = np.where(has_yaw, yaw_sigma, np.nan)

    keep = decoded
    features = Features(
        time_s=times[keep],
        range_m=range_m[keep],
        azimuth_rad=azimuth_m[keep],
        elevation_rad=elevation_m[keep],
        yaw_rad=yaw_m[keep],
        range_sigma_m=range_sigma[keep],
        angle_sigma_rad=angle_sigma[keep],
        yaw_sigma_rad=yaw_sigma_out[keep],
    )
    counts = {
        "epochs": int(n),
        "rows": int(np.count_nonzero(keep)),
        "rows_below_snr": int(np.count_nonzero(~decoded)),
        "rows_without_yaw": int(np.count_nonzero(keep & ~has_yaw)),
    }
    return features, counts, sig["snr_db"]


def _world_yaw_rate(truth) -> np.ndarray:
    """Rate of turn about world +z (rad/s): the z row of ``R omega_body``."""
    return rotate(truth.orientation, truth.angular_velocity)[:, 2]


def simulate_marvel(scenario_data: dict, seed: int | None = None):
    """Run a ``pipeline = "marvel"`` scenario: truth (100 Hz), IMU and features.

    ``scenario_data`` is a scenario dict (validated and completed here with
    :func:`scattertrack.sim.scenario_resolve.resolve_scenario`); ``seed`` overrides
    its ``seed``. Returns a :class:`scattertrack.sim.simulation.Simulation`
    with ``imu``, ``features`` and ``truth`` (``epc = "drone"``, with
    orientation) set and ``reads = None``; ``details`` holds the hidden
    controller position, walls, seed and counts.
    """
    if seed is not None:
        scenario_data = {**scenario_data, "seed": seed}
    data = resolve_scenario(scenario_data)
    seed = data["seed"]
    rngs = dict(zip(("imu", "features"), np.random.default_rng(seed).spawn(2)))
    duration = data["duration_s"]
    flight_params = data["flight"]
    controller = data["controller"]
    imu_model = data["imu_model"]
    feature_model = data["feature_model"]

    truth_times = np.arange(int(math.ceil(duration * data["truth_rate_hz"] - 1e-9))) / data["truth_rate_hz"]
    state = flight(flight_params, truth_times)
    truth = Truth(
        time_s=truth_times,
        epc=np.full(len(truth_times), "drone"),
        position=state.position,
        velocity=state.velocity,
        orientation=state.orientation,
    )
    imu_times = np.arange(int(math.ceil(duration * imu_model["rate_hz"] - 1e-9))) / imu_model["rate_hz"]
    imu: Imu = simulate_imu(flight(flight_params, imu_times), imu_model, rngs["imu"])
    features, counts, snr_db = simulate_features(flight_params, controller, feature_model, duration, rngs["features"])

    scene_spec = data["scene"]
    region = scene_spec.get("region", {"min": DEFAULT_REGION[0], "max": DEFAULT_REGION[1]})
    scene = Scene(
        name=scene_spec["name"],
        dimensions=3,
        reader=Reader(kind="lora-backscatter"),
        antennas=[],
        region=Region(np.array(region["min"], dtype=float), np.array(region["max"], dtype=float)),
    )
    counts["imu_samples"] = len(imu)
    counts["imu_gaps"] = imu.gaps
    details = {
        "controller_position_m": [float(v) for v in controller["position"]],
        "controller_array": controller["array"],
        "walls": int(controller["walls"]),
        "seed": int(seed),
        "counts": counts,
        "snr_db": {
            "min": float(np.min(snr_db)) if len(snr_db) else None,
            "median": float(np.median(snr_db)) if len(snr_db) else None,
            "max": float(np.max(snr_db)) if len(snr_db) else None,
            "decode_threshold": decode_threshold_db(feature_model),
        },
        "tags": {
            "names": list(DEFAULT_TAGS.names),
            "positions_body_m": DEFAULT_TAGS.positions_body.tolist(),
            "shifts_hz": DEFAULT_TAGS.shifts_hz.tolist(),
        },
    }
    return Simulation(
        scene=scene,
        reads=None,
        truth=truth,
        scenario=data,
        seed=seed,
        details=details,
        imu=imu,
        features=features,
    )


# --------------------------------------------------------------------------
# IQ level: the controller's LoRa recording of the same flight


LORA_SEED_STREAM = 2
"""Spawn key of the LoRa recording's seed under the scenario seed: ``simulate_marvel``
spawns streams 0 (IMU) and 1 (features), so the recording's draws are independent of both."""


def lora_seed(seed: int) -> int:
    """The seed :func:`scattertrack.sim.lora.simulate_lora_iq` gets for scenario seed ``seed``.

    A child of the scenario's seed sequence that the feature-level run does
    not use (:data:`LORA_SEED_STREAM`), so the IQ noise, clock and receiver
    draws neither repeat nor shift the IMU's.
    """
    state = np.random.SeedSequence(int(seed), spawn_key=(LORA_SEED_STREAM,)).generate_state(1, np.uint32)
    return int(state[0])


def simulate_marvel_iq(scenario_data: dict, seed: int | None = None):
    """Run a ``pipeline = "marvel"`` scenario at IQ level: ``(Simulation, LoraRecording)``.

    The flight, the IMU and the truth are those of :func:`simulate_marvel`
    with the same scenario and seed (identical arrays); instead of
    feature-level rows (``Simulation.features`` is None) the controller's
    channelised LoRa streams come from :func:`scattertrack.sim.lora.simulate_lora_iq`
    over the scenario's ``duration_s``: the drone's pose at every sample
    time from :func:`scattertrack.sim.drone.flight`, the scenario's
    ``[controller]`` (position m, array, walls) and its optional
    ``[lora_model]`` table (keys of :data:`scattertrack.sim.lora.LORA_MODEL_DEFAULTS`).
    The recording's seed is :func:`lora_seed` of the scenario seed.

    ``Simulation.details`` keeps the hidden controller position, walls and
    seed, and replaces the feature-level counts with the recording's:
    ``counts`` (``epochs``, ``imu_samples``, ``imu_gaps``), ``snr_db``
    (per-sample SNR of the direct path over epochs, tags and antennas, dB;
    the dechirp adds ``10 log10(2^SF)``) and ``lora`` (its seed, the tags'
    clock error ``eps``, their CFOs in Hz, the switching phase in rad). The
    recording's own ``details`` hold the per-epoch truth (see
    :func:`scattertrack.sim.lora.simulate_lora_iq`).
    """
    from scattertrack.sim.lora import simulate_lora_iq

    simulation = simulate_marvel(scenario_data, seed)
    data = simulation.scenario
    flight_params = data["flight"]

    def pose_at(times):
        state = flight(flight_params, times)
        return state.position, state.orientation

    controller = data["controller"]
    iq_seed = lora_seed(simulation.seed)
    recording = simulate_lora_iq(
        pose_at,
        {"position": controller["position"], "array": controller["array"], "walls": int(controller["walls"])},
        data.get("lora_model"),
        float(data["duration_s"]),
        iq_seed,
    )
    lora_details = recording.details
    snr = np.asarray(lora_details["snr_db"], dtype=float)
    details = dict(simulation.details)
    details["counts"] = {
        "epochs": recording.n_epochs,
        "imu_samples": len(simulation.imu),
        "imu_gaps": simulation.imu.gaps,
    }
    details["snr_db"] = {
        "min": float(np.min(snr)),
        "median": float(np.median(snr)),
        "max": float(np.max(snr)),
        "dechirp_gain": 10.0 * math.log10(int(recording.metadata["samples_per_chirp"])),
    }
    details["lora"] = {
        "seed": iq_seed,
        "clock_error": float(lora_details["clock_error"]),
        "cfo_hz": [float(v) for v in lora_details["cfo_hz"]],
        "tag_phase_rad": float(lora_details["tag_phase_rad"]),
        "model": recording.metadata["model"],
    }
    simulation.details = details
    simulation.features = None
    return simulation, recording


def write_marvel_iq_simulation(simulation, recording, out_dir, *, datatype: str = "ci16_le"):
    """Write ``recording.sigmf-meta``/``.sigmf-data`` (``datatype``, default ci16),
    ``scene.toml``, ``imu.csv``, ``truth.csv`` and ``simulation.json`` into ``out_dir``; returns the folder."""
    from pathlib import Path

    from scattertrack.io.sigmf_lora import write_lora_sigmf

    out = write_simulation(simulation, out_dir)
    write_lora_sigmf(Path(out) / "recording", recording, datatype=datatype)
    return out
