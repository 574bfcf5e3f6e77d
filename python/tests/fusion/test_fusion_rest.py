"""The rest test (fusion/rest.py) and the ground phase it gates in the estimator."""

import math

import numpy as np
import pytest

from scattertrack.fusion import MarvelEstimator, MarvelParams
from scattertrack.fusion.rest import RestThresholds, baro_contradicts_ground, baro_slope, rest_test
from scattertrack.fusion.run import run_marvel
from scattertrack.io.types import Imu

G = 9.80665
THRESHOLDS = RestThresholds(G, 0.1, 0.05, 0.02, 0.3)


def _window(rng, n=50, force=(0.0, 0.0, G), accel_noise=0.01, gyro=(0.0, 0.0, 0.0), gyro_noise=1e-3):
    accel = np.asarray(force) + rng.normal(0.0, accel_noise, (n, 3))
    rates = np.asarray(gyro) + rng.normal(0.0, gyro_noise, (n, 3))
    return accel, rates


def test_a_body_at_rest_passes_and_gives_gravity():
    rng = np.random.default_rng(0)
    accel, gyro = _window(rng, force=(0.02, -0.01, G + 0.02))  # a bias of a few hundredths
    verdict = rest_test(accel, gyro, THRESHOLDS, np.arange(50) * 0.01, rng.normal(0.0, 0.1, 50))
    assert verdict.at_rest and verdict.reason == ""
    assert abs(np.linalg.norm(verdict.mean_force) - G) < 0.05


@pytest.mark.parametrize(
    "kind, reason",
    [("lift_off", "force"), ("vibration", "accel_energy"), ("turning", "gyro_energy"), ("climbing", "baro_slope")],
)
def test_each_kind_of_motion_fails_its_check(kind, reason):
    rng = np.random.default_rng(1)
    force, accel_noise, gyro, baro_rate = (0.0, 0.0, G), 0.01, (0.0, 0.0, 0.0), 0.0
    if kind == "lift_off":
        force = (0.0, 0.0, G + 0.5)  # a climb accelerating at 0.5 m/s^2
    elif kind == "vibration":
        accel_noise = 0.2
    elif kind == "turning":
        gyro = (0.0, 0.0, 0.2)
    else:
        baro_rate = 1.0  # m/s
    accel, rates = _window(rng, force=force, accel_noise=accel_noise, gyro=gyro)
    t = np.arange(50) * 0.01
    verdict = rest_test(accel, rates, THRESHOLDS, t, baro_rate * t + rng.normal(0.0, 0.01, 50))
    assert not verdict.at_rest and verdict.reason == reason


def test_too_few_samples_is_not_rest():
    verdict = rest_test(np.zeros((2, 3)), np.zeros((2, 3)), THRESHOLDS)
    assert not verdict.at_rest and verdict.reason == "too_few_samples"


def test_baro_slope_and_contradiction():
    t = np.linspace(0.0, 1.0, 11)
    assert baro_slope(t, 3.0 + 0.5 * t) == pytest.approx(0.5)
    assert math.isnan(baro_slope(t[:2], t[:2]))
    assert baro_contradicts_ground(10.5, 10.0, 0.3) and baro_contradicts_ground(9.5, 10.0, 0.3)
    assert not baro_contradicts_ground(10.2, 10.0, 0.3)
    assert not baro_contradicts_ground(10.5, float("nan"), 0.3)


def test_rest_start_gets_ground_factors_after_the_verdict(circle_flight):
    data = circle_flight  # 0.5 s at rest, then the climb
    estimator = MarvelEstimator(MarvelParams(tilt_window_s=0.3))
    imu, f = data.imu, data.features
    j = 0
    for i in range(len(f)):
        while j < len(imu) and imu.time_s[j] <= f.time_s[i]:
            estimator.add_imu(imu.time_s[j], imu.accel[j], imu.gyro[j], imu.baro_z[j])
            j += 1
        estimator.add_features(f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i], f.yaw_rad[i])
        if f.time_s[i] < 0.3:
            assert estimator.rest_state == "pending" and estimator.on_ground
        if f.time_s[i] > 3.0:
            break
    assert estimator.rest_state == "rest" and estimator.rest_test.at_rest
    assert estimator.ground_end_reason == "imu"
    # The IMU ended the ground phase: its earlier samples were at rest, nothing is dropped.
    assert estimator.ground_factors_dropped == 0


def test_a_lift_off_start_is_not_taken_for_rest(lift_off_flight):
    data = lift_off_flight
    track = run_marvel(data.imu, data.features, correlation_distance_m=0.0, range_bias_sigma_m=0.0)
    rest = track.stats["drone"]["rest"]
    assert rest["state"] == "moving" and rest["failed_check"] == "force"
    rows = np.searchsorted(data.truth_time, track.time_s)
    height_error = np.abs(track.position[:, 2] - data.truth_position[rows, 2])
    # The height follows the climb (it stayed near 0 when rest was assumed).
    assert data.truth_position[rows, 2].max() > 1.5
    assert np.mean(height_error) < 0.25


def test_a_ground_constraint_the_barometer_contradicts_is_dropped(circle_flight):
    data = circle_flight
    imu = data.imu
    # The IMU keeps the rest (a climb too gentle for it: here none at all) while the
    # barometer rises 1 m at 0.4 s: the ground must end, by the barometer.
    still = imu.time_s < 0.5
    accel = np.where(still[:, None], imu.accel, imu.accel[0])
    gyro = np.where(still[:, None], imu.gyro, imu.gyro[0])
    baro = imu.baro_z + np.where(imu.time_s >= 0.4, 1.0, 0.0)
    frozen = Imu(time_s=imu.time_s, accel=accel, gyro=gyro, baro_z=baro)
    estimator = MarvelEstimator(MarvelParams(tilt_window_s=0.3))
    f = data.features
    j = 0
    for i in range(30):
        while j < len(frozen) and frozen.time_s[j] <= f.time_s[i]:
            estimator.add_imu(frozen.time_s[j], frozen.accel[j], frozen.gyro[j], frozen.baro_z[j])
            j += 1
        estimator.add_features(f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i])
    assert estimator.rest_state == "rest"
    assert estimator.ground_end_reason == "barometer"
    assert estimator.ground_factors_dropped > 0  # the ground factors of the rise's window
    assert not estimator.on_ground
