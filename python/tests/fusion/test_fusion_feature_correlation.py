"""The features' white share measured from the features (scattertrack.fusion.feature_correlation)."""

import math

import numpy as np
import pytest

from scattertrack.fusion.feature_correlation import (
    MIN_PAIRS,
    FeatureCorrelationMeter,
    correlated_share,
    measurement_function,
)
from scattertrack.track import marvel

CONTROLLER = np.array([-3.0, -15.0, 1.0])


def _feed(errors: np.ndarray, phi: float = 0.78, speed=1.2, rate_hz=10.0, path_noise_m=0.0, seed=0):
    """A drone on a 4 m circle at ``speed`` seen from CONTROLLER; feature errors
    ``errors`` (n, 3); the IMU's displacement exact, or with ``path_noise_m`` per step."""
    rng = np.random.default_rng(seed)
    n = len(errors)
    t = np.arange(n) / rate_hz
    angle = speed * t / 4.0
    position = np.stack([4.0 * np.cos(angle), 4.0 * np.sin(angle), np.full(n, 2.0)], 1)
    features = measurement_function(position, CONTROLLER) + errors
    meter = FeatureCorrelationMeter()
    for k in range(1, n):
        step = position[k] - position[k - 1] + path_noise_m * rng.standard_normal(3)
        meter.add(features[k], position[k - 1], step, phi)
    return meter


def _errors(n, rho, seed=1, sigma=(0.3, 0.05, 0.05)):
    """AR(1) errors of per-epoch correlation ``rho`` (0: white) and 1-sigma ``sigma``."""
    rng = np.random.default_rng(seed)
    e = np.zeros((n, 3))
    w = rng.standard_normal((n, 3)) * np.asarray(sigma)
    e[0] = w[0]
    for k in range(1, n):
        e[k] = rho * e[k - 1] + math.sqrt(1 - rho * rho) * w[k]
    return e


def test_white_errors_measure_a_small_correlated_share():
    range_s, direction_s, pairs = _feed(_errors(400, 0.0)).correlated_shares(CONTROLLER)
    assert pairs == 400 - 1 - 10
    # The conservative (upper 2-sigma) bound of a white series of this length.
    assert range_s < 0.4 and direction_s < 0.4


def test_correlated_errors_measure_a_large_share_even_with_a_rough_imu_path():
    range_s, direction_s, _ = _feed(_errors(400, 0.9), path_noise_m=0.01).correlated_shares(CONTROLLER)
    assert range_s > 0.85 and direction_s > 0.85


def test_no_measurement_before_enough_pairs_or_across_a_break():
    meter = _feed(_errors(10 + MIN_PAIRS, 0.0))
    assert meter.correlated_shares(CONTROLLER) is None
    meter = _feed(_errors(400, 0.0))
    meter.break_chain()
    assert meter.correlated_shares(CONTROLLER) is None
    assert _feed(_errors(400, 0.0)).correlated_shares(None) is None


@pytest.mark.parametrize("share", [0.0, 0.3, 0.75, 1.0])
def test_correlated_share_inverts_the_model_ratio(share):
    phi_1, phi_l = 0.78, 0.78**10
    ratio = (1 - share * phi_l) / (1 - share * phi_1)
    assert correlated_share(ratio, phi_1, phi_l) == pytest.approx(share, abs=1e-12)
    assert correlated_share(0.5, phi_1, phi_l) == 0.0  # below one: whiter than white
    assert correlated_share(50.0, phi_1, phi_l) == 1.0
    assert math.isnan(correlated_share(math.nan, phi_1, phi_l))


def test_the_estimator_raises_the_white_share_of_white_features(circle_flight):
    """The test flights' features carry white noise: after 20 s the measured
    white share is well above the stated 0.5; switched off, it stays 0.5."""
    track = marvel.run_features("marvel", None, circle_flight.imu, circle_flight.features)
    white = track.stats["drone"]["feature_white_fraction"]
    assert white["measured_shares"] is not None and white["measured_shares"][2] >= MIN_PAIRS
    assert min(white["used"]) > 0.7
    kept = marvel.run_features("marvel", None, circle_flight.imu, circle_flight.features, multipath_from_data=False)
    white = kept.stats["drone"]["feature_white_fraction"]
    assert white["measured_shares"] is None and white["used"] == (0.5, 0.5)
