"""Divergence (fusion/divergence.py): bounds, persistent gating, the restart from the features."""

import numpy as np
import pytest

from scattertrack.fusion import MarvelEstimator, MarvelParams
from scattertrack.fusion.divergence import (
    GateMonitor,
    controller_from_origin,
    is_plausible_controller,
    physical_violation,
    position_from_features,
)

BOUNDS = {"max_speed_m_s": 30.0, "max_controller_range_m": 1000.0, "max_position_m": 1000.0}
WHITE = {"correlation_distance_m": 0.0, "range_bias_sigma_m": 0.0}


def test_physical_bounds():
    ok = physical_violation([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], [0.0, -15.0, 1.0], **BOUNDS)
    assert ok is None
    assert "m/s" in physical_violation([0, 0, 0], [40.0, 0, 0], [0, -15, 1], **BOUNDS)
    assert "controller" in physical_violation([0, 0, 0], [0, 0, 0], [5000.0, 0, 0], **BOUNDS)
    # The drone at -49169 m (once printed as a result) is refused.
    assert "take-off" in physical_violation([0.0, 0.0, -49169.0], [0, 0, 0], [0.0, 0.0, -49170.0], **BOUNDS)
    assert physical_violation([np.nan, 0, 0], [0, 0, 0], [0, 0, 0], **BOUNDS) == "non-finite state"


def test_gate_monitor_needs_a_persistent_majority():
    monitor = GateMonitor(window=5, fraction=0.8)
    assert not any(monitor.add(g) for g in (True, True, True))  # the window is not full yet
    assert not monitor.add(False)
    assert monitor.add(True)  # 4 of the last 5
    monitor.clear()
    assert not monitor.add(True)
    assert not GateMonitor(window=0, fraction=0.8).add(True)


def test_feature_positions_round_trip():
    controller = controller_from_origin(15.0, 1.2, 0.1)
    assert np.allclose(position_from_features(controller, 15.0, 1.2, 0.1), 0.0, atol=1e-12)
    assert is_plausible_controller(controller, np.zeros(3), 1000.0)
    assert not is_plausible_controller([np.inf, 0, 0], np.zeros(3), 1000.0)
    assert not is_plausible_controller([2000.0, 0, 0], np.zeros(3), 1000.0)


def _run(estimator, data, corrupt=lambda j, row: row):
    imu, f = data.imu, data.features
    out, j = [], 0
    for i in range(len(f)):
        while j < len(imu) and imu.time_s[j] <= f.time_s[i]:
            estimator.add_imu(imu.time_s[j], imu.accel[j], imu.gyro[j], imu.baro_z[j])
            j += 1
        row = corrupt(i, [f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i], f.yaw_rad[i]])
        out.append(estimator.add_features(*row))
    return out


def test_a_divergence_is_detected_restarted_from_the_features_and_recovered(flight_factory):
    """Rows 80-109 claim the drone 8 m farther and 0.5 rad round: every
    measurement is gated for 3 s, the state (not the rows) is then judged wrong
    and restarted from the features; when the rows return to the truth, the
    track does too, and the divergence counts as recovered."""
    data = flight_factory(duration_s=25.0, seed=21)

    def corrupt(i, row):
        if 80 <= i < 110:
            row[1] += 8.0
            row[2] += 0.5
        return row

    estimator = MarvelEstimator(MarvelParams(**WHITE, max_declined_epochs=1000))
    estimates = _run(estimator, data, corrupt)
    assert estimator.divergences >= 1
    assert estimator.declined["persistently_gated"] >= 1
    assert estimator.divergences_recovered == estimator.divergences
    final = [e for e in estimates[-30:] if e is not None]
    errors = [np.linalg.norm(e.position - data.truth_position[np.searchsorted(data.truth_time, e.time_s)]) for e in final]
    assert len(final) >= 25 and np.mean(errors) < 1.0


def test_a_state_beyond_the_bounds_is_refused_and_restarted(flight_factory):
    """A tiny ``max_position_m`` makes the climb itself implausible: the rows
    past it are refused (never output) and each refusal restarts the smoother."""
    data = flight_factory(duration_s=8.0, seed=4)
    estimator = MarvelEstimator(MarvelParams(**WHITE, max_position_m=1.0))
    estimates = _run(estimator, data)
    accepted = [e for e in estimates if e is not None]
    assert estimator.declined["diverged"] > 0 and estimator.divergences == estimator.declined["diverged"]
    assert all(np.linalg.norm(e.position) <= 1.0 for e in accepted)
    assert any("take-off" in reason for reason in estimator.divergence_reasons)


@pytest.mark.parametrize("gated_fraction", [1.0])
def test_clean_flights_do_not_diverge(circle_flight, gated_fraction):
    estimator = MarvelEstimator(MarvelParams(**WHITE, divergence_gated_fraction=gated_fraction))
    _run(estimator, circle_flight)
    assert estimator.divergences == 0 and estimator.restarts == 0
