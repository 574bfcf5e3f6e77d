"""The causal backscatter-inertial estimator on synthetic flights (conftest.py).

Accuracy against the features alone, orientation, the controller's
convergence, consistency of the 1-sigma output, declined rows by reason,
causality, and the streaming interface.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from scattertrack.fusion import (
    DECLINE_REASONS,
    MarvelEstimator,
    MarvelParams,
    chi_square_gate,
    run_marvel,
    tilt_from_specific_force,
)
from scattertrack.io.types import Features

WHITE = {"correlation_distance_m": 0.0, "range_bias_sigma_m": 0.0}
"""The synthetic features of conftest.py have white noise and no walls: no
correlation between rows, no range bias state."""


@pytest.fixture(scope="module")
def circle_track(circle_flight):
    return run_marvel(circle_flight.imu, circle_flight.features, **WHITE)


def _position_errors(track, data) -> np.ndarray:
    assert np.allclose(track.time_s, data.truth_time[: len(track)])
    return np.linalg.norm(track.position - data.truth_position[: len(track)], axis=1)


# --- accuracy --------------------------------------------------------------------


def test_fused_position_beats_the_features_alone(circle_flight, circle_track):
    errors = _position_errors(circle_track, circle_flight)
    # The features alone, even placed with the TRUE controller position.
    raw = np.linalg.norm(circle_flight.raw_position - circle_flight.truth_position, axis=1)
    assert len(circle_track) == len(circle_flight.features)
    assert errors.mean() < 0.45 * raw.mean()
    assert errors.mean() < 0.5
    assert np.median(errors) < 0.45


def test_orientation_error_is_a_few_degrees(circle_flight, circle_track, rotation_errors):
    errors = rotation_errors(circle_track.orientation, circle_flight.truth_rotation)
    assert errors.mean() < 3.0
    assert errors.max() < 8.0
    assert np.allclose(np.linalg.norm(circle_track.orientation, axis=1), 1.0)
    assert np.all(circle_track.orientation[:, 0] >= 0.0)


def test_controller_estimate_converges(circle_flight, circle_track):
    stats = circle_track.stats["drone"]
    error = stats["controller"] - circle_flight.controller
    assert np.linalg.norm(error) < 0.5
    # And its own 1-sigma accounts for the error.
    assert np.all(np.abs(error) < 3.0 * stats["controller_sigma"])
    # The first row's controller (range sigma 0.5 m, 15 m * 0.05 rad across) is far worse.
    first = MarvelEstimator()
    data = circle_flight
    for i in range(6):
        first.add_imu(data.imu.time_s[i], data.imu.accel[i], data.imu.gyro[i], data.imu.baro_z[i])
    f = data.features
    first.add_features(f.time_s[0], f.range_m[0], f.azimuth_rad[0], f.elevation_rad[0], f.yaw_rad[0])
    assert np.linalg.norm(first.controller - data.controller) > np.linalg.norm(error)


def test_position_sigma_is_consistent(circle_flight, circle_track):
    """NEES-style check: normalised errors per axis within 3 sigma, mean NEES near 3."""
    assert circle_track.sigma is not None and np.all(np.isfinite(circle_track.sigma))
    normalised = (circle_track.position - circle_flight.truth_position) / circle_track.sigma
    within = np.mean(np.all(np.abs(normalised) < 3.0, axis=1))
    nees = np.mean(np.sum(normalised**2, axis=1))
    assert within > 0.95
    # 3 axes: mean 3 when consistent; a factor ~3 either way flags over- or under-confidence.
    assert 1.0 < nees < 9.0


def test_yaw_is_observable_without_yaw_features(flight_factory, rotation_errors):
    """IMU + range/direction alone find the heading once the drone accelerates sideways."""
    data = flight_factory(duration_s=15.0, seed=3)
    track = run_marvel(data.imu, data.features, use_yaw=False, **WHITE)
    errors = rotation_errors(track.orientation, data.truth_rotation)
    late = track.time_s > 10.0
    assert errors[late].mean() < 8.0


# --- declined rows ------------------------------------------------------------------


def test_outliers_and_bad_rows_are_declined_and_counted(flight_factory):
    data = flight_factory(duration_s=15.0, seed=5)
    f = data.features
    columns = {
        name: getattr(f, name).copy()
        for name in (
            "time_s", "range_m", "azimuth_rad", "elevation_rad", "yaw_rad",
            "range_sigma_m", "angle_sigma_rad", "yaw_sigma_rad",
        )
    }
    range_rows, direction_rows, yaw_rows = [40, 60, 80, 100, 120], [50, 70, 90, 110], [55, 75, 95]
    nan_rows = [45, 65, 85]
    columns["range_m"][range_rows] += 12.0  # 24 sigma
    columns["azimuth_rad"][direction_rows] += 0.6  # 12 sigma
    columns["yaw_rad"][yaw_rows] += 2.0  # 20 sigma
    columns["range_m"][nan_rows[0]] = np.nan
    columns["azimuth_rad"][nan_rows[1]] = np.nan
    columns["time_s"][nan_rows[2]] = np.nan
    # A row before the first IMU sample and a repeated epoch time.
    for name, column in columns.items():
        columns[name] = np.insert(column, [0, 31], [column[0], column[30]])
    columns["time_s"][0] = -0.5
    features = Features(**columns)

    track = run_marvel(data.imu, features, **WHITE)
    declined = track.stats["drone"]["declined"]
    assert declined["non_finite"] == 3
    assert declined["before_imu"] == 1
    assert declined["not_after_previous"] == 1
    # Every injected outlier is caught; at 99.9 % a clean one is rarely gated too.
    assert len(range_rows) <= declined["range_gate"] <= len(range_rows) + 1
    assert len(direction_rows) <= declined["direction_gate"] <= len(direction_rows) + 1
    assert len(yaw_rows) <= declined["yaw_gate"] <= len(yaw_rows) + 1
    for key, reason in DECLINE_REASONS.items():
        if declined[key]:
            assert track.skipped.counts[reason] == declined[key]
    # Rows with a gated measurement still give an estimate; invalid rows do not.
    assert len(track) == len(f) - 3
    truth_rows = np.searchsorted(data.truth_time, track.time_s)
    assert np.array_equal(data.truth_time[truth_rows], track.time_s)
    errors = np.linalg.norm(track.position - data.truth_position[truth_rows], axis=1)
    assert errors.mean() < 0.5


def test_gate_does_not_lock_out_after_consecutive_declines(flight_factory):
    """After max_declined_epochs rows with every measurement gated, one row is taken ungated."""
    data = flight_factory(duration_s=8.0, seed=11)
    f = data.features
    # divergence_window_epochs=0: this tests the ungated re-acquisition alone
    # (the persistent-gating restart is tested in test_fusion_divergence.py).
    estimator = MarvelEstimator(max_declined_epochs=3, robust="huber", divergence_window_epochs=0)
    used, imu = [], 0
    for j in range(len(f)):
        while imu < len(data.imu) and data.imu.time_s[imu] <= f.time_s[j]:
            estimator.add_imu(data.imu.time_s[imu], data.imu.accel[imu], data.imu.gyro[imu], data.imu.baro_z[imu])
            imu += 1
        # From row 50 on every measurement is far off (a jump the gate must refuse).
        jump = j >= 50
        estimate = estimator.add_features(
            f.time_s[j], f.range_m[j] + 20.0 * jump, f.azimuth_rad[j] + 1.0 * jump, f.elevation_rad[j],
            f.yaw_rad[j] + 2.5 * jump,
        )
        used.append(estimate.used["range"])
    assert all(used[:50])
    assert used[50:54] == [False, False, False, True]  # three declined epochs, then re-acquisition
    assert estimator.declined["range_gate"] >= 3


# --- causality -------------------------------------------------------------------------


def test_estimates_do_not_change_when_later_data_is_appended(flight_factory, truncate_flight):
    data = flight_factory(duration_s=10.0, seed=7)
    full = run_marvel(data.imu, data.features, **WHITE)
    imu, features = truncate_flight(data, 6.0)
    part = run_marvel(imu, features, **WHITE)
    n = len(part)
    assert 50 < n < len(full)
    assert np.array_equal(part.time_s, full.time_s[:n])
    assert np.array_equal(part.position, full.position[:n])
    assert np.array_equal(part.velocity, full.velocity[:n])
    assert np.array_equal(part.orientation, full.orientation[:n])
    assert np.array_equal(part.sigma, full.sigma[:n])


# --- the revised (fixed-lag smoothed) track ------------------------------------------------


def test_revised_track_has_every_row_and_is_closer_than_the_causal_one(circle_flight, circle_track):
    revised = circle_track.revised
    assert revised is not None and circle_track.stats["drone"]["revised_fallbacks"] == 0
    assert np.array_equal(revised.time_s, circle_track.time_s)
    assert set(revised.epc) == {"drone"}
    times, positions = circle_track.smoothed["drone"]
    assert np.array_equal(times, revised.time_s) and np.array_equal(positions, revised.position)
    # The newest state's revision is its causal estimate: no row came after it.
    assert np.array_equal(revised.position[-1], circle_track.position[-1])
    causal = _position_errors(circle_track, circle_flight)
    smoothed = _position_errors(revised, circle_flight)
    assert smoothed.mean() < 0.9 * causal.mean()
    # Later rows only add information: the 1-sigma shrinks.
    assert np.median(revised.sigma / circle_track.sigma) < 0.9
    assert np.allclose(np.linalg.norm(revised.orientation, axis=1), 1.0)
    assert np.all(revised.orientation[:, 0] >= 0.0)


def test_revised_rows_use_the_rows_of_one_lag_after_them_and_no_more(flight_factory, truncate_flight):
    """A state's revision is fixed once it leaves the window: data appended
    more than ``smoother_lag_s`` after it cannot change it."""
    data = flight_factory(duration_s=10.0, seed=7)
    lag = 3.0
    params = WHITE | {"smoother_lag_s": lag}
    full = run_marvel(data.imu, data.features, **params).revised
    imu, features = truncate_flight(data, 6.0)
    part = run_marvel(imu, features, **params).revised
    # Marginalised before the truncation's last row (whole 1 s buckets, each
    # stamped with its end: see marginalize_every_s): final in both runs.
    stamp = MarvelEstimator(MarvelParams.from_kwargs(**params))._stamp
    settled = np.array([stamp(t) for t in part.time_s]) < stamp(features.time_s[-1]) - lag
    n = int(settled.sum())
    assert n >= 20 and np.all(settled[:n])
    assert np.array_equal(part.time_s[:n], full.time_s[:n])
    assert np.array_equal(part.position[:n], full.position[:n])
    assert np.array_equal(part.orientation[:n], full.orientation[:n])
    # The rows still in the window at the truncation's end differ: the full
    # run revised them with the rows after 6 s.
    assert not np.allclose(part.position[n:], full.position[n : len(part)])


def test_states_leave_the_window_in_groups_and_are_read_as_they_leave(flight_factory):
    """With ``marginalize_every_s`` = 1 s the states of one 1 s bucket leave
    the window together (ten at 10 Hz), each after ``smoother_lag_s`` to
    ``smoother_lag_s`` + 1 s, and their revised rows are read half a bucket
    before that update (none is lost: no fallback); with 0 each leaves alone
    after exactly the lag and is read as it leaves."""
    data = flight_factory(duration_s=10.0, seed=7)
    lag = 3.0
    for every in (1.0, 0.0):
        estimator = MarvelEstimator(MarvelParams(**WHITE, smoother_lag_s=lag, marginalize_every_s=every))
        reads: list[tuple[float, float]] = []  # (update time, state time)
        clock = {"now": math.nan}
        revise = estimator._revise

        def recording(k, causal, revise=revise, reads=reads, clock=clock):
            reads.append((clock["now"], causal.time_s))
            return revise(k, causal)

        estimator._revise = recording
        f, imu = data.features, data.imu
        j = 0
        for i in range(len(f)):
            while j < len(imu) and imu.time_s[j] <= f.time_s[i]:
                estimator.add_imu(imu.time_s[j], imu.accel[j], imu.gyro[j], imu.baro_z[j])
                j += 1
            clock["now"] = f.time_s[i]
            estimate = estimator.add_features(
                f.time_s[i], f.range_m[i], f.azimuth_rad[i], f.elevation_rad[i], f.yaw_rad[i],
                f.range_sigma_m[i], f.angle_sigma_rad[i], f.yaw_sigma_rad[i],
            )
            assert estimate is not None
        assert estimator.revised_fallbacks == 0
        update_times, state_times = np.array(reads).T
        age = update_times - state_times
        if every == 0.0:
            # Read at the update that marginalises it: older than the lag, and
            # younger than lag + one epoch (it was still there before).
            assert np.all(age > lag - 1e-9) and np.all(age < lag + 0.1 + 1e-9)
        else:
            # Read half a bucket before its bucket leaves (MarvelEstimator._prefetch):
            # lag - T/2 to lag + T/2 (+ one epoch) after its time.
            assert np.all(age > lag - every / 2 - 1e-9) and np.all(age < lag + every / 2 + 0.1 + 1e-9)
        _, group_sizes = np.unique(update_times, return_counts=True)
        if every == 0.0:
            # One, or two where the rows' stamps straddle the horizon unevenly.
            assert np.max(group_sizes) <= 2
        else:
            assert np.median(group_sizes) >= 9
            # A bucket leaves whole: its states share their second.
            for t in np.unique(update_times):
                assert len(set(np.floor(state_times[update_times == t]))) == 1
        estimator.finish()
        assert [r.time_s for r in estimator.revised] == list(f.time_s)


def test_holding_the_window_until_the_heading_is_known_fixes_the_take_off_heading():
    """The drone takes off facing 115 deg, the estimator guesses 0 and nothing
    observes the heading until the drone turns. Held in the window until the
    heading is found (``heading_hold_sigma_rad``), the take-off states are
    revised with it; marginalised at the guess (hold off), their error stays."""
    from scattertrack.eval import compare
    from scattertrack.sim import load_scenario, simulate

    scenario = load_scenario("marvel-circle-20m") | {"seed": 1000, "duration_s": 20.0}
    scenario["flight"] = dict(scenario["flight"]) | {"yaw_rad": 2.0}
    sim = simulate(scenario)
    held = run_marvel(sim.imu, sim.features)
    free = run_marvel(sim.imu, sim.features, heading_hold_sigma_rad=0.0)
    end = held.stats["drone"]["heading_hold_end_s"]
    lag, longest = MarvelParams().smoother_lag_s, MarvelParams().heading_hold_max_s
    assert lag < end < longest and math.isnan(free.stats["drone"]["heading_hold_end_s"])
    for track in (held, free):
        assert track.stats["drone"]["revised_fallbacks"] == 0 and len(track.revised) == len(track)
    held_revised, free_revised = compare(sim.truth, held.revised).overall, compare(sim.truth, free.revised).overall
    assert held_revised.mean_orientation_deg < 0.6 * free_revised.mean_orientation_deg
    assert held_revised.mean_3d_m < free_revised.mean_3d_m


# --- interface ----------------------------------------------------------------------------


def test_streaming_interface_and_take_off_row(circle_flight):
    data = circle_flight
    estimator = MarvelEstimator(smoother_lag_s=2.0)
    # A row before any IMU sample is declined.
    assert estimator.add_features(0.0, 15.0, 1.4, 0.0) is None
    assert estimator.declined["before_imu"] == 1
    estimator.step(("imu", data.imu.time_s[0], data.imu.accel[0], data.imu.gyro[0], data.imu.baro_z[0]))
    # A row at the first IMU sample's own time measures the take-off state X(0).
    delta = data.truth_position[0] - data.controller
    first = estimator.add_features(data.imu.time_s[0], np.linalg.norm(delta), math.atan2(delta[1], delta[0]), 0.0)
    assert first is not None and np.allclose(first.position, 0.0, atol=0.2)
    assert first.wall_time_s > 0.0
    f = data.features
    estimates = []
    imu_time = data.imu.time_s
    for i in range(1, 400):
        estimator.step(("imu", imu_time[i], data.imu.accel[i], data.imu.gyro[i], data.imu.baro_z[i]))
        # The rows from this sample's time up to the next sample's.
        for j in np.flatnonzero((f.time_s >= imu_time[i]) & (f.time_s < imu_time[i + 1])):
            row = ("features", f.time_s[j], f.range_m[j], f.azimuth_rad[j], f.elevation_rad[j], f.yaw_rad[j])
            estimates.append(estimator.step(row))
    assert len(estimates) == 40 and all(e is not None for e in estimates)
    last = estimates[-1]
    assert last.position.shape == (3,) and last.velocity.shape == (3,) and last.orientation.shape == (4,)
    assert np.all(np.isfinite(last.sigma)) and np.all(np.isfinite(last.controller_sigma))
    assert last.used == {"range": True, "direction": True, "yaw": True, "baro": True}
    assert np.linalg.norm(last.position - data.truth_position[39]) < 1.0
    assert set(estimator.latency_ns()) >= {"p50", "p99"}
    # IMU samples out of order or non-finite are ignored and counted.
    estimator.add_imu(imu_time[10], data.imu.accel[10], data.imu.gyro[10])
    estimator.add_imu(imu_time[400], [np.nan, 0.0, 9.8], data.imu.gyro[400])
    assert estimator.imu_declined == {"non_finite": 1, "not_after_previous": 1}


def test_run_marvel_reports_stats_and_latency(circle_track):
    stats = circle_track.stats["drone"]
    assert stats["epochs"] == len(circle_track)
    assert stats["time_ns_p50"] > 0 and stats["time_ns_p99"] >= stats["time_ns_p50"]
    assert circle_track.latency_quantiles_ns["p99"] == stats["time_ns_p99"]
    assert set(circle_track.epc) == {"drone"}


def test_params_are_checked():
    with pytest.raises(ValueError, match="unknown Marvel parameter"):
        MarvelParams.from_kwargs(smoother_lag=3.0)
    with pytest.raises(ValueError):
        MarvelEstimator(MarvelParams(), smoother_lag_s=1.0)
    with pytest.raises(ValueError, match="robust"):
        MarvelParams(robust="cauchy")
    with pytest.raises(ValueError, match="smoother_lag_s"):
        MarvelParams(smoother_lag_s=0.0)
    with pytest.raises(ValueError, match="marginalize_every_s"):
        MarvelParams(marginalize_every_s=7.0)
    with pytest.raises(ValueError, match="relinearize_skip"):
        MarvelParams(relinearize_skip=0)
    with pytest.raises(ValueError, match="heading_hold"):
        MarvelParams(heading_hold_sigma_rad=-0.1)
    with pytest.raises(ValueError, match="multipath"):
        MarvelParams(multipath="white")
    with pytest.raises(ValueError, match="multipath_white_fraction"):
        MarvelParams(multipath_white_fraction=1.0)
    defaults = MarvelParams()
    # docs/marvel.md section 3.
    assert (defaults.accel_noise_density, defaults.gyro_noise_density) == (1.0e-3, 8.7e-5)
    assert (defaults.accel_bias_random_walk, defaults.gyro_bias_random_walk) == (1.0e-4, 2.0e-5)
    assert (defaults.accel_bias_sigma, defaults.gyro_bias_sigma) == (0.02, 0.002)
    assert defaults.gravity_m_s2 == 9.80665


def test_chi_square_gate_quantiles():
    assert chi_square_gate(0.999, 1) == pytest.approx(10.828, abs=1e-3)
    assert chi_square_gate(0.999, 2) == pytest.approx(13.816, abs=1e-3)
    assert chi_square_gate(0.95, 1) == pytest.approx(3.841, abs=1e-3)


def test_tilt_from_specific_force():
    roll, pitch = 0.1, -0.2
    # R^T (0, 0, g) for R = Ry(pitch) Rx(roll).
    force = 9.8 * np.array([-math.sin(pitch), math.cos(pitch) * math.sin(roll), math.cos(pitch) * math.cos(roll)])
    assert tilt_from_specific_force(force) == pytest.approx((roll, pitch))


class _Nav:
    """The part of a gtsam.NavState the estimator's helpers read: position (m), velocity (m/s)."""

    def __init__(self, velocity=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0)):
        self._velocity = np.asarray(velocity, dtype=float)
        self._position = np.asarray(position, dtype=float)

    def velocity(self):
        return self._velocity

    def position(self):
        return self._position


def test_correlated_rows_are_inflated_by_rows_per_decorrelation():
    estimator = MarvelEstimator(MarvelParams(correlation_distance_m=0.5, correlation_time_s=5.0))
    estimator._last_epoch_time = 10.0
    # At rest: 5 s / 0.1 s = 50 rows share one multipath error.
    assert estimator._correlation_inflation(10.1, _Nav([0.0, 0.0, 0.0])) == pytest.approx(math.sqrt(50.0))
    # At 2.5 m/s the error decorrelates in 0.2 s: two rows each.
    assert estimator._correlation_inflation(10.1, _Nav([1.5, 2.0, 0.0])) == pytest.approx(math.sqrt(2.0))
    # Faster than one decorrelation per row: never below 1 (no deflation).
    assert estimator._correlation_inflation(10.1, _Nav([30.0, 0.0, 0.0])) == 1.0
    off = MarvelEstimator(MarvelParams(correlation_distance_m=0.0))
    off._last_epoch_time = 10.0
    assert off._correlation_inflation(10.1, _Nav([0.0, 0.0, 0.0])) == 1.0


def _sim_run(use_ground: bool):
    """10 s of marvel-circle-20m (2 s on the ground, climb, hover) with a noise-free IMU."""
    from scattertrack.sim import load_scenario, simulate
    from scattertrack.sim.imu import NOISE_KEYS

    scenario = load_scenario("marvel-circle-20m") | {"duration_s": 10.0}
    scenario["imu_model"] = {key: 0.0 for key in NOISE_KEYS}
    sim = simulate(scenario, seed=0)
    track = run_marvel(sim.imu, sim.features, use_ground=use_ground, use_yaw=False)
    truth = np.column_stack([np.interp(track.time_s, sim.truth.time_s, sim.truth.position[:, a]) for a in range(3)])
    return track, np.linalg.norm(track.position - truth, axis=1)


def test_ground_factors_keep_a_perfect_imu_from_drifting_in_the_hover():
    # The features at 20 m carry metre-level correlated errors. Without the
    # zero-rotation updates on the ground the gyroscope bias is free, the
    # features pull it, and the tilt it integrates drags the hover by metres.
    track, errors = _sim_run(use_ground=True)
    _, errors_free = _sim_run(use_ground=False)
    assert np.max(errors[track.time_s < 9.0]) < 0.3
    assert np.max(errors_free) > 3.0 * np.max(errors[track.time_s < 9.0])


def test_on_ground_until_the_imu_shows_motion_and_predict_propagates():
    estimator = MarvelEstimator()
    assert estimator.predict(0.0) is None
    g = estimator.params.gravity_m_s2
    for i in range(50):
        estimator.add_imu(i * 0.01, [0.0, 0.0, g], [0.0, 0.0, 0.0])
    assert estimator.on_ground
    assert estimator.add_features(0.5, 20.0, 1.5, 0.05) is not None
    position, velocity, rotation = estimator.predict(0.55)
    assert np.allclose(velocity, 0.0, atol=1e-3) and np.allclose(rotation, np.eye(3), atol=1e-3)
    # 1 m/s^2 up: it has left the ground, and predict integrates it from the
    # held-sample prediction at 0.55 s to 0.99 s: 0.44 m/s.
    for i in range(50, 100):
        estimator.add_imu(i * 0.01, [0.0, 0.0, g + 1.0], [0.0, 0.0, 0.0])
    assert not estimator.on_ground
    position, velocity, _ = estimator.predict(0.99)
    assert velocity[2] == pytest.approx(0.44, abs=0.02)


def test_level_horizontal_acceleration_ends_the_ground_phase_on_tilted_ground():
    estimator = MarvelEstimator()
    g = estimator.params.gravity_m_s2
    tilt = 0.05  # rad: a drone resting on uneven ground reads gravity off its z axis
    rest = np.array([-g * math.sin(tilt), 0.0, g * math.cos(tilt)])
    for i in range(100):
        estimator.add_imu(i * 0.01, rest, [0.0, 0.0, 0.0])
    assert estimator.on_ground  # tilted, but not moving
    # A rail's 0.5 m/s ramp: 0.94 m/s^2 forward changes |f| by only 0.045 m/s^2.
    estimator.add_imu(1.0, rest + [0.94, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert not estimator.on_ground


def _run_with_smoother_swapped(data, estimator, rows: int, at: int, replacement):
    """Feeds ``rows`` feature rows (and the IMU before each); just before row ``at`` the
    estimator's smoother is replaced by ``replacement(real_smoother)``. Returns the
    estimates and the replaced smoother."""
    imu, features = data.imu, data.features
    j = 0
    results = []
    swapped = None
    for i in range(rows):
        while j < len(imu) and imu.time_s[j] <= features.time_s[i]:
            estimator.add_imu(imu.time_s[j], imu.accel[j], imu.gyro[j], imu.baro_z[j])
            j += 1
        if i == at:
            swapped = replacement(estimator._smoother)
            estimator._smoother = swapped
        results.append(estimator.add_features(
            features.time_s[i], features.range_m[i], features.azimuth_rad[i], features.elevation_rad[i],
            features.yaw_rad[i], features.range_sigma_m[i], features.angle_sigma_rad[i], features.yaw_sigma_rad[i],
        ))
    return results, swapped


def test_a_solver_failure_declines_the_row_and_restarts_the_smoother(circle_flight):
    data = circle_flight
    # A 2 s lag, each state read alone: by the failure (3 s) the first
    # states have left the window with their revisions, the rest have not.
    estimator = MarvelEstimator(MarvelParams(correlation_distance_m=0.0, smoother_lag_s=2.0, marginalize_every_s=0.0))
    failed_at = 30

    class Failing:
        """The real smoother's values (read before the update), but the update fails."""

        def __init__(self, real):
            self.real = real

        def __getattr__(self, name):
            return getattr(self.real, name)

        def update(self, *args):
            raise RuntimeError("Indeterminate linear system detected")

    results, failing = _run_with_smoother_swapped(data, estimator, 60, failed_at, Failing)
    # Restarted: a fresh smoother, neither the failing one nor the one it replaced.
    assert estimator._smoother is not failing and estimator._smoother is not failing.real
    assert results[failed_at] is None
    assert estimator.declined["solver_failure"] == 1 and estimator.restarts == 1
    assert all(r is not None for r in results[failed_at + 1 :])
    truth = np.array([np.interp(results[-1].time_s, data.truth_time, data.truth_position[:, a]) for a in range(3)])
    assert np.linalg.norm(results[-1].position - truth) < 1.0
    # The revised track: the states in the failed smoother's window keep
    # their causal estimates (counted); every accepted row is there once.
    estimator.finish()
    accepted = [r for r in results if r is not None]
    assert [r.time_s for r in estimator.revised] == [r.time_s for r in accepted]
    # Stamped at or after the failed row's time minus the lag: not yet marginalised.
    cutoff = data.features.time_s[failed_at] - estimator.params.smoother_lag_s
    in_window = [r for r in results[:failed_at] if r is not None and r.time_s >= cutoff]
    assert estimator.revised_fallbacks == len(in_window) > 10
    assert len(in_window) < failed_at - 5  # the oldest had left with their revisions
    for row in in_window:
        assert any(r is row for r in estimator.revised)


class _Delegating:
    """A stand-in smoother that passes everything to the real one; a test
    overrides the one read-back it corrupts."""

    def __init__(self, real):
        self._real = real

    def __getattr__(self, name):
        return getattr(self._real, name)


def test_a_solve_out_of_physical_bounds_is_declined_as_diverged(circle_flight):
    """A finite but absurd solve (the runaway seen behind reflecting walls at IQ
    level): declined as "diverged", the smoother restarts, the track stays sane."""
    estimator = MarvelEstimator(MarvelParams(**WHITE))

    class RunningAway(_Delegating):
        def calculateEstimatePoint3(self, key):
            return np.array([1e108, 0.0, 0.0])

    results, running_away = _run_with_smoother_swapped(circle_flight, estimator, 40, 30, RunningAway)
    assert estimator._smoother is not running_away
    assert results[30] is None
    assert estimator.declined["diverged"] == 1 and estimator.declined["solver_failure"] == 0
    assert estimator.restarts == 1
    assert all(r is not None and np.linalg.norm(r.controller) < 1e3 for r in results[31:])
    with pytest.raises(ValueError, match="max_speed_m_s"):
        MarvelParams(max_speed_m_s=0.0)


def test_a_non_finite_solve_is_a_solver_failure(circle_flight):
    """A smoother that returns a non-finite state (an overflowed solve) is treated like one
    that throws: the row is declined, the smoother restarts, and no inf reaches the track."""
    estimator = MarvelEstimator(MarvelParams(**WHITE))

    class Overflowing(_Delegating):
        def calculateEstimateVector(self, key):
            return np.full(3, np.inf)

    results, overflowing = _run_with_smoother_swapped(circle_flight, estimator, 40, 30, Overflowing)
    assert estimator._smoother is not overflowing
    assert results[30] is None
    assert estimator.declined["solver_failure"] == 1 and estimator.restarts == 1
    assert all(r is not None and np.all(np.isfinite(r.position)) for r in results[31:])


# --- multipath states and the range bias -------------------------------------------


def test_multipath_states_follow_the_gauss_markov_model():
    """M(k) = phi M(k-1) + w, phi = exp(-|dp| / d - dt / tau): frozen while hovering,
    renewed once the drone has moved a few decimetres; M(k) keeps its row's sigma."""
    import gtsam
    from gtsam.symbol_shorthand import M

    params = MarvelParams(correlation_distance_m=0.5, correlation_time_s=5.0, multipath_white_fraction=0.6)
    estimator = MarvelEstimator(params)
    sigma = np.array([1.0, 0.05, 0.05])  # total sigma: range m, direction rad
    correlated = sigma * 0.8  # sqrt(1 - 0.6^2)
    graph, initial, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
    estimator._key = 0
    assert np.allclose(estimator._add_multipath(graph, initial, stamps, 10.0, sigma, None, _Nav(position=[0, 0, 0])), 0.0)
    assert graph.size() == 1  # the stationary prior N(0, correlated^2)
    assert np.allclose(graph.at(0).noiseModel().sigmas(), correlated)
    estimator._last_epoch_time = 10.0
    previous = np.array([0.4, 0.01, -0.02])
    for moved, phi in ((0.0, math.exp(-0.1 / 5.0)), (0.25, math.exp(-0.5 - 0.1 / 5.0))):
        for scale in (2.0, 0.5, 1e6):  # the next row is less / more certain; an unsettled fringe
            graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
            estimator._key += 1
            estimator._multipath = previous
            estimator._multipath_sigma = correlated
            predicted = estimator._add_multipath(
                graph, initial, stamps, 10.1, scale * sigma, np.zeros(3), _Nav(position=[moved, 0.0, 0.0])
            )
            assert np.allclose(predicted, phi * previous)  # never scaled up by the sigma ratio
            walk = graph.at(0).noiseModel().sigmas()
            # phi^2 Var M(k-1) + Var w: the row's own sigma, or a bit more when it shrank.
            total = phi**2 * correlated**2 + walk**2
            assert np.all(total >= (scale * correlated) ** 2 * (1 - 1e-9))
            assert np.allclose(walk**2, np.maximum((scale * correlated) ** 2 - (phi * correlated) ** 2,
                                                   (1 - phi**2) * (scale * correlated) ** 2))
            values = gtsam.Values()
            values.insert(M(estimator._key - 1), np.array([1.0, 1.0, 1.0]))
            values.insert(M(estimator._key), np.zeros(3))
            assert np.allclose(graph.at(0).unwhitenedError(values), -phi)
            assert stamps[M(estimator._key)] == 10.1


def test_white_features_do_not_derail_the_multipath_states(flight_factory):
    """Features whose errors are white (no multipath, e.g. thermal noise at low SNR) but
    an estimator that assumes them correlated: the model is wrong, the track stays sane.
    (With a white share of 0.1 these two flights ended metres away.)"""
    for seed in (4, 7):
        data = flight_factory(duration_s=30.0, seed=seed)
        track = run_marvel(data.imu, data.features)
        errors = np.linalg.norm(
            track.position - np.column_stack([np.interp(track.time_s, data.truth_time, data.truth_position[:, a]) for a in range(3)]),
            axis=1,
        )
        assert errors.mean() < 0.4


def test_the_range_bias_of_walls_is_estimated(flight_factory):
    """Ranges 0.5 m too long (walls' excess path): the range bias state finds most of it,
    and the controller lands closer than without the state."""
    for seed in (3, 5):
        data = flight_factory(duration_s=30.0, seed=seed)
        f = data.features
        biased = Features(
            f.time_s, f.range_m + 0.5, f.azimuth_rad, f.elevation_rad, f.yaw_rad,
            f.range_sigma_m, f.angle_sigma_rad, f.yaw_sigma_rad,
        )
        with_state = run_marvel(data.imu, biased, correlation_distance_m=0.0).stats["drone"]
        without = run_marvel(data.imu, biased, correlation_distance_m=0.0, range_bias_sigma_m=0.0).stats["drone"]
        assert without["range_bias_m"] is None
        assert abs(with_state["range_bias_m"] - 0.5) < 0.3
        assert np.linalg.norm(with_state["controller"] - data.controller) < np.linalg.norm(
            without["controller"] - data.controller
        )
