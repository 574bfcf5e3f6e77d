"""Batch helper: the causal estimator over whole recordings (imu.csv + features.csv)."""

from __future__ import annotations

import numpy as np

from scattertrack.fusion.estimator import DECLINE_REASONS, IMU_DECLINE_REASONS, MarvelEstimator, MarvelParams
from scattertrack.io.types import Features, Imu, Scene, SkipReport, Track

EPC = "drone"
"""The track's ``epc`` column: the pipeline tracks one body, the drone."""


def run_marvel(imu: Imu, features: Features, scene: Scene | None = None, *, progress: bool = False, **params) -> Track:
    """Backscatter-inertial fusion of a flight: one track row per accepted feature row.

    A loop over the causal steps: the IMU samples at or before each feature
    row's time go in first, then the row, so every row's estimate uses only
    data up to its time. ``params`` are :class:`MarvelParams` fields (SI
    units). ``scene`` is accepted for the common tracker signature; the
    estimator needs nothing from it (the controller's position is estimated).

    The track carries orientation (world_T_body ``qw, qx, qy, qz``) and
    1-sigma position (nan with ``compute_sigma=False``); ``skipped`` holds
    the inputs' own skip reports plus the rows and measurements the
    estimator declined; ``stats["drone"]`` the counters, the final controller
    estimate (m) and the per-row wall time quantiles (ns), also in
    ``latency_quantiles_ns``; ``revised`` the fixed-lag smoothed track (each
    state as last revised, about ``smoother_lag_s`` later; see
    :attr:`MarvelEstimator.revised`) and ``smoothed["drone"]`` its positions.
    """
    del scene  # nothing in the scene is needed: the controller is a state
    estimator = MarvelEstimator(MarvelParams.from_kwargs(**params))
    imu_time = np.asarray(imu.time_s, dtype=float)
    accel = np.asarray(imu.accel, dtype=float)
    gyro = np.asarray(imu.gyro, dtype=float)
    baro = np.asarray(imu.baro_z, dtype=float) if imu.baro_z is not None else np.full(len(imu_time), np.nan)
    order = np.argsort(features.time_s, kind="stable")
    # IMU samples up to and including each feature time (side="right": a
    # sample at the epoch's own time is part of "at or before").
    ends = np.searchsorted(imu_time, np.asarray(features.time_s, dtype=float)[order], side="right")

    rows: list = []
    next_imu = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(order), unit="epoch", desc="marvel", leave=False)
    for row, end in zip(order, ends):
        for i in range(next_imu, end):
            estimator.add_imu(imu_time[i], accel[i], gyro[i], baro[i])
        next_imu = max(next_imu, end)
        estimate = estimator.add_features(
            features.time_s[row],
            features.range_m[row],
            features.azimuth_rad[row],
            features.elevation_rad[row],
            features.yaw_rad[row],
            features.range_sigma_m[row],
            features.angle_sigma_rad[row],
            features.yaw_sigma_rad[row],
        )
        if estimate is not None:
            rows.append(estimate)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    estimator.finish()

    skipped = SkipReport()
    for report in (features.skipped, imu.skipped):
        for reason, n in report.counts.items():
            skipped.counts[reason] = skipped.counts.get(reason, 0) + n
            skipped.examples.setdefault(reason, []).extend(report.examples.get(reason, [])[:5])
    for counts, reasons in ((estimator.declined, DECLINE_REASONS), (estimator.imu_declined, IMU_DECLINE_REASONS)):
        for key, n in counts.items():
            if n:
                skipped.add(reasons[key], n=n)

    latency = estimator.latency_ns()
    track = track_from_estimates(rows, skipped)
    attach_revised(track, estimator)
    track.stats = {
        EPC: {
            "epochs": estimator.epochs,
            "imu_samples": estimator.imu_samples,
            "declined": dict(estimator.declined),
            "imu_declined": dict(estimator.imu_declined),
            "controller": estimator.controller,
            "controller_sigma": rows[-1].controller_sigma if rows else None,
            "range_bias_m": estimator.range_bias,
            "revised_fallbacks": estimator.revised_fallbacks,
            "heading_hold_end_s": estimator.heading_hold_end_s,
            "time_ns_p50": latency.get("p50", float("nan")),
            "time_ns_p99": latency.get("p99", float("nan")),
            "imu_time_ns_per_sample": estimator.imu_wall_time_s * 1e9 / max(estimator.imu_samples, 1),
        }
    }
    track.latency_quantiles_ns = {k: latency[k] for k in ("p50", "p99")} if latency else {}
    track.latency = (n, latency["mean"], latency["max"]) if latency else None
    return track


def attach_revised(track: Track, estimator: MarvelEstimator) -> None:
    """Puts the estimator's revised rows (call :meth:`MarvelEstimator.finish`
    first) on ``track``: the whole track in ``revised`` (nothing skipped of
    its own: its rows are the accepted epochs) and its positions in
    ``smoothed["drone"]``."""
    revised = track_from_estimates(estimator.revised, SkipReport())
    track.revised = revised
    track.smoothed = {EPC: (revised.time_s.copy(), revised.position.copy())}


def track_from_estimates(rows: list, skipped: SkipReport) -> Track:
    """The drone's track (epc ``drone``) from the estimator's :class:`Estimate` rows, in order:
    position (m), velocity (m/s), 1-sigma position (m), orientation (qw, qx, qy, qz)."""
    n = len(rows)
    return Track(
        time_s=np.array([e.time_s for e in rows], dtype=float),
        epc=np.full(n, EPC),
        position=np.array([e.position for e in rows], dtype=float).reshape(n, 3),
        velocity=np.array([e.velocity for e in rows], dtype=float).reshape(n, 3),
        sigma=np.array([e.sigma for e in rows], dtype=float).reshape(n, 3),
        orientation=np.array([e.orientation for e in rows], dtype=float).reshape(n, 4),
        skipped=skipped,
    )
