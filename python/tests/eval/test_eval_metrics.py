"""compare() and nees() on synthetic circles with known errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eval_synthetic import circle, concat_tracks, concat_truth, make_truth, track_from
from scattertrack.eval import compare, nees
from scattertrack.eval.metrics import NO_TRUTH_FOR_TAG, OUTSIDE_TRUTH_SPAN
from scattertrack.io.types import Track, Truth

TIGHT = 1e-9  # metres: exact up to floating point


def test_constant_offset_gives_that_error_exactly():
    truth = make_truth()
    report = compare(truth, track_from(truth, position_offset=(0.005, 0.0, 0.0)))
    tag = report.per_tag["E2000A01"]
    assert tag.n == len(tag.errors_3d_m) == 501
    for value in (tag.median_3d_m, tag.p90_3d_m, tag.mean_3d_m, tag.rmse_3d_m, tag.max_3d_m):
        assert value == pytest.approx(0.005, abs=TIGHT)
    np.testing.assert_allclose(tag.median_axis_m, [0.005, 0.0, 0.0], atol=TIGHT)
    assert report.overall.median_3d_m == pytest.approx(0.005, abs=TIGHT)
    assert tag.n_excluded == 0 and report.excluded.total == 0
    assert tag.first_estimate_s == 0.0


def test_per_axis_errors():
    truth = make_truth()
    report = compare(truth, track_from(truth, position_offset=(0.003, -0.004, 0.012)))
    tag = report.per_tag["E2000A01"]
    assert tag.median_3d_m == pytest.approx(0.013, abs=TIGHT)
    np.testing.assert_allclose(tag.median_axis_m, [0.003, 0.004, 0.012], atol=TIGHT)
    np.testing.assert_allclose(tag.p90_axis_m, [0.003, 0.004, 0.012], atol=TIGHT)
    assert tag.errors_axis_m.shape == (tag.n, 3)


@settings(max_examples=30, deadline=None)
@given(st.tuples(*[st.floats(-0.1, 0.1, allow_nan=False)] * 3))
def test_any_constant_offset_is_recovered(offset):
    truth = make_truth(duration_s=2.0)
    tag = compare(truth, track_from(truth, position_offset=offset)).per_tag["E2000A01"]
    assert tag.median_3d_m == pytest.approx(np.linalg.norm(offset), abs=TIGHT)
    np.testing.assert_allclose(tag.median_axis_m, np.abs(offset), atol=TIGHT)


def test_track_between_truth_samples_is_interpolated():
    truth = make_truth()
    time = np.arange(0.0013, 9.99, 0.0371)  # never on a 200 Hz sample
    position, velocity = circle(time)
    track = Track(time, np.full(len(time), "E2000A01"), position + [0.0, 0.0, 0.005], velocity)
    tag = compare(truth, track).per_tag["E2000A01"]
    # Linear interpolation of a 0.5 m circle at 200 Hz is off by a few micrometres at most.
    assert tag.median_3d_m == pytest.approx(0.005, abs=1e-5)
    assert tag.median_velocity_m_s == pytest.approx(0.0, abs=1e-4)


def test_velocity_error_from_truth_columns():
    truth = make_truth()
    tag = compare(truth, track_from(truth, velocity_offset=(0.01, 0.0, 0.0))).per_tag["E2000A01"]
    assert tag.median_velocity_m_s == pytest.approx(0.01, abs=TIGHT)
    assert tag.p90_velocity_m_s == pytest.approx(0.01, abs=TIGHT)
    assert tag.n_velocity == tag.n


def test_velocity_error_from_finite_differences_when_truth_has_none():
    analytic = make_truth()
    truth = make_truth(with_velocity=False)
    track = track_from(analytic, velocity_offset=(0.0, 0.0, 0.02))
    tag = compare(truth, track).per_tag["E2000A01"]
    # Central differences at 200 Hz on this circle are off by ~2e-6 m/s.
    assert tag.median_velocity_m_s == pytest.approx(0.02, abs=1e-4)


def test_nan_velocity_is_left_out_of_velocity_statistics_only():
    truth = make_truth()
    track = track_from(truth, position_offset=(0.005, 0.0, 0.0), velocity_offset=(0.03, 0.0, 0.0))
    track.velocity[::2] = np.nan  # half the rows without velocity
    tag = compare(truth, track).per_tag["E2000A01"]
    assert tag.n == 501
    assert tag.n_velocity == 250
    assert tag.median_velocity_m_s == pytest.approx(0.03, abs=TIGHT)
    assert len(tag.velocity_errors_m_s) == tag.n  # aligned with times_s, nan where absent

    track.velocity[:] = np.nan  # a method without velocity
    report = compare(truth, track)
    tag = report.per_tag["E2000A01"]
    assert tag.n_velocity == 0
    assert np.isnan(tag.median_velocity_m_s) and np.isnan(report.overall.p90_velocity_m_s)
    assert tag.median_3d_m == pytest.approx(0.005, abs=TIGHT)


def _start_stop_truth(with_velocity=True) -> Truth:
    """Still for the first second, then on the circle until t = 11 s."""
    time = np.arange(0, 11 * 200 + 1) / 200.0
    position, velocity = circle(np.maximum(time - 1.0, 0.0))
    velocity[time < 1.0] = 0.0
    if not with_velocity:
        velocity[:] = np.nan
    return Truth(time, np.full(len(time), "E2000A01"), position, velocity)


def _track_with_errors(truth: Truth, error_m) -> Track:
    """Every 4th truth sample, offset along x by ``error_m(time)`` metres."""
    track = track_from(truth)
    track.position[:, 0] += error_m(track.time_s)
    return track


@pytest.mark.parametrize("with_velocity", [True, False])
def test_convergence_time_is_measured_from_motion_start(with_velocity):
    truth = _start_stop_truth(with_velocity)
    track = _track_with_errors(truth, lambda t: np.where(t < 3.0, 0.05, 0.005))
    report = compare(truth, track)
    tag = report.per_tag["E2000A01"]
    assert tag.motion_start_s == pytest.approx(1.0)
    assert tag.converged_at_s == pytest.approx(3.0)
    assert tag.convergence_time_s == pytest.approx(2.0)
    assert report.overall.convergence_time_s == pytest.approx(2.0)
    rows_after = np.count_nonzero(track.time_s >= 3.0)
    assert tag.converged_fraction == pytest.approx(rows_after / len(track))


def test_convergence_restarts_after_a_late_excursion():
    truth = make_truth()
    error = lambda t: np.where((t < 2.0) | ((t >= 5.0) & (t < 5.5)), 0.05, 0.005)  # noqa: E731
    tag = compare(truth, _track_with_errors(truth, error)).per_tag["E2000A01"]
    assert tag.convergence_time_s == pytest.approx(5.5)


def test_never_converged_is_nan():
    truth = make_truth()
    report = compare(truth, _track_with_errors(truth, lambda t: np.full_like(t, 0.05)))
    tag = report.per_tag["E2000A01"]
    assert np.isnan(tag.convergence_time_s) and np.isnan(tag.converged_at_s)
    assert tag.converged_fraction == 0.0
    assert np.isnan(report.overall.convergence_time_s)


def test_convergence_must_hold_for_hold_s():
    truth = make_truth()
    late = _track_with_errors(truth, lambda t: np.where(t < 9.5, 0.05, 0.005))  # good for the last 0.5 s
    assert np.isnan(compare(truth, late, hold_s=1.0).per_tag["E2000A01"].convergence_time_s)
    assert compare(truth, late, hold_s=0.4).per_tag["E2000A01"].convergence_time_s == pytest.approx(9.5)


def test_convergence_threshold_is_configurable():
    truth = make_truth()
    track = _track_with_errors(truth, lambda t: np.where(t < 2.0, 0.05, 0.015))
    assert np.isnan(compare(truth, track, convergence_threshold_m=0.01).per_tag["E2000A01"].convergence_time_s)
    assert compare(truth, track, convergence_threshold_m=0.02).per_tag["E2000A01"].convergence_time_s == pytest.approx(
        2.0
    )


def test_rows_outside_truth_span_are_excluded_and_counted():
    truth = make_truth(start_s=1.0, duration_s=8.0)  # truth covers 1 s .. 9 s
    time = np.arange(0, 501) / 50.0  # track covers 0 s .. 10 s at 50 Hz
    position, velocity = circle(time - 1.0)
    track = Track(time, np.full(len(time), "E2000A01"), position + [0.005, 0.0, 0.0], velocity)
    report = compare(truth, track)
    tag = report.per_tag["E2000A01"]
    assert tag.n_rows == 501
    assert tag.n_excluded == 100  # 50 rows before 1 s, 50 after 9 s
    assert tag.n == 401
    assert report.excluded.counts == {OUTSIDE_TRUTH_SPAN: 100}
    assert tag.times_s.min() == 1.0 and tag.times_s.max() == 9.0
    assert tag.median_3d_m == pytest.approx(0.005, abs=TIGHT)
    assert tag.first_estimate_s == pytest.approx(-1.0)


def test_multiple_tags_are_pooled():
    truth_a = make_truth("A")
    truth_b = make_truth("B", centre=(0.0, 0.0, 1.0))
    truth_c = make_truth("C")  # never tracked
    track_a = track_from(truth_a, every=4, position_offset=(0.005, 0.0, 0.0))
    track_b = track_from(truth_b, every=2, position_offset=(0.0, 0.010, 0.0))
    track_b.position[track_b.time_s < 3.0, 1] += 0.1  # B converges at 3 s
    ghost = track_from(make_truth("GHOST"), every=100)  # a tag with no truth
    # Interleave the tags in time, as a multi-tag tracker writes them.
    merged = concat_tracks(track_a, ghost, track_b)
    order = np.argsort(merged.time_s, kind="stable")
    merged = Track(merged.time_s[order], merged.epc[order], merged.position[order], merged.velocity[order])
    report = compare(concat_truth(truth_a, truth_b, truth_c), merged)

    assert list(report.per_tag) == ["A", "B"]
    a, b, overall = report.per_tag["A"], report.per_tag["B"], report.overall
    assert (a.n, b.n, overall.n) == (501, 1001, 1502)
    assert a.median_3d_m == pytest.approx(0.005, abs=TIGHT)
    assert overall.median_3d_m == pytest.approx(0.010, abs=TIGHT)
    expected_mean = (501 * 0.005 + np.sum(np.where(track_b.time_s < 3.0, 0.11, 0.01))) / 1502
    assert overall.mean_3d_m == pytest.approx(expected_mean, abs=TIGHT)
    np.testing.assert_allclose(overall.errors_3d_m, np.concatenate([a.errors_3d_m, b.errors_3d_m]))
    assert overall.convergence_time_s == pytest.approx(3.0)  # the worst tag
    assert a.convergence_time_s == 0.0
    assert report.excluded.counts == {NO_TRUTH_FOR_TAG: len(ghost)}
    assert report.missing_tags == ["C"]
    b_after = np.count_nonzero(track_b.time_s >= 3.0)
    assert overall.converged_fraction == pytest.approx((501 + b_after) / 1502)


def test_unsorted_track_rows_give_the_same_report():
    truth = make_truth()
    track = _track_with_errors(truth, lambda t: np.where(t < 2.0, 0.05, 0.005))
    shuffled = np.random.default_rng(1).permutation(len(track))
    shuffled_track = Track(
        track.time_s[shuffled], track.epc[shuffled], track.position[shuffled], track.velocity[shuffled]
    )
    expected = compare(truth, track).per_tag["E2000A01"]
    actual = compare(truth, shuffled_track).per_tag["E2000A01"]
    assert actual.convergence_time_s == pytest.approx(expected.convergence_time_s)
    assert actual.median_3d_m == expected.median_3d_m
    np.testing.assert_array_equal(actual.times_s, expected.times_s)


def test_skip_first_s_and_after_convergence_only():
    truth = make_truth()
    track = _track_with_errors(truth, lambda t: np.where(t < 2.0, 0.05, 0.005))
    full = compare(truth, track).per_tag["E2000A01"]
    assert full.max_3d_m == pytest.approx(0.05)
    skipped = compare(truth, track, skip_first_s=2.0).per_tag["E2000A01"]
    assert skipped.max_3d_m == pytest.approx(0.005)
    assert skipped.n == np.count_nonzero(track.time_s >= 2.0)
    assert skipped.convergence_time_s == pytest.approx(2.0)  # convergence ignores the filters
    after = compare(truth, track, after_convergence_only=True).per_tag["E2000A01"]
    assert after.max_3d_m == pytest.approx(0.005) and after.n == skipped.n

    never = _track_with_errors(truth, lambda t: np.full_like(t, 0.05))
    report = compare(truth, never, after_convergence_only=True)
    assert report.per_tag["E2000A01"].n == 0 and report.overall.n == 0
    assert np.isnan(report.overall.median_3d_m) and np.isnan(report.per_tag["E2000A01"].median_axis_m).all()


def test_empty_track():
    truth = make_truth()
    track = Track(np.zeros(0), np.zeros(0, dtype=str), np.zeros((0, 3)), np.zeros((0, 3)))
    report = compare(truth, track)
    assert report.per_tag == {} and report.overall.n == 0
    assert np.isnan(report.overall.convergence_time_s)
    assert report.missing_tags == ["E2000A01"]


def test_nees_is_about_three_for_consistent_gaussian_errors():
    truth = make_truth()
    sigma_m = np.array([0.01, 0.02, 0.005])
    rng = np.random.default_rng(7)
    track = track_from(truth, every=1)
    track.position += rng.normal(size=track.position.shape) * sigma_m
    track.sigma = np.tile(sigma_m, (len(track), 1))
    assert nees(truth, track)["E2000A01"] == pytest.approx(3.0, abs=0.3)
    # Over-confident by a factor 2 in sigma: NEES grows by 4.
    track.sigma = track.sigma / 2
    assert nees(truth, track)["E2000A01"] == pytest.approx(12.0, abs=1.2)


def test_nees_of_a_planar_track_counts_two_axes():
    truth = make_truth()
    sigma_m = np.array([0.01, 0.02, 0.0])  # sz = 0: z is not estimated
    rng = np.random.default_rng(8)
    track = track_from(truth, every=1)
    track.position += rng.normal(size=track.position.shape) * sigma_m
    track.sigma = np.tile(sigma_m, (len(track), 1))
    assert nees(truth, track)["E2000A01"] == pytest.approx(2.0, abs=0.25)


def test_nees_needs_sigma():
    truth = make_truth()
    with pytest.raises(ValueError, match="sigma"):
        nees(truth, track_from(truth))


def _yaw_quaternions(yaw: np.ndarray) -> np.ndarray:
    """Unit quaternions (qw, qx, qy, qz) of rotations by ``yaw`` (rad) about +z."""
    return np.column_stack([np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)])


def _spinning(n=201, rate=0.8):
    time = np.linspace(0.0, 2.0, n)
    position = np.column_stack([time, np.zeros(n), np.ones(n)])
    truth = Truth(time, np.full(n, "drone"), position, np.tile([1.0, 0.0, 0.0], (n, 1)), _yaw_quaternions(rate * time))
    return truth, time, position


def test_orientation_error_is_the_relative_rotation_angle():
    truth, time, position = _spinning()
    query = time[::7] + 0.003  # between truth rows: exercises the interpolation
    offset = np.radians(10.0)
    estimated = _yaw_quaternions(0.8 * query + offset)
    estimated[::2] *= -1.0  # q and -q are one rotation
    track = Track(query, np.full(len(query), "drone"), np.column_stack([query, np.zeros(len(query)), np.ones(len(query))]),
                  np.tile([1.0, 0.0, 0.0], (len(query), 1)), orientation=estimated)
    report = compare(truth, track)
    assert report.overall.n_orientation == len(query)
    assert report.overall.mean_orientation_deg == pytest.approx(10.0, abs=1e-3)
    assert report.overall.mean_yaw_deg == pytest.approx(10.0, abs=1e-3)
    assert np.all(np.abs(report.overall.yaw_errors_rad - offset) < 1e-5)


def test_tilt_shows_in_orientation_but_not_in_yaw():
    truth, time, position = _spinning()
    tilt = np.radians(5.0)
    # A tilt about body x after the true yaw: q_est = q_true * q_x(tilt).
    q = truth.orientation
    qx = np.array([np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0])
    w1, x1, y1, z1 = q.T
    w2, x2, y2, z2 = qx
    estimated = np.column_stack([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])
    track = Track(time, truth.epc, position, truth.velocity, orientation=estimated)
    report = compare(truth, track)
    assert report.overall.mean_orientation_deg == pytest.approx(5.0, abs=1e-3)
    assert report.overall.mean_yaw_deg < 0.5


def test_no_orientation_gives_nan_orientation_statistics():
    truth, time, position = _spinning()
    track = Track(time, truth.epc, position, truth.velocity)
    report = compare(truth, track)
    assert report.overall.n_orientation == 0
    assert np.isnan(report.overall.mean_orientation_deg)
    assert np.isnan(report.overall.mean_yaw_deg)
