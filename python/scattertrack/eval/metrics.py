"""Accuracy metrics of a track against ground truth (docs/formats.md sections 3-4).

Everything here works on the in-memory :class:`~scattertrack.io.types.Truth`
and :class:`~scattertrack.io.types.Track`; nothing does I/O except
:func:`compare_files`. Units are SI: metres, seconds, m/s.

Matching rule, per tag (epc): the truth rows of that tag are interpolated
linearly at the track times. Truth is sampled at 100 Hz or more
(docs/formats.md 3), so linear interpolation is accurate to well under a
millimetre for hand- or arm-speed motion. Track rows outside the time span of
that tag's truth are not extrapolated: they are excluded and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scattertrack.io.cells import TextTable
from scattertrack.io.types import SkipReport, Track, Truth

OUTSIDE_TRUTH_SPAN = "outside the truth time span"
"""Reason: a track row earlier than the tag's first truth row or later than its last."""
NO_TRUTH_FOR_TAG = "no truth for the tag"
"""Reason: a track row of a tag that has no truth rows at all."""
NON_FINITE_POSITION = "non-finite estimated position"
"""Reason: a track row whose x, y or z is nan or infinite (only possible in memory)."""


@dataclass
class TagMetrics:
    """Error statistics of one tag, or of all tags pooled (``Report.overall``).

    Statistics are over the rows evaluated (``n``): rows inside the truth
    time span, after the ``skip_first_s`` / ``after_convergence_only``
    filters. A statistic over no rows is nan.
    """

    n: int
    """Rows evaluated for the position statistics."""
    median_3d_m: float
    """Median 3D position error, metres."""
    p90_3d_m: float
    """90th percentile 3D position error, metres."""
    mean_3d_m: float
    """Mean 3D position error, metres."""
    rmse_3d_m: float
    """Root mean square 3D position error, metres."""
    max_3d_m: float
    """Largest 3D position error, metres."""
    median_axis_m: np.ndarray
    """Median absolute error per axis (x, y, z), metres, shape (3,)."""
    p90_axis_m: np.ndarray
    """90th percentile absolute error per axis (x, y, z), metres, shape (3,)."""
    median_velocity_m_s: float
    """Median velocity error |v_est - v_true|, m/s, over rows with a finite estimated velocity."""
    p90_velocity_m_s: float
    """90th percentile velocity error, m/s."""
    n_velocity: int
    """Rows that had a finite estimated velocity (the velocity statistics use only these)."""
    convergence_time_s: float
    """Seconds from the start of motion to convergence (see :func:`compare`); nan if never.
    Overall: the largest over the tags, nan if any tag never converged."""
    first_estimate_s: float
    """Time of the tag's first track row minus the tag's first truth time, seconds
    (negative if the tracker started before the truth). Overall: the largest over the tags."""
    converged_fraction: float
    """Fraction of the rows matched to truth that lie at or after the convergence instant
    (0 if never converged). Overall: pooled over rows of all tags."""
    n_rows: int
    """Track rows of this tag (overall: of all evaluated tags), before any exclusion."""
    n_excluded: int
    """Track rows of this tag not matched to truth: outside the tag's truth time span
    (or, in memory only, with a non-finite position); reasons in ``Report.excluded``."""
    motion_start_s: float
    """Absolute time at which the truth first moves faster than ``motion_speed_m_s``,
    seconds (the tag's first truth time if it never does). nan for ``overall``."""
    converged_at_s: float
    """Absolute track time of convergence, seconds; nan if never (and for ``overall``)."""
    errors_3d_m: np.ndarray = field(repr=False)
    """3D position error of each evaluated row, metres, shape (n,)."""
    errors_axis_m: np.ndarray = field(repr=False)
    """Absolute error per axis of each evaluated row, metres, shape (n, 3)."""
    velocity_errors_m_s: np.ndarray = field(repr=False)
    """Velocity error of each evaluated row, m/s, shape (n,); nan where the track has no
    velocity (kept aligned with ``times_s``; use ``np.nanmedian`` or the statistics above)."""
    times_s: np.ndarray = field(repr=False)
    """Track time of each evaluated row, seconds, shape (n,)."""
    mean_orientation_deg: float = float("nan")
    """Mean orientation error, degrees: the angle of the rotation between the estimated and
    the true orientation (geodesic distance on SO(3)), over rows where both exist."""
    median_orientation_deg: float = float("nan")
    """Median orientation error, degrees."""
    mean_yaw_deg: float = float("nan")
    """Mean absolute heading (yaw about +z) error, degrees, wrapped to [0, 180]."""
    n_orientation: int = 0
    """Rows with both an estimated and a true orientation."""
    orientation_errors_rad: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    """Orientation error of each evaluated row, radians, shape (n,); nan where either side has none."""
    yaw_errors_rad: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    """Signed heading error of each evaluated row, radians in (-pi, pi]; nan where either side has none."""


@dataclass
class Report:
    """Result of :func:`compare`: per-tag metrics, pooled metrics and what was left out."""

    per_tag: dict[str, TagMetrics]
    """Metrics of each tag that has both track and truth rows, in order of first track row."""
    overall: TagMetrics
    """Errors pooled over all tags (see :class:`TagMetrics` for the aggregated fields)."""
    excluded: SkipReport = field(default_factory=SkipReport)
    """Track rows not evaluated, by reason (outside truth span, no truth for the tag...)."""
    track_skipped: SkipReport = field(default_factory=SkipReport)
    """Reads the tracker itself declined (``Track.skipped``), carried for the report."""
    missing_tags: list[str] = field(default_factory=list)
    """Tags that have truth but no track row at all."""
    convergence_threshold_m: float = 0.02
    """3D error below which a tag counts as converged, metres."""
    hold_s: float = 1.0
    """How long the error must stay below the threshold to count as converged, seconds."""
    motion_speed_m_s: float = 0.01
    """Truth speed above which the tag counts as moving, m/s."""
    after_convergence_only: bool = False
    """Whether the statistics use only rows at or after convergence."""
    skip_first_s: float = 0.0
    """Rows earlier than this after each tag's first estimate were left out, seconds."""


def compare(
    truth: Truth,
    track: Track,
    *,
    convergence_threshold_m: float = 0.02,
    hold_s: float = 1.0,
    motion_speed_m_s: float = 0.01,
    after_convergence_only: bool = False,
    skip_first_s: float = 0.0,
) -> Report:
    """Compare a track with ground truth, tag by tag, and pool the errors.

    For each tag in the track: truth position and velocity are interpolated
    linearly at the track times; the 3D error is ``|p_est - p_true|`` (metres),
    the per-axis errors ``|p_est - p_true|`` per coordinate (metres), the
    velocity error ``|v_est - v_true|`` (m/s). Truth velocity comes from the
    ``vx, vy, vz`` columns where they are finite, otherwise from central
    finite differences of the truth positions. Rows with a nan estimated
    velocity (a method without velocity) are left out of the velocity
    statistics only.

    Convergence (per tag): motion starts at the first truth time where the
    truth speed exceeds ``motion_speed_m_s`` (m/s), or at the first truth time
    if the tag never moves that fast. The tag converges at the first track
    time ``t_c`` after which the 3D error stays below
    ``convergence_threshold_m`` (metres) for the rest of the track, provided
    that lasts at least ``hold_s`` seconds (last track time - ``t_c`` >=
    ``hold_s``), so a track that only dips below the threshold at its very end
    does not count. ``convergence_time_s = max(0, t_c - motion start)``: a
    tracker that locks on before the tag moves has converged in 0 s. Nan if
    it never converges.

    Args:
        truth: ground truth of one or more tags.
        track: tracker output of one or more tags.
        convergence_threshold_m: 3D error that counts as converged, metres.
        hold_s: minimal time the error must stay below the threshold, seconds.
        motion_speed_m_s: truth speed that counts as moving, m/s.
        after_convergence_only: use only rows at or after each tag's
            convergence instant in the statistics (none if it never converged).
        skip_first_s: leave out rows earlier than this many seconds after the
            tag's first track row (some papers report errors after
            initialisation), seconds.

    Returns:
        A :class:`Report`. Convergence and ``converged_fraction`` are computed
        on all rows inside the truth span, whatever the two filters.
    """
    excluded = SkipReport()
    per_tag: dict[str, TagMetrics] = {}
    truth_groups = dict(_group_rows(truth.epc))
    track_groups = _group_rows(track.epc)

    for epc, track_rows in track_groups:
        if epc not in truth_groups:
            excluded.add(NO_TRUTH_FOR_TAG, n=len(track_rows))
            continue
        truth_time, truth_position, truth_velocity = _truth_of_tag(truth, truth_groups[epc])
        # The tracker writes rows in time order per tag (docs/formats.md 4), but an
        # in-memory track may not be; the convergence rule needs time order.
        track_rows = track_rows[np.argsort(track.time_s[track_rows], kind="stable")]
        time = track.time_s[track_rows]
        position = track.position[track_rows]
        velocity = track.velocity[track_rows]

        finite = np.all(np.isfinite(position), axis=1)
        inside = (time >= truth_time[0]) & (time <= truth_time[-1])
        n_outside = int(np.count_nonzero(finite & ~inside))
        n_non_finite = int(np.count_nonzero(~finite))
        if n_outside:
            excluded.add(OUTSIDE_TRUTH_SPAN, n=n_outside)
        if n_non_finite:
            excluded.add(NON_FINITE_POSITION, n=n_non_finite)
        used = finite & inside

        time_used = time[used]
        true_position = _interpolate(time_used, truth_time, truth_position)
        true_velocity = _interpolate(time_used, truth_time, truth_velocity)
        difference = position[used] - true_position
        errors_3d = np.linalg.norm(difference, axis=1)
        errors_axis = np.abs(difference)
        # nan where the method has no velocity; kept aligned with the times.
        velocity_errors = np.linalg.norm(velocity[used] - true_velocity, axis=1)
        orientation_errors, yaw_errors = _orientation_errors(truth, truth_groups[epc], track, track_rows[used], time_used)

        motion_start = _motion_start(truth_time, truth_velocity, motion_speed_m_s)
        converged_at = _convergence_instant(time_used, errors_3d, convergence_threshold_m, hold_s)
        convergence_time = max(0.0, converged_at - motion_start) if np.isfinite(converged_at) else np.nan
        n_after_convergence = int(np.count_nonzero(time_used >= converged_at))

        keep = time_used >= time[0] + skip_first_s
        if after_convergence_only:
            keep &= time_used >= converged_at  # all False when converged_at is nan

        per_tag[epc] = _summarise(
            times=time_used[keep],
            errors_3d=errors_3d[keep],
            errors_axis=errors_axis[keep],
            velocity_errors=velocity_errors[keep],
            orientation_errors=orientation_errors[keep],
            yaw_errors=yaw_errors[keep],
            convergence_time_s=convergence_time,
            first_estimate_s=float(time[0] - truth_time[0]),
            converged_fraction=n_after_convergence / len(time_used) if len(time_used) else np.nan,
            n_rows=len(track_rows),
            n_excluded=n_outside + n_non_finite,
            motion_start_s=motion_start,
            converged_at_s=converged_at,
        )

    tracked = {epc for epc, _ in track_groups}
    missing = [epc for epc in truth_groups if epc not in tracked]
    return Report(
        per_tag=per_tag,
        overall=_pool(per_tag),
        excluded=excluded,
        track_skipped=track.skipped,
        missing_tags=missing,
        convergence_threshold_m=convergence_threshold_m,
        hold_s=hold_s,
        motion_speed_m_s=motion_speed_m_s,
        after_convergence_only=after_convergence_only,
        skip_first_s=skip_first_s,
    )


def nees(truth: Truth, track: Track) -> dict[str, float]:
    """Mean normalised estimation error squared (NEES) of each tag, dimensionless.

    Per row: ``sum_i ((p_est_i - p_true_i) / sigma_i)^2`` over the axes i,
    using the track's 1-sigma columns ``sx, sy, sz`` (metres). This is the
    **diagonal-only** NEES: the track format carries no covariance between
    axes, so correlated errors are treated as independent. Axes whose sigma
    is not a positive finite number (e.g. ``sz = 0`` for a planar track) are
    left out of that row's sum, so for a consistent filter the mean is close
    to the number of axes with a sigma (3 for a 3D track, 2 for a planar
    one); larger means over-confident, smaller under-confident. Rows outside
    the truth span are excluded as in :func:`compare`.

    Raises:
        ValueError: the track has no sigma columns.
    """
    if track.sigma is None:
        raise ValueError("nees: the track has no sigma (sx, sy, sz) columns")
    truth_groups = dict(_group_rows(truth.epc))
    result: dict[str, float] = {}
    for epc, track_rows in _group_rows(track.epc):
        if epc not in truth_groups:
            continue
        truth_time, truth_position, _ = _truth_of_tag(truth, truth_groups[epc])
        time = track.time_s[track_rows]
        position = track.position[track_rows]
        sigma = track.sigma[track_rows]
        inside = (time >= truth_time[0]) & (time <= truth_time[-1]) & np.all(np.isfinite(position), axis=1)
        true_position = _interpolate(time[inside], truth_time, truth_position)
        sigma = sigma[inside]
        has_sigma = np.isfinite(sigma) & (sigma > 0)
        normalised = np.where(has_sigma, (position[inside] - true_position) / np.where(has_sigma, sigma, 1.0), 0.0)
        rows = np.any(has_sigma, axis=1)
        squared = np.sum(normalised**2, axis=1)[rows]
        result[epc] = float(np.mean(squared)) if len(squared) else float("nan")
    return result


def compare_files(truth_path, track_path, **kw) -> Report:
    """:func:`compare` on a ``truth.csv`` and a ``track.csv`` read with :mod:`scattertrack.io`.

    Keyword arguments go to :func:`compare` (thresholds in metres, times in seconds).
    """
    # Imported here so that the metrics work without the file readers loaded.
    from scattertrack.io import read_track, read_truth

    return compare(read_truth(truth_path), read_track(track_path), **kw)


# --- helpers ---------------------------------------------------------------


def _group_rows(epc: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Row indices of each tag, tags in order of first appearance, rows in file order."""
    # Codes in order of first appearance; no fixed-width array (its size would follow the longest epc).
    codes, names = TextTable().encode([str(e) for e in np.asarray(epc, dtype=object).reshape(-1).tolist()])
    if len(codes) == 0:
        return []
    order = np.argsort(codes, kind="stable")  # stable: rows of a tag keep their order
    bounds = np.cumsum(np.bincount(codes, minlength=len(names)))[:-1]
    return list(zip(names, np.split(order, bounds)))


def _truth_of_tag(truth: Truth, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), position (m) and velocity (m/s) of one tag's truth, sorted, one row per time.

    Repeated time stamps keep their first row, because interpolation and
    finite differences need strictly increasing times. Velocity is the
    truth's own where finite, otherwise the central finite difference of
    position (one-sided at the ends).
    """
    rows = rows[np.argsort(truth.time_s[rows], kind="stable")]
    time = np.asarray(truth.time_s[rows], dtype=float)
    _, unique = np.unique(time, return_index=True)
    rows = rows[unique]
    time = time[unique]
    position = np.asarray(truth.position[rows], dtype=float)
    velocity = np.asarray(truth.velocity[rows], dtype=float)
    if len(time) >= 2:
        differenced = np.gradient(position, time, axis=0)
    else:
        differenced = np.full_like(position, np.nan)
    velocity = np.where(np.isfinite(velocity), velocity, differenced)
    return time, position, velocity


def _interpolate(query_time: np.ndarray, time: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of each column of ``values`` (n, k) at ``query_time`` (m,)."""
    return np.column_stack([np.interp(query_time, time, values[:, k]) for k in range(values.shape[1])])


def _orientation_errors(
    truth: Truth, truth_rows: np.ndarray, track: Track, track_rows: np.ndarray, time: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Orientation (geodesic, rad) and signed yaw (rad) errors of the track rows at ``time`` (s).

    Nan where the track or the truth has no orientation. The truth quaternion
    is interpolated component-wise between its two neighbouring rows after
    making them the same hemisphere (``q`` and ``-q`` are one rotation), then
    normalised: at the >= 100 Hz truth rate this is within 1e-4 rad of slerp
    for rotation rates below 1 rad/s per 10 ms.
    """
    n = len(time)
    nan = np.full(n, np.nan)
    if track.orientation is None or truth.orientation is None or n == 0:
        return nan, nan.copy()
    rows = truth_rows[np.argsort(truth.time_s[truth_rows], kind="stable")]
    truth_time = np.asarray(truth.time_s[rows], dtype=float)
    _, unique = np.unique(truth_time, return_index=True)
    truth_time = truth_time[unique]
    truth_q = np.asarray(truth.orientation[rows[unique]], dtype=float)
    # Hemisphere continuity, so that neighbours interpolate along the short arc.
    flips = np.cumsum(np.r_[0, np.einsum("ij,ij->i", truth_q[1:], truth_q[:-1]) < 0]) % 2
    truth_q = np.where(flips[:, None] == 1, -truth_q, truth_q)
    true_q = _interpolate(time, truth_time, truth_q)
    true_q /= np.linalg.norm(true_q, axis=1, keepdims=True)
    estimated = np.asarray(track.orientation[track_rows], dtype=float)
    estimated = estimated / np.linalg.norm(estimated, axis=1, keepdims=True)
    # |<q_est, q_true>| = cos(angle / 2) of the relative rotation.
    dot = np.clip(np.abs(np.einsum("ij,ij->i", estimated, true_q)), 0.0, 1.0)
    angle = 2.0 * np.arccos(dot)
    yaw_error = _yaw(estimated) - _yaw(true_q)
    yaw_error = (yaw_error + np.pi) % (2.0 * np.pi) - np.pi
    return angle, yaw_error


def _yaw(q: np.ndarray) -> np.ndarray:
    """Heading of body x about +z of unit quaternions ``(qw, qx, qy, qz)`` (n, 4), radians."""
    w, x, y, z = q.T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _motion_start(time: np.ndarray, velocity: np.ndarray, speed_m_s: float) -> float:
    """First truth time (s) with speed above ``speed_m_s`` (m/s); the first truth time if none."""
    moving = np.flatnonzero(np.linalg.norm(velocity, axis=1) > speed_m_s)
    return float(time[moving[0]] if len(moving) else time[0])


def _convergence_instant(time: np.ndarray, errors_3d: np.ndarray, threshold_m: float, hold_s: float) -> float:
    """Start (s) of the final run of rows with error below ``threshold_m`` (m), if it lasts ``hold_s`` (s).

    Nan if the last row is above the threshold or the final run is shorter than ``hold_s``.
    """
    if len(time) == 0:
        return float("nan")
    above = np.flatnonzero(~(errors_3d < threshold_m))
    if len(above) and above[-1] == len(time) - 1:
        return float("nan")
    start = above[-1] + 1 if len(above) else 0
    if time[-1] - time[start] < hold_s:
        return float("nan")
    return float(time[start])


def _statistic(values: np.ndarray, q: float) -> float:
    """Quantile ``q`` of the finite values (nan if none), without numpy's empty-slice warning."""
    values = values[np.isfinite(values)]
    return float(np.quantile(values, q)) if len(values) else float("nan")


def _summarise(
    *,
    times: np.ndarray,
    errors_3d: np.ndarray,
    errors_axis: np.ndarray,
    velocity_errors: np.ndarray,
    convergence_time_s: float,
    first_estimate_s: float,
    orientation_errors: np.ndarray | None = None,
    yaw_errors: np.ndarray | None = None,
    converged_fraction: float,
    n_rows: int,
    n_excluded: int,
    motion_start_s: float,
    converged_at_s: float,
) -> TagMetrics:
    """Statistics of the given rows (errors in metres, m/s, radians; times in seconds)."""
    n = len(errors_3d)
    nan = float("nan")
    if orientation_errors is None:
        orientation_errors = np.full(n, nan)
    if yaw_errors is None:
        yaw_errors = np.full(n, nan)
    has_orientation = np.isfinite(orientation_errors)
    return TagMetrics(
        n=n,
        median_3d_m=_statistic(errors_3d, 0.5),
        p90_3d_m=_statistic(errors_3d, 0.9),
        mean_3d_m=float(np.mean(errors_3d)) if n else nan,
        rmse_3d_m=float(np.sqrt(np.mean(errors_3d**2))) if n else nan,
        max_3d_m=float(np.max(errors_3d)) if n else nan,
        median_axis_m=np.array([_statistic(errors_axis[:, k], 0.5) for k in range(3)]),
        p90_axis_m=np.array([_statistic(errors_axis[:, k], 0.9) for k in range(3)]),
        median_velocity_m_s=_statistic(velocity_errors, 0.5),
        p90_velocity_m_s=_statistic(velocity_errors, 0.9),
        n_velocity=int(np.count_nonzero(np.isfinite(velocity_errors))),
        convergence_time_s=float(convergence_time_s),
        first_estimate_s=float(first_estimate_s),
        converged_fraction=float(converged_fraction),
        n_rows=int(n_rows),
        n_excluded=int(n_excluded),
        motion_start_s=float(motion_start_s),
        converged_at_s=float(converged_at_s),
        errors_3d_m=errors_3d,
        errors_axis_m=errors_axis.reshape(n, 3),
        velocity_errors_m_s=velocity_errors,
        times_s=times,
        mean_orientation_deg=float(np.degrees(np.mean(orientation_errors[has_orientation])))
        if np.any(has_orientation)
        else nan,
        median_orientation_deg=float(np.degrees(_statistic(orientation_errors, 0.5))),
        mean_yaw_deg=float(np.degrees(np.mean(np.abs(yaw_errors[np.isfinite(yaw_errors)]))))
        if np.any(np.isfinite(yaw_errors))
        else nan,
        n_orientation=int(np.count_nonzero(has_orientation)),
        orientation_errors_rad=orientation_errors,
        yaw_errors_rad=yaw_errors,
    )


def _pool(per_tag: dict[str, TagMetrics]) -> TagMetrics:
    """Overall metrics: errors pooled over rows; convergence and first estimate worst over tags."""
    tags = list(per_tag.values())
    nan = float("nan")
    if not tags:
        empty = np.zeros(0)
        return _summarise(
            times=empty,
            errors_3d=empty,
            errors_axis=np.zeros((0, 3)),
            velocity_errors=empty,
            convergence_time_s=nan,
            first_estimate_s=nan,
            converged_fraction=nan,
            n_rows=0,
            n_excluded=0,
            motion_start_s=nan,
            converged_at_s=nan,
        )
    convergence = np.array([tag.convergence_time_s for tag in tags])
    # One tag that never converges means the set never converged: nan, not the max of the rest.
    overall_convergence = float(np.max(convergence)) if np.all(np.isfinite(convergence)) else nan
    # Weighted by the rows matched to truth, i.e. pooled over rows.
    matched = np.array([tag.n_rows - tag.n_excluded for tag in tags], dtype=float)
    fractions = np.nan_to_num(np.array([tag.converged_fraction for tag in tags]))
    return _summarise(
        times=np.concatenate([tag.times_s for tag in tags]),
        errors_3d=np.concatenate([tag.errors_3d_m for tag in tags]),
        errors_axis=np.concatenate([tag.errors_axis_m for tag in tags]),
        velocity_errors=np.concatenate([tag.velocity_errors_m_s for tag in tags]),
        orientation_errors=np.concatenate([tag.orientation_errors_rad for tag in tags]),
        yaw_errors=np.concatenate([tag.yaw_errors_rad for tag in tags]),
        convergence_time_s=overall_convergence,
        first_estimate_s=float(np.max([tag.first_estimate_s for tag in tags])),
        converged_fraction=float(np.sum(fractions * matched) / np.sum(matched)) if np.sum(matched) else nan,
        n_rows=sum(tag.n_rows for tag in tags),
        n_excluded=sum(tag.n_excluded for tag in tags),
        motion_start_s=nan,
        converged_at_s=nan,
    )
