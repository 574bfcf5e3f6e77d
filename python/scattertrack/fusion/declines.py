"""Why the Marvel estimator declines a feature row, a measurement or an IMU sample.

The keys are the counters in ``MarvelEstimator.declined`` and
``MarvelEstimator.imu_declined``; the values the text of ``Track.skipped``
(:func:`scattertrack.fusion.run.finish_run` merges them).
"""

from __future__ import annotations

DECLINE_REASONS = {
    "non_finite": "feature row with a non-finite time, range or angle (declined)",
    "before_imu": "feature row before the first IMU sample (declined)",
    "not_after_previous": "feature row not after the previous epoch (declined)",
    "too_close": "feature row within min_epoch_interval_s of the previous epoch (declined)",
    "before_latest_imu": "feature row older than an IMU sample already integrated (declined)",
    "range_gate": "range outside the innovation gate (declined)",
    "direction_gate": "direction outside the innovation gate (declined)",
    "yaw_gate": "yaw outside the innovation gate (declined)",
    "solver_failure": "feature row on which the smoother's linear system failed (declined; smoother restarted)",
    "diverged": "feature row whose solve left the physical bounds, max_speed_m_s, max_controller_range_m or max_position_m (refused; smoother restarted from the features)",
    "persistently_gated": "feature row after persistent gating (divergence_gated_fraction of divergence_window_epochs; declined; smoother restarted from the features)",
}
"""Reasons a feature row (or one of its measurements) is declined."""

IMU_DECLINE_REASONS = {
    "non_finite": "IMU sample with a non-finite time, force or rate (ignored)",
    "not_after_previous": "IMU sample not after the previous one (ignored)",
}
"""IMU samples the estimator ignores."""

__all__ = ["DECLINE_REASONS", "IMU_DECLINE_REASONS"]
