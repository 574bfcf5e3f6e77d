"""The IMU's white noise measured from its own samples (scattertrack.fusion.imu_noise)."""

import math

import numpy as np
import pytest

from scattertrack.fusion.imu_noise import MIN_SAMPLES, ImuNoiseMeter, density_in_use, white_noise_density
from scattertrack.track import marvel


def _samples(density_accel, density_gyro, rate_hz=100.0, seconds=10.0, seed=0, motion=True):
    """Time, specific force and rate: a smooth manoeuvre (a 0.5 Hz swing of 2 m/s^2,
    a 1 rad/s turn) plus white noise of the given densities."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    smooth = np.stack([2.0 * np.sin(math.pi * t), np.cos(0.3 * t), 9.81 + 0.5 * np.sin(2.0 * t)], 1) if motion else np.zeros((len(t), 3))
    turn = np.stack([0.2 * np.sin(t), 0.1 * np.cos(t), np.full_like(t, 1.0)], 1) if motion else np.zeros((len(t), 3))
    sqrt_rate = math.sqrt(rate_hz)
    accel = smooth + density_accel * sqrt_rate * rng.standard_normal((len(t), 3))
    gyro = turn + density_gyro * sqrt_rate * rng.standard_normal((len(t), 3))
    return t, accel, gyro


def _measure(t, accel, gyro):
    meter = ImuNoiseMeter()
    for row in zip(t, accel, gyro):
        meter.add(*row)
    return meter.densities()


@pytest.mark.parametrize("rate_hz", [100.0, 400.0])
@pytest.mark.parametrize("accel_density, gyro_density", [(1.0e-3, 8.7e-5), (3.9e-3, 2.6e-4)])
def test_the_meter_recovers_the_densities_through_a_manoeuvre(rate_hz, accel_density, gyro_density):
    accel, gyro = _measure(*_samples(accel_density, gyro_density, rate_hz=rate_hz))
    # 1000 second differences x 3 axes: the median's spread is a few per cent.
    assert accel == pytest.approx(accel_density, rel=0.08)
    assert gyro == pytest.approx(gyro_density, rel=0.08)


def test_spikes_do_not_inflate_the_measurement():
    t, accel, gyro = _samples(1.0e-3, 8.7e-5)
    accel[::50] += 5.0  # a knock every half second
    assert _measure(t, accel, gyro)[0] == pytest.approx(1.0e-3, rel=0.12)


def test_no_measurement_before_enough_samples_and_gaps_are_skipped():
    t, accel, gyro = _samples(1.0e-3, 8.7e-5, seconds=0.3)
    assert _measure(t, accel, gyro) is None  # 30 samples < MIN_SAMPLES
    t, accel, gyro = _samples(1.0e-3, 8.7e-5, seconds=4.0)
    keep = np.ones(len(t), bool)
    keep[1::3] = False  # every third sample lost: intervals 0.01 and 0.02 s alternate
    meter = ImuNoiseMeter()
    for row in zip(t[keep], accel[keep], gyro[keep]):
        meter.add(*row)
    assert meter.samples == 0 and meter.densities() is None
    assert MIN_SAMPLES <= 100


def test_white_noise_density_formula():
    rng = np.random.default_rng(1)
    sigma = 0.02  # per sample at 100 Hz
    samples = sigma * rng.standard_normal(200_000)
    d2 = samples[2:] - 2 * samples[1:-1] + samples[:-2]
    assert white_noise_density(d2, 0.01) == pytest.approx(sigma * math.sqrt(0.01), rel=0.02)
    assert math.isnan(white_noise_density(np.array([]), 0.01))


def test_the_stated_density_is_a_floor_and_close_agreement_keeps_it():
    assert density_in_use(1.0e-3, 1.1e-3, 1.2) == 1.0e-3
    assert density_in_use(1.0e-3, 3.0e-3, 1.2) == 3.0e-3
    assert density_in_use(1.0e-3, 0.2e-3, 1.2) == 1.0e-3
    assert density_in_use(1.0e-3, math.nan, 1.2) == 1.0e-3


def test_the_estimator_preintegrates_with_a_noisier_imus_density(flight_factory):
    """A flight whose IMU is four times noisier than stated: the estimator measures
    and uses it; with the stated density the same log is tracked as before."""
    data = flight_factory(duration_s=8.0, seed=3)
    rng = np.random.default_rng(9)
    extra = 3.0e-3 * 10.0 * rng.standard_normal(data.imu.accel.shape)  # 3e-3 m/s^2/sqrt(Hz) more at 100 Hz
    noisy = type(data.imu)(data.imu.time_s, data.imu.accel + extra, data.imu.gyro, data.imu.baro_z)
    track = marvel.run_features("marvel", None, noisy, data.features)
    noise = track.stats["drone"]["imu_noise"]
    measured, used, stated = noise["measured"], noise["used"], noise["stated"]
    assert measured[0] == pytest.approx(math.hypot(1.0e-3, 3.0e-3), rel=0.1)
    # In use: the measured density (changed only when it moves by over 10 %);
    # the gyroscope agrees with its stated density and keeps it.
    assert used[0] == pytest.approx(measured[0], rel=0.1) and used[1] == stated[1]
    kept = marvel.run_features("marvel", None, noisy, data.features, imu_noise_from_data=False)
    assert kept.stats["drone"]["imu_noise"]["used"] == stated
    assert kept.stats["drone"]["imu_noise"]["measured"] is None
    # A well-stated IMU is tracked exactly as without the measurement.
    clean_on = marvel.run_features("marvel", None, data.imu, data.features)
    clean_off = marvel.run_features("marvel", None, data.imu, data.features, imu_noise_from_data=False)
    assert clean_on.stats["drone"]["imu_noise"]["used"] == stated
    assert np.array_equal(clean_on.position, clean_off.position)
