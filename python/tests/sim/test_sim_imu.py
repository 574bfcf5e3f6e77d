"""The IMU model (docs/marvel.md section 3): sign conventions via strapdown, noise statistics, gaps."""

import numpy as np
import pytest

from scattertrack.sim.drone import GRAVITY, FlightTruth, ParameterError, flight
from scattertrack.sim.imu import IMU_MODEL_DEFAULTS, NOISE_KEYS, ideal_imu, resolve_imu_model, simulate_imu
from scattertrack.sim.rotation import quat_exp, quat_multiply, quat_normalize, quat_to_matrix

PERFECT = {key: 0.0 for key in NOISE_KEYS}
"""An IMU model without noise or biases."""


def at_rest(seconds: float, rate_hz: float = 100.0) -> FlightTruth:
    """A drone standing still on the ground, level, for ``seconds``."""
    n = int(round(seconds * rate_hz))
    zeros = np.zeros((n, 3))
    return FlightTruth(
        time_s=np.arange(n) / rate_hz,
        position=zeros,
        velocity=zeros,
        acceleration=zeros,
        orientation=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        angular_velocity=zeros,
    )


def test_at_rest_the_accelerometer_reads_plus_g_on_body_z():
    imu = simulate_imu(at_rest(2.0), PERFECT, np.random.default_rng(0))
    np.testing.assert_allclose(imu.accel, np.tile([0.0, 0.0, 9.80665], (200, 1)), atol=1e-12)
    np.testing.assert_allclose(imu.gyro, 0.0, atol=1e-12)
    np.testing.assert_allclose(imu.baro_z, 0.0, atol=1e-12)
    noisy = simulate_imu(at_rest(2.0), None, np.random.default_rng(0))
    assert np.abs(noisy.accel.mean(axis=0) - [0, 0, 9.81]).max() < 0.1


def strapdown(truth: FlightTruth, accel: np.ndarray, gyro: np.ndarray, start: int):
    """Integrate body-frame specific force and rate from the true state at sample ``start``.

    Orientation: ``q <- q * Exp(mean rate * dt)``; velocity and position by
    the trapezoidal rule on the world acceleration ``R f + g``.
    """
    time = truth.time_s
    n = len(time)
    q = truth.orientation[start].copy()
    v = truth.velocity[start].copy()
    p = truth.position[start].copy()
    positions, orientations = [p.copy()], [q.copy()]
    accel_world = quat_to_matrix(q) @ accel[start] + GRAVITY
    for k in range(start, n - 1):
        dt = time[k + 1] - time[k]
        q_next = quat_normalize(quat_multiply(q, quat_exp((gyro[k] + gyro[k + 1]) / 2 * dt)))
        next_world = quat_to_matrix(q_next) @ accel[k + 1] + GRAVITY
        v_next = v + (accel_world + next_world) / 2 * dt
        # Position from the velocity's trapezoid plus the curvature term (exact for a linear acceleration).
        p = p + (v + v_next) / 2 * dt - (next_world - accel_world) * dt**2 / 12
        q, v, accel_world = q_next, v_next, next_world
        positions.append(p.copy())
        orientations.append(q.copy())
    return np.array(positions), np.array(orientations)


@pytest.mark.parametrize(
    "params",
    [
        {"kind": "figure-eight", "size": [8.0, 4.0], "speed": 2.5, "rotation_rad": 0.4},
        {"kind": "circle", "radius": 5.0, "speed": 2.5, "yaw": "rate", "yaw_rate": 0.7},
        {"kind": "rail", "length": 6.0, "speed": 3.0, "yaw": "velocity"},
    ],
    ids=["figure-eight", "circle-spinning", "rail"],
)
def test_noise_free_imu_integrates_back_to_the_trajectory(params):
    # 1 kHz over 6 s: take-off/turn-in and the pattern, so every sign matters.
    rate = 1000.0
    t = np.arange(3.0 * rate, 9.0 * rate) / rate
    truth = flight(params, t)
    imu = simulate_imu(truth, PERFECT | {"rate_hz": rate}, np.random.default_rng(0))
    positions, orientations = strapdown(truth, imu.accel, imu.gyro, 0)
    assert np.abs(positions - truth.position).max() < 2e-5  # metres after 6 s
    rotation_error = np.einsum("nji,njk->nik", quat_to_matrix(orientations), quat_to_matrix(truth.orientation))
    angle = np.arccos(np.clip((np.trace(rotation_error, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert angle.max() < 1e-4  # rad
    # At the IMU's own 100 Hz the same integration stays within millimetres.
    coarse = flight(params, t[::10])
    imu100 = simulate_imu(coarse, PERFECT, np.random.default_rng(0))
    positions100, _ = strapdown(coarse, imu100.accel, imu100.gyro, 0)
    assert np.abs(positions100 - coarse.position).max() < 2e-3


def test_a_wrong_sign_would_be_caught():
    params = {"kind": "figure-eight", "size": [8.0, 4.0], "speed": 2.5}
    t = np.arange(3000, 9000) / 1000.0
    truth = flight(params, t)
    force, rate = ideal_imu(truth)
    wrong, _ = strapdown(truth, force, -rate, 0)
    assert np.abs(wrong - truth.position).max() > 0.5


def test_noise_statistics_match_the_densities():
    model = dict(IMU_MODEL_DEFAULTS)
    rate = model["rate_hz"]
    truth = at_rest(600.0)
    white = simulate_imu(truth, PERFECT | {"accel_noise_density": 1e-3, "gyro_noise_density": 8.7e-5,
                                           "baro_noise_m": 0.1}, np.random.default_rng(1))
    np.testing.assert_allclose(white.accel.std(axis=0), 1e-3 * np.sqrt(rate), rtol=0.03)
    np.testing.assert_allclose(white.gyro.std(axis=0), 8.7e-5 * np.sqrt(rate), rtol=0.03)
    assert white.baro_z.std() == pytest.approx(0.1, rel=0.03)
    # Random walks: increments have sigma = walk * sqrt(dt).
    walks = simulate_imu(truth, PERFECT | {"accel_bias_walk": 1e-4, "gyro_bias_walk": 2e-5, "baro_walk": 0.02},
                         np.random.default_rng(2))
    dt = 1.0 / rate
    np.testing.assert_allclose(np.diff(walks.accel, axis=0).std(axis=0), 1e-4 * np.sqrt(dt), rtol=0.03)
    np.testing.assert_allclose(np.diff(walks.gyro, axis=0).std(axis=0), 2e-5 * np.sqrt(dt), rtol=0.03)
    assert np.diff(walks.baro_z).std() == pytest.approx(0.02 * np.sqrt(dt), rel=0.03)
    # Initial biases: one draw per run, 1-sigma 0.02 m/s^2 and 0.002 rad/s.
    short = at_rest(0.02)
    biased = PERFECT | {"accel_bias_initial": 0.02, "gyro_bias_initial": 0.002}
    runs = [simulate_imu(short, biased, np.random.default_rng(seed)) for seed in range(400)]
    accel_bias = np.array([run.accel[0] for run in runs]) - [0.0, 0.0, 9.80665]
    gyro_bias = np.array([run.gyro[0] for run in runs])
    assert accel_bias.std() == pytest.approx(0.02, rel=0.08)
    assert gyro_bias.std() == pytest.approx(0.002, rel=0.08)


def test_seeded_and_dropped_spans_leave_gaps():
    truth = flight({"kind": "circle", "radius": 5.0, "speed": 2.0}, np.arange(2000) / 100.0)
    a = simulate_imu(truth, None, np.random.default_rng(5))
    b = simulate_imu(truth, None, np.random.default_rng(5))
    np.testing.assert_array_equal(a.accel, b.accel)
    dropped = simulate_imu(truth, {"dropped_spans": [[5.0, 5.5], [12.0, 12.02]]}, np.random.default_rng(5))
    assert len(dropped) == len(a) - 50 - 2
    assert dropped.gaps == 1  # 0.5 s is a gap; 0.02 s (3 periods) is not longer than 3 periods
    keep = ~(((a.time_s >= 5.0) & (a.time_s < 5.5)) | ((a.time_s >= 12.0) & (a.time_s < 12.02)))
    np.testing.assert_array_equal(dropped.accel, a.accel[keep])
    np.testing.assert_array_equal(dropped.time_s, a.time_s[keep])
    no_baro = simulate_imu(truth, {"baro": False}, np.random.default_rng(5))
    assert np.isnan(no_baro.baro_z).all()


def test_bad_models_and_sampling_are_refused():
    with pytest.raises(ParameterError) as error:
        resolve_imu_model({"gyro_noise": 1.0})
    assert error.value.key == "gyro_noise"
    with pytest.raises(ParameterError) as error:
        resolve_imu_model({"accel_noise_density": -1.0})
    assert error.value.key == "accel_noise_density"
    with pytest.raises(ParameterError) as error:
        resolve_imu_model({"dropped_spans": [[3.0, 2.0]]})
    assert error.value.key == "dropped_spans[0]"
    with pytest.raises(ValueError, match="sampled every"):
        simulate_imu(at_rest(1.0, rate_hz=200.0), None, np.random.default_rng(0))
