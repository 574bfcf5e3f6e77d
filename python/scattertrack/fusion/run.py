"""The run helper behind both Marvel entry points: feature files and LoRa recordings.

:func:`run_marvel` (``features.csv`` + ``imu.csv``; the same run as
:class:`scattertrack.track.marvel.MarvelTracker`'s loop over ``step``) and
:func:`scattertrack.track.marvel.run_sigmf` (a recording sensed epoch by
epoch) differ only in where each epoch's feature row comes from. Everything
around it is here, once: the estimator from its parameters
(:func:`new_estimator`), the IMU fed in time order up to each epoch
(:class:`ImuFeed`), the loop over the epochs with its progress bar
(:func:`drive`), and the end of the run (:func:`finish_run`): the revised
track, the declined rows by reason, the refusal of implausible results, the
counters, and the typed latency record (:class:`~scattertrack.fusion.latency.Latency`).
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.fusion.divergence import is_plausible_controller
from scattertrack.fusion.declines import DECLINE_REASONS, IMU_DECLINE_REASONS
from scattertrack.fusion.estimator import MarvelEstimator
from scattertrack.fusion.params import MarvelParams
from scattertrack.io.types import Features, Imu, Scene, SkipReport, Track

EPC = "drone"
"""The track's ``epc`` column: the pipeline tracks one body, the drone."""

OUTSIDE_REGION = "fused estimate outside the scene's region (refused, not output)"
"""``Track.skipped`` reason of a row whose estimate left the scene's ``[region]``."""
IMPLAUSIBLE_CONTROLLER = "controller estimate implausible (refused, not reported)"
"""``Track.skipped`` reason of a final controller estimate that is not finite or out of reach."""


class ImuFeed:
    """An :class:`Imu`'s samples given to an estimator in time order, each once."""

    def __init__(self, imu: Imu):
        self.time_s = np.asarray(imu.time_s, dtype=float)
        self.accel = np.asarray(imu.accel, dtype=float)
        self.gyro = np.asarray(imu.gyro, dtype=float)
        self.baro = np.asarray(imu.baro_z, dtype=float) if imu.baro_z is not None else np.full(len(self.time_s), np.nan)
        self.next = 0

    def until(self, estimator, time_s: float) -> None:
        """Every sample at or before ``time_s`` (s) not given yet (``side="right"``:
        a sample at the epoch's own time is part of "at or before")."""
        for i in self.take_until(time_s):
            estimator.add_imu(self.time_s[i], self.accel[i], self.gyro[i], self.baro[i])

    def take_until(self, time_s: float) -> range:
        """The indices of the samples at or before ``time_s`` (s) not given yet, now counted as given."""
        end = int(np.searchsorted(self.time_s, time_s, side="right"))
        taken = range(self.next, end)
        self.next = max(self.next, end)
        return taken


def run_marvel(imu: Imu, features: Features, scene: Scene | None = None, *, progress: bool = False, **params) -> Track:
    """Backscatter-inertial fusion of a flight: one track row per accepted feature row.

    A loop over the causal steps: the IMU samples at or before each feature
    row's time go in first, then the row, so every row's estimate uses only
    data up to its time. ``params`` are :class:`MarvelParams` fields (SI
    units). ``scene``: its ``region`` refuses estimates outside it (counted
    in ``skipped``); the controller's position is estimated, not read.

    The track carries orientation (world_T_body ``qw, qx, qy, qz``) and
    1-sigma position (nan with ``compute_sigma=False``); ``skipped`` the
    inputs' own skip reports plus the rows and measurements the estimator
    declined or refused; ``stats["drone"]`` the counters (:func:`finish_run`);
    ``revised`` the fixed-lag smoothed track and ``smoothed["drone"]`` its positions.
    """
    estimator = new_estimator(params)
    feed = ImuFeed(imu)
    order = np.argsort(features.time_s, kind="stable")

    def rows_in_time_order():
        for row in order:
            feed.until(estimator, float(features.time_s[row]))
            yield estimator.add_features(
                features.time_s[row],
                features.range_m[row],
                features.azimuth_rad[row],
                features.elevation_rad[row],
                features.yaw_rad[row],
                features.range_sigma_m[row],
                features.angle_sigma_rad[row],
                features.yaw_sigma_rad[row],
            )

    estimates = drive(rows_in_time_order(), progress=progress, total=len(order), desc="marvel")
    rows = [estimate for estimate in estimates if estimate is not None]
    return finish_run(estimator, rows, scene, input_skips=(features.skipped, imu.skipped))


def new_estimator(params: dict) -> MarvelEstimator:
    """A :class:`MarvelEstimator` with the :class:`MarvelParams` fields ``params`` (SI units)."""
    return MarvelEstimator(MarvelParams.from_kwargs(**params))


def drive(epochs, *, progress: bool = False, total: int | None = None, desc: str = "marvel") -> list:
    """Runs a fusion loop: every item of ``epochs``, an iterable whose each
    step feeds the estimator one epoch (its IMU samples, then its row) and
    yields what that epoch gave, collected in order, with a progress bar of
    ``total`` epochs (None: unknown) when ``progress``. Both entry points'
    loops: :func:`run_marvel` (rows of a features file) and
    :func:`scattertrack.track.marvel.run_sigmf` (epochs sensed from a recording)."""
    bar = _progress_bar(progress, total, desc)
    collected = []
    for item in epochs:
        collected.append(item)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return collected


def _progress_bar(enabled: bool, total: int | None, desc: str):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="epoch", desc=desc, leave=False)


REGION_MARGIN_M = 1.0
"""Metres beyond the scene's region (plus 3 reported sigmas) a row may lie
before it is refused: the region bounds where the drone can be, an estimate
near its edge is that plus its error."""


def inside_region(position: np.ndarray, scene: Scene | None, sigma: np.ndarray | None = None) -> np.ndarray:
    """Which rows of ``position`` (n, 3) m are finite and within the scene's
    region widened by :data:`REGION_MARGIN_M` plus 3 ``sigma`` (n, 3) m per
    axis (non-finite sigmas count as 0); all finite rows without a region."""
    position = np.asarray(position, dtype=float).reshape(-1, 3)
    finite = np.all(np.isfinite(position), axis=1)
    region = getattr(scene, "region", None) if scene is not None else None
    if region is None:
        return finite
    margin = np.full(position.shape, REGION_MARGIN_M)
    if sigma is not None:
        margin = margin + 3.0 * np.nan_to_num(np.asarray(sigma, dtype=float).reshape(-1, 3), nan=0.0, posinf=0.0)
    low, high = np.asarray(region.min, dtype=float), np.asarray(region.max, dtype=float)
    return finite & np.all((position >= low - margin) & (position <= high + margin), axis=1)


def finish_run(
    estimator: MarvelEstimator,
    rows: list,
    scene: Scene | None = None,
    *,
    input_skips: tuple[SkipReport, ...] = (),
    extra_declines: tuple[tuple[dict, dict], ...] = (),
    stats: dict | None = None,
) -> Track:
    """The end of a fusion run: the :class:`Track` of the accepted ``rows`` (Estimates).

    Calls :meth:`MarvelEstimator.finish`; merges the inputs' skip reports,
    then ``extra_declines`` (``(counts, reasons)`` pairs: counter key -> n,
    key -> text) and the estimator's declines into ``skipped``. Refuses
    implausible results instead of printing them: rows outside the scene's
    region (:data:`OUTSIDE_REGION`) and a final controller estimate that is
    not finite or farther than ``max_controller_range_m`` from the last row
    (:data:`IMPLAUSIBLE_CONTROLLER`: ``stats["controller"]`` is then None and
    ``controller_refused`` says why). ``stats["drone"]``: the estimator's
    counters, the rest test, the IMU's white-noise densities (``imu_noise``:
    measured, used and stated pairs, accelerometer then gyroscope:
    :mod:`scattertrack.fusion.imu_noise`), the features' white share
    (``feature_white_fraction``: the measured correlated shares of the
    variance with their epoch count, the range's and direction's ``f`` in use,
    the stated one: :mod:`scattertrack.fusion.feature_correlation`), divergences (and how many recovered), the typed
    latency records ``latency`` (wall) and ``cpu_latency`` (thread CPU, both
    :class:`~scattertrack.fusion.latency.Latency`), their quantiles in ns
    (``time_ns_p50``, ``time_ns_p99``, ``time_ns_max``, ``cpu_time_ns_*``),
    the work between epochs' record ``between_epochs_latency`` (wall; None
    without any: :mod:`scattertrack.fusion.between_epochs`) and its
    ``between_epochs_time_ns_max``, then the caller's ``stats``.
    """
    estimator.finish()
    skipped = SkipReport()
    for report in input_skips:
        for reason, n in report.counts.items():
            skipped.counts[reason] = skipped.counts.get(reason, 0) + n
            skipped.examples.setdefault(reason, []).extend(report.examples.get(reason, [])[:5])
    for counts, reasons in (*extra_declines, (estimator.declined, DECLINE_REASONS), (estimator.imu_declined, IMU_DECLINE_REASONS)):
        for key, count in counts.items():
            if count:
                skipped.add(reasons[key], n=count)

    positions = np.array([e.position for e in rows], dtype=float).reshape(len(rows), 3)
    sigmas = np.array([e.sigma for e in rows], dtype=float).reshape(len(rows), 3)
    inside = inside_region(positions, scene, sigmas)
    if not np.all(inside):
        skipped.add(OUTSIDE_REGION, n=int(np.count_nonzero(~inside)))
        rows = [e for e, keep in zip(rows, inside) if keep]

    controller = estimator.controller
    controller_refused = ""
    if controller is not None:
        last = rows[-1].position if rows else np.zeros(3)
        if not is_plausible_controller(controller, last, estimator.params.max_controller_range_m):
            controller_refused = (
                f"controller at {np.linalg.norm(controller - last):.3g} m from the drone "
                f"(bound max_controller_range_m = {estimator.params.max_controller_range_m:g} m)"
            )
            skipped.add(IMPLAUSIBLE_CONTROLLER)
            controller = None

    wall = estimator.latency()
    cpu = estimator.cpu_latency()
    between = estimator.between_epochs_latency()
    track = track_from_estimates(rows, skipped)
    attach_revised(track, estimator)
    rest_test = estimator.rest_test
    track.stats = {
        EPC: {
            "epochs": estimator.epochs,
            "imu_samples": estimator.imu_samples,
            "declined": dict(estimator.declined),
            "imu_declined": dict(estimator.imu_declined),
            "controller": controller,
            "controller_refused": controller_refused,
            "controller_sigma": rows[-1].controller_sigma if rows and controller is not None else None,
            "range_bias_m": estimator.range_bias,
            "revised_fallbacks": estimator.revised_fallbacks,
            "heading_hold_end_s": estimator.heading_hold_end_s,
            "rest": {
                "state": estimator.rest_state,
                "failed_check": rest_test.reason if rest_test is not None else "pending",
                "ground_end": estimator.ground_end_reason,
                "ground_factors_dropped": estimator.ground_factors_dropped,
            },
            "imu_noise": {
                "measured": estimator.imu_noise_measured,
                "used": estimator.imu_noise_used,
                "stated": (estimator.params.accel_noise_density, estimator.params.gyro_noise_density),
            },
            "feature_white_fraction": {
                "measured_shares": estimator.multipath_measured,
                "used": (float(estimator._white_fraction[0]), float(estimator._white_fraction[1])),
                "stated": estimator.params.multipath_white_fraction,
            },
            "divergences": estimator.divergences,
            "divergences_recovered": estimator.divergences_recovered,
            "divergence_reasons": list(estimator.divergence_reasons),
            "restarts": estimator.restarts,
            "refused_outside_region": int(np.count_nonzero(~inside)),
            "latency": wall,
            "cpu_latency": cpu,
            "time_ns_p50": wall.p50_ns if wall else math.nan,
            "time_ns_p99": wall.p99_ns if wall else math.nan,
            "time_ns_max": wall.max_ns if wall else math.nan,
            "cpu_time_ns_p50": cpu.p50_ns if cpu else math.nan,
            "cpu_time_ns_p99": cpu.p99_ns if cpu else math.nan,
            "cpu_time_ns_max": cpu.max_ns if cpu else math.nan,
            "between_epochs_latency": between,
            "between_epochs_time_ns_max": between.max_ns if between else math.nan,
            "epoch_times_ns": np.asarray(estimator.wall_times_s, dtype=float) * 1e9,
            "imu_time_ns_per_sample": estimator.imu_wall_time_s * 1e9 / max(estimator.imu_samples, 1),
            **(stats or {}),
        }
    }
    track.latency_quantiles_ns = wall.quantiles() if wall else {}
    track.latency = wall.as_tuple() if wall else None
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
