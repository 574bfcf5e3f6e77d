"""The work between epochs (fusion/between_epochs.py): the once-a-second updates off the rows' path."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from scattertrack.fusion import MarvelEstimator, MarvelParams
from scattertrack.fusion.keys import CONTROLLER
from scattertrack.fusion.run import ImuFeed


def _fly(estimator, data, imu_between=True, after_row=None):
    """Feeds ``data``'s rows, each after the IMU samples up to it (with
    ``imu_between`` False only those before the first row: none between
    rows); ``after_row(estimator, estimate)`` after each accepted row."""
    f, imu = data.features, data.imu
    j = 0
    rows = []
    for i in range(len(f)):
        if imu_between or i == 0:
            while j < len(imu) and imu.time_s[j] <= f.time_s[i]:
                estimator.add_imu(imu.time_s[j], imu.accel[j], imu.gyro[j], imu.baro_z[j])
                j += 1
        estimate = estimator.add_features(
            f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i], f.yaw_rad[i],
            f.range_sigma_m[i], f.angle_sigma_rad[i], f.yaw_sigma_rad[i],
        )
        if estimate is not None:
            rows.append(estimate)
            if after_row is not None:
                after_row(estimator, estimate)
    return rows


@pytest.fixture(scope="module")
def flight(flight_factory):
    return flight_factory(duration_s=8.0, seed=11)


def test_no_row_update_relinearises_and_one_between_update_per_skip_rows_does(flight):
    """With IMU samples between the rows, no row's update relinearises; the
    relinearisation comes between epochs, once per ``relinearize_skip`` rows."""
    skip = 5
    estimator = MarvelEstimator(MarvelParams(relinearize_skip=skip))
    relinearised_by_rows = []
    _fly(estimator, flight, after_row=lambda e, _: relinearised_by_rows.append(
        e._smoother.getISAM2Result().getVariablesRelinearized()))
    assert estimator.epochs == len(flight.features)
    assert max(relinearised_by_rows) == 0
    # One run per row (the last row's work has no IMU sample after it).
    assert len(estimator.between_epochs_times_s) == estimator.epochs - 1
    assert estimator._updates == estimator.epochs + estimator.epochs // skip - (estimator.epochs % skip == 0)
    assert estimator.between_epochs_latency().count == estimator.epochs - 1


def test_between_epochs_work_runs_at_the_next_row_without_imu_between(flight):
    """Rows without IMU samples between them: the work runs at the next row's
    start, and the estimator still relinearises (the same count of updates)."""
    estimator = MarvelEstimator(MarvelParams(relinearize_skip=5))
    rows = _fly(estimator, flight, imu_between=False)
    assert len(rows) == len(flight.features)
    assert len(estimator.between_epochs_times_s) == len(rows) - 1
    assert estimator._updates == len(rows) + len(rows) // 5 - (len(rows) % 5 == 0)


def test_relinearize_skip_one_runs_nothing_between_epochs(flight):
    """With ``relinearize_skip`` 1 every row's update relinearises: no extra update."""
    estimator = MarvelEstimator(MarvelParams(relinearize_skip=1, heading_hold_sigma_rad=0.0))
    _fly(estimator, flight)
    assert estimator._updates == estimator.epochs


def test_ordering_anchors_change_no_estimate(flight):
    """The zero-information priors of the between-epoch update leave the
    estimates as they were (an update without relinearisation re-solves the
    same system)."""
    estimator = MarvelEstimator(MarvelParams(relinearize_skip=1000, heading_hold_sigma_rad=0.0))
    _fly(estimator, flight)
    k = estimator._key
    before = (estimator._smoother.calculateEstimatePose3(X(k)), estimator._smoother.calculateEstimatePoint3(CONTROLLER))
    estimator._anchored_update()
    after = (estimator._smoother.calculateEstimatePose3(X(k)), estimator._smoother.calculateEstimatePoint3(CONTROLLER))
    assert after[0].equals(before[0], 1e-9)
    np.testing.assert_allclose(after[1], before[1], atol=1e-9)
    # They are removed with the next update.
    assert len(estimator._pending_removals) >= 4
    graph = gtsam.NonlinearFactorGraph()
    estimator._smoother_update(graph, gtsam.Values(), {}, estimator._pending_removals)


def test_the_heading_hold_ends_between_epochs():
    """The hold's end (the lag back to ``smoother_lag_s``) is applied between
    epochs: the row that ends it keeps the long lag, the next row has the
    short one, and the smoother's lag is the estimator's after every row."""
    from scattertrack.sim import load_scenario, simulate

    sim = simulate(load_scenario("marvel-circle-20m") | {"seed": 1000, "duration_s": 14.0})
    estimator = MarvelEstimator()
    feed = ImuFeed(sim.imu)
    f = sim.features
    lags = []
    for i in range(len(f)):
        feed.until(estimator, float(f.time_s[i]))
        estimate = estimator.add_features(
            f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i], f.yaw_rad[i],
            f.range_sigma_m[i], f.angle_sigma_rad[i], f.yaw_sigma_rad[i],
        )
        if estimate is not None:
            lags.append((estimate.time_s, estimator._lag, estimator._smoother.smootherLag()))
    end, lag = estimator.heading_hold_end_s, estimator.params.smoother_lag_s
    assert lag < end
    at_end = [held for t, held, _ in lags if t == end]
    after = [held for t, held, _ in lags if t > end]
    assert at_end and at_end[0] > lag
    assert after and all(held == lag for held in after)
    assert all(held == smoother_lag for _, held, smoother_lag in lags)
    assert estimator.revised_fallbacks == 0
