"""Inertial measurement unit and barometer (docs/marvel.md section 3).

:func:`simulate_imu` turns a :class:`~scattertrack.sim.drone.FlightTruth`
sampled at the IMU's sample times into what the IMU reports
(:class:`scattertrack.io.types.Imu`, docs/formats.md section 6):

- accelerometer: the specific force in the body frame,
  ``f_B = R^T (a_W - g_W) + b_a + n_a`` (m/s^2); at rest ``(0, 0, +9.81)``;
- gyroscope: ``omega_B + b_g + n_g`` (rad/s);
- barometer: ``z + b_z + n_z`` (metres; height above the take-off point).

``n`` is discrete white noise with ``sigma = density * sqrt(rate)`` (a
continuous white noise of that spectral density, sampled at ``rate``);
``b`` are random walks ``b[k+1] = b[k] + walk * sqrt(dt) * N(0, 1)`` from an
initial value drawn with ``*_bias_initial`` (the barometer's walk starts at
0: it is zeroed at take-off). Every draw comes from the ``rng`` passed in.

Defaults (:data:`IMU_MODEL_DEFAULTS`) are a LORD MicroStrain 3DM-GX4-45
class IMU, the paper's (sec. V-A).
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import Imu
from scattertrack.sim.drone import GRAVITY, FlightTruth, ParameterError, with_defaults
from scattertrack.sim.rotation import quat_conjugate, rotate

IMU_MODEL_DEFAULTS = {
    "rate_hz": 100.0,  # Hz, sample rate of the IMU and the barometer
    "accel_noise_density": 1.0e-3,  # m/s^2/sqrt(Hz) (100 ug/sqrt(Hz))
    "gyro_noise_density": 8.7e-5,  # rad/s/sqrt(Hz) (0.005 deg/s/sqrt(Hz))
    "accel_bias_walk": 1.0e-4,  # m/s^3/sqrt(Hz): accelerometer bias random walk
    "gyro_bias_walk": 2.0e-5,  # rad/s^2/sqrt(Hz): gyroscope bias random walk
    "accel_bias_initial": 0.02,  # m/s^2, 1-sigma of each axis's bias at t = 0
    "gyro_bias_initial": 0.002,  # rad/s, 1-sigma of each axis's bias at t = 0
    "baro": True,  # write baro_z
    "baro_noise_m": 0.1,  # m, white noise of each barometer sample
    "baro_walk": 0.02,  # m/sqrt(s): barometer drift (weather, temperature) random walk
    "dropped_spans": [],  # [[start_s, end_s], ...]: samples in these spans are lost (gaps)
}
"""The IMU model; every key documented with its unit. A scenario's ``[imu_model]`` overrides keys."""

NOISE_KEYS = (
    "accel_noise_density",
    "gyro_noise_density",
    "accel_bias_walk",
    "gyro_bias_walk",
    "accel_bias_initial",
    "gyro_bias_initial",
    "baro_noise_m",
    "baro_walk",
)
"""Non-negative numbers of the model; all 0 gives a perfect IMU."""


def resolve_imu_model(given: dict | None = None) -> dict:
    """The model with defaults filled in; raises :class:`ParameterError` (naming the key) for a bad one."""
    model = with_defaults(given, IMU_MODEL_DEFAULTS)
    rate = model["rate_hz"]
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not rate > 0 or not np.isfinite(rate):
        raise ParameterError("rate_hz", f"must be a positive number, got {rate!r}")
    model["rate_hz"] = float(rate)
    for key in NOISE_KEYS:
        value = model[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0 or not np.isfinite(value):
            raise ParameterError(key, f"must be a non-negative number, got {value!r}")
        model[key] = float(value)
    if not isinstance(model["baro"], bool):
        raise ParameterError("baro", f"must be true or false, got {model['baro']!r}")
    spans = model["dropped_spans"]
    if not isinstance(spans, list):
        raise ParameterError("dropped_spans", f"must be a list of [start_s, end_s], got {spans!r}")
    cleaned = []
    for index, span in enumerate(spans):
        if (
            not isinstance(span, (list, tuple))
            or len(span) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in span)
            or not span[0] < span[1]
        ):
            raise ParameterError(f"dropped_spans[{index}]", f"must be [start_s, end_s] with start < end, got {span!r}")
        cleaned.append([float(span[0]), float(span[1])])
    model["dropped_spans"] = cleaned
    return model


def ideal_imu(truth: FlightTruth) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free specific force (n, 3) m/s^2 and angular rate (n, 3) rad/s in the body frame."""
    specific_force = rotate(quat_conjugate(truth.orientation), truth.acceleration - GRAVITY)
    return specific_force, np.asarray(truth.angular_velocity, dtype=float).copy()


def _random_walk(rng, n: int, width: int, initial_sigma: float, walk: float, dt: float) -> np.ndarray:
    """(n, width) random walks: N(0, initial_sigma^2) at the first sample, steps N(0, walk^2 dt)."""
    start = initial_sigma * rng.standard_normal((1, width))
    steps = walk * np.sqrt(dt) * rng.standard_normal((n - 1, width))
    return start + np.concatenate([np.zeros((1, width)), np.cumsum(steps, axis=0)])


def simulate_imu(truth: FlightTruth, model: dict | None, rng) -> Imu:
    """IMU samples at ``truth.time_s`` (the caller samples the flight at the IMU rate).

    ``model`` overrides :data:`IMU_MODEL_DEFAULTS` (None: the defaults);
    ``rng`` is a ``numpy.random.Generator``. The truth's sample spacing must
    be ``1 / rate_hz`` (the noise levels assume it; ValueError otherwise).
    Samples inside ``dropped_spans`` are removed afterwards, so the other
    samples do not depend on the spans. Draw order (fixed, for
    reproducibility): accelerometer bias, gyroscope bias, accelerometer
    noise, gyroscope noise, barometer walk, barometer noise.
    """
    model = resolve_imu_model(model)
    time = np.asarray(truth.time_s, dtype=float)
    n = len(time)
    if n < 2:
        raise ValueError("an IMU needs at least 2 truth samples")
    dt = 1.0 / model["rate_hz"]
    spacing = float(np.median(np.diff(time)))
    if abs(spacing - dt) > 1e-3 * dt:
        raise ValueError(f"truth is sampled every {spacing:g} s but the IMU runs at {model['rate_hz']:g} Hz")
    specific_force, rate = ideal_imu(truth)
    accel_bias = _random_walk(rng, n, 3, model["accel_bias_initial"], model["accel_bias_walk"], dt)
    gyro_bias = _random_walk(rng, n, 3, model["gyro_bias_initial"], model["gyro_bias_walk"], dt)
    sqrt_rate = np.sqrt(model["rate_hz"])
    accel = specific_force + accel_bias + model["accel_noise_density"] * sqrt_rate * rng.standard_normal((n, 3))
    gyro = rate + gyro_bias + model["gyro_noise_density"] * sqrt_rate * rng.standard_normal((n, 3))
    baro_drift = _random_walk(rng, n, 1, 0.0, model["baro_walk"], dt)[:, 0]
    baro = np.asarray(truth.position)[:, 2] + baro_drift + model["baro_noise_m"] * rng.standard_normal(n)
    if not model["baro"]:
        baro = np.full(n, np.nan)
    keep = np.ones(n, dtype=bool)
    for start, end in model["dropped_spans"]:
        keep &= ~((time >= start) & (time < end))
    gaps = _count_gaps(time[keep], dt)
    return Imu(time_s=time[keep], accel=accel[keep], gyro=gyro[keep], baro_z=baro[keep], gaps=gaps)


def _count_gaps(time: np.ndarray, period_s: float) -> int:
    """Gaps longer than 3 nominal periods (the rule :func:`scattertrack.io.imu.count_gaps` applies)."""
    if len(time) < 2:
        return 0
    return int(np.count_nonzero(np.diff(time) > 3.0 * period_s * (1.0 + 1e-6)))
