"""Causal backscatter-inertial estimator on a GTSAM fixed-lag smoother (paper sec. IV).

One state per sensing epoch k: ``X(k)`` pose (world_T_body), ``V(k)``
velocity (m/s, world), ``B(k)`` IMU biases, ``O(k)`` the barometer's offset
(m, when a barometer is used), ``M(k)`` the features' multipath errors
(range m, direction's two tangent components rad; ``multipath = "states"``),
and one ``L(0)``: the controller's position
``rho`` (m, world). Between epochs the IMU samples are preintegrated into one
``CombinedImuFactor`` (eq. 13, with the bias random walk inside); each
feature row adds range, direction and yaw factors (eq. 12, see
:mod:`scattertrack.fusion.factors`). An ``IncrementalFixedLagSmoother``
(iSAM2 that marginalises states older than the lag) solves eq. 10; the
controller's time stamp is renewed every epoch so it is never marginalised.

Causality: :meth:`MarvelEstimator.add_features` returns the smoother's
estimate of the newest state right after the update with that row, using
only IMU samples and rows given before (at or before its time).

Revised (fixed-lag smoothed) estimates: every state stays in the window for
``smoother_lag_s`` to ``smoother_lag_s + marginalize_every_s`` (states leave
in groups, once per ``marginalize_every_s``) and is revised by each later
row until it leaves. :attr:`MarvelEstimator.revised` collects each state as
last revised, just before the update that marginalises it (and the rest at
:meth:`finish`): a track delayed by the lag that uses the rows of at least
the lag after each state. A state whose smoother failed before it left
keeps its causal estimate (counted in ``revised_fallbacks``).

This class is the orchestration: :meth:`MarvelEstimator.add_features` is a
sequence of named steps, each in the mixin of its concept: the IMU stream
(:mod:`.imu`), the first state and the controller (:mod:`.take_off`), the
ground phase (:mod:`.ground`), multipath (:mod:`.multipath`), gating
(:mod:`.gating`), the measurement factors (:mod:`.measurements`), the
barometer (:mod:`.barometer`), the window (:mod:`.window`) and its work
between epochs (:mod:`.between_epochs`), the read-out
(:mod:`.readout`), restarts (:mod:`.restart`) and the revised track
(:mod:`.revised`).
"""

from __future__ import annotations

import math
import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from scattertrack.fusion.barometer import Barometer
from scattertrack.fusion.between_epochs import BetweenEpochs
from scattertrack.fusion.declines import DECLINE_REASONS
from scattertrack.fusion.estimate import Estimate, FeatureRow, finite_or
from scattertrack.fusion.gating import Gating
from scattertrack.fusion.ground import GroundPhase
from scattertrack.fusion.imu import ImuStream
from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS
from scattertrack.fusion.latency import Latency
from scattertrack.fusion.measurements import FeatureFactors
from scattertrack.fusion.multipath import Multipath
from scattertrack.fusion.params import MarvelParams
from scattertrack.fusion.readout import Readout
from scattertrack.fusion.restart import Diverged, Restarts
from scattertrack.fusion.revised import RevisedTrack
from scattertrack.fusion.take_off import TakeOff
from scattertrack.fusion.window import Window

# MarvelParams and Estimate stay importable from here (their homes: .params, .estimate).
__all__ = ["Estimate", "MarvelEstimator", "MarvelParams"]


class MarvelEstimator(
    ImuStream, TakeOff, GroundPhase, Multipath, Gating, FeatureFactors, Barometer, Window, BetweenEpochs, Readout, Restarts,
    RevisedTrack,
):
    """Causal backscatter-inertial fusion: feed IMU samples and feature rows in time order.

    ``add_imu`` for every IMU sample, ``add_features`` for every feature row
    (after the IMU samples at or before its time); the latter returns the
    :class:`Estimate` of that epoch, or ``None`` when the row is declined
    (counted in :attr:`declined`).
    """

    def __init__(self, params: MarvelParams | None = None, **kwargs):
        if params is None:
            params = MarvelParams.from_kwargs(**kwargs)
        elif kwargs:
            raise ValueError("pass either a MarvelParams or keyword parameters, not both")
        self.params = params
        self.declined: dict[str, int] = {key: 0 for key in DECLINE_REASONS}
        self.epochs = 0
        self.wall_times_s: list[float] = []
        self.cpu_times_s: list[float] = []
        """Thread CPU time per accepted row, s (see :mod:`scattertrack.fusion.latency`)."""
        # The newest state: its index (-1 before take-off), time, estimate
        # and the gate's covariances of it (world frame; nan before the first row).
        self._key = -1
        self._last_epoch_time: float | None = None
        self._nav: gtsam.NavState | None = None
        self._bias = gtsam.imuBias.ConstantBias()
        self._cov_position = np.full((3, 3), np.nan)  # m^2
        self._cov_velocity = np.full((3, 3), np.nan)
        self._cov_yaw = float("nan")
        self._cov_controller = np.full((3, 3), np.nan)
        self._init_imu_stream()
        self._init_take_off()
        self._init_ground()
        self._init_multipath()
        self._init_gating()
        self._init_barometer()
        self._init_between_epochs()
        self._init_window()
        self._init_restarts()
        self._init_revised()

    def step(self, measurement) -> Estimate | None:
        """Either an IMU sample ``("imu", time_s, accel, gyro[, baro_z])`` or a
        feature row ``("features", time_s, range_m, azimuth_rad, elevation_rad, ...)``."""
        kind, *rest = measurement
        if kind == "imu":
            self.add_imu(*rest)
            return None
        if kind == "features":
            return self.add_features(*rest)
        raise ValueError(f"unknown measurement kind {kind!r}")

    # --- one epoch ---------------------------------------------------------

    def add_features(
        self,
        time_s: float,
        range_m: float,
        azimuth_rad: float,
        elevation_rad: float,
        yaw_rad: float = float("nan"),
        range_sigma_m: float = float("nan"),
        angle_sigma_rad: float = float("nan"),
        yaw_sigma_rad: float = float("nan"),
    ) -> Estimate | None:
        """One feature row (docs/formats.md section 7): adds the epoch's state and
        factors, updates the smoother and returns the newest state's estimate;
        ``None`` when the row is declined."""
        if self._between_epochs_due:
            # No IMU sample since the last epoch: its work runs now.
            self._run_between_epochs()
        started = time.perf_counter()
        cpu_started = time.thread_time()
        row = self._admit(time_s, range_m, azimuth_rad, elevation_rad, yaw_rad, range_sigma_m, angle_sigma_rad, yaw_sigma_rad)
        if row is None:
            return None
        self._integrate_to(row.time_s)
        graph = gtsam.NonlinearFactorGraph()
        initial = gtsam.Values()
        stamps: dict[int, float] = {}  # key -> the time (s) of its state
        previous_position = None if self._nav is None else np.asarray(self._nav.position(), dtype=float)
        k = self._add_state(graph, initial, stamps, row)
        predicted = self._nav
        ground_slots = self._ground_for_epoch(graph, k, row.time_s)
        gated = self._gating_on()
        if self._controller is None:
            self._place_controller(graph, initial, row, predicted)
        stamps[CONTROLLER] = row.time_s
        if self._has_range_bias():
            stamps[RANGE_BIAS] = row.time_s

        used = {"range": True, "direction": True, "yaw": row.yaw_rad is not None, "baro": False}
        sigmas = self._row_sigmas(row, predicted)
        multipath_predicted = np.zeros(3)
        if self.params.multipath == "states":
            multipath_predicted = self._add_multipath(
                graph, initial, stamps, row.time_s, np.concatenate([[sigmas.range_m], sigmas.direction_rad]),
                previous_position, predicted,
            )
            self._observe_features(row, previous_position, predicted)
        if not gated:
            self._declined_run = 0
        elif self._gate_row(row, predicted, sigmas, multipath_predicted, used):
            # Persistently beyond the gate: the state is wrong, not the rows.
            return self._diverge(k, row.time_s, predicted, "persistently_gated", row.restart_row)
        self._add_feature_factors(graph, k, row, sigmas, used)
        used["baro"] = self._add_baro(graph, initial, stamps, row.time_s, predicted)

        try:
            stamps = self._update_window(graph, initial, stamps, row.time_s)
            if ground_slots:
                self._record_ground(k, row.time_s, ground_slots)
            for _ in range(self.params.extra_iterations):
                self._smoother_update()
            estimate = self._read_estimate(row.time_s, used)
        except Diverged as failure:
            return self._diverge(k, row.time_s, predicted, "diverged", row.restart_row, str(failure))
        except RuntimeError:
            return self._solver_failed(k, row.time_s, predicted)
        self._accept(k, float(stamps[X(k)]), estimate)
        estimate.wall_time_s = time.perf_counter() - started
        self.wall_times_s.append(estimate.wall_time_s)
        self.cpu_times_s.append(time.thread_time() - cpu_started)
        return estimate

    def _admit(self, time_s, range_m, azimuth_rad, elevation_rad, yaw_rad, range_sigma_m, angle_sigma_rad, yaw_sigma_rad):
        """The :class:`FeatureRow` of these values (missing sigmas the defaults,
        the yaw None when absent or unused), or None when the row is declined
        (counted): not finite, before the IMU (then kept as the anchor), not
        after the previous epoch, too close to it, or older than the newest
        IMU sample."""
        p = self.params
        values = (time_s, range_m, azimuth_rad, elevation_rad)
        if not all(v is not None and math.isfinite(v) for v in values) or range_m <= 0.0:
            return self._decline("non_finite")
        has_yaw = p.use_yaw and yaw_rad is not None and math.isfinite(yaw_rad)
        row = FeatureRow(
            time_s=float(time_s),
            range_m=float(range_m),
            azimuth_rad=float(azimuth_rad),
            elevation_rad=float(elevation_rad),
            yaw_rad=float(yaw_rad) if has_yaw else None,
            range_sigma_m=finite_or(range_sigma_m, p.range_sigma_m),
            angle_sigma_rad=finite_or(angle_sigma_rad, p.angle_sigma_rad),
            yaw_sigma_rad=finite_or(yaw_sigma_rad, p.yaw_sigma_rad),
        )
        if self._first_imu_time is None or row.time_s < self._first_imu_time:
            self._hold_anchor(row)
            return self._decline("before_imu")
        if self._last_epoch_time is not None and row.time_s <= self._last_epoch_time:
            return self._decline("not_after_previous")
        if self._last_epoch_time is not None and row.time_s - self._last_epoch_time < p.min_epoch_interval_s:
            return self._decline("too_close")
        if row.time_s < self._last_sample[0]:
            return self._decline("before_latest_imu")
        return row

    def _add_state(self, graph, initial, stamps, row) -> int:
        """The epoch's new state ``k`` (returned): the first state at take-off
        (and, for a row after it, one more through the preintegrated IMU), or
        the next one joined to the previous through it."""
        if self._key < 0:
            self._take_off(graph, initial, stamps, row)
            # A row at the take-off instant itself measures X(0).
            if self._preintegrated.deltaTij() > 0.0:
                self._key = 1
                self._add_imu_factor(graph, initial, 0)
            else:
                self._key = 0
        else:
            self._key += 1
            self._add_imu_factor(graph, initial, self._key - 1)
        k = self._key
        for key in (X(k), V(k), B(k)):
            stamps[key] = row.time_s
        return k

    def _accept(self, k: int, stamp: float, estimate: Estimate) -> None:
        """After a good update: state ``k`` joins the window at its ``stamp``
        (s), recovery is counted, the next interval integrates against the
        newest bias estimate, and the work between epochs is scheduled
        (:mod:`scattertrack.fusion.between_epochs`)."""
        self._window[k] = (stamp, estimate)
        self._count_recovery()
        self._last_epoch_time = estimate.time_s
        self._restart_integration()
        self.epochs += 1
        self._schedule_between_epochs(estimate.time_s)

    def _decline(self, reason: str) -> None:
        """Counts a declined row; returns None, the value add_features gives for it."""
        self.declined[reason] += 1

    # --- reporting ---------------------------------------------------------

    def latency(self) -> Latency | None:
        """The wall time per accepted row as a :class:`~scattertrack.fusion.latency.Latency` (None before any)."""
        return Latency.of(self.wall_times_s)

    def cpu_latency(self) -> Latency | None:
        """The thread CPU time per accepted row as a :class:`~scattertrack.fusion.latency.Latency`."""
        return Latency.of(self.cpu_times_s)

    def between_epochs_latency(self) -> Latency | None:
        """The wall time of each relinearisation between epochs as a
        :class:`~scattertrack.fusion.latency.Latency` (None without any;
        :mod:`scattertrack.fusion.window`)."""
        return Latency.of(self.between_epochs_times_s)

    def latency_ns(self) -> dict[str, float]:
        """Quantiles of the wall time per accepted feature row, ns (``p50``, ``p99``, ``mean``, ``max``)."""
        record = self.latency()
        if record is None:
            return {}
        return {"p50": record.p50_ns, "p99": record.p99_ns, "mean": record.mean_ns, "max": record.max_ns}

    @property
    def controller(self) -> np.ndarray | None:
        """Current estimate of the controller position, (3,) m, or None before the first row."""
        return None if self._controller is None else self._controller.copy()

    @property
    def velocity_covariance(self) -> np.ndarray | None:
        """World-frame covariance of the newest smoothed velocity, (3, 3) (m/s)^2, or None before the first row.

        With the yaw still loose (no yaw feature: a rail, a hover) it is about
        ``|v|^2 sigma_yaw^2`` across the velocity: the IMU-integrated velocity's
        direction is only as good as the yaw."""
        if not np.all(np.isfinite(self._cov_velocity)):
            return None
        return self._cov_velocity.copy()

    @property
    def position_covariance(self) -> np.ndarray | None:
        """World-frame covariance of the newest position, (3, 3) m^2, or None before the first row."""
        return self._cov_position.copy() if np.all(np.isfinite(self._cov_position)) else None

    @property
    def range_bias(self) -> float | None:
        """Current estimate of the constant range bias ``W(0)`` (m), or None without that state."""
        return self._range_bias if self._has_range_bias() and self._controller is not None else None

    @property
    def multipath(self) -> np.ndarray | None:
        """The newest epoch's multipath errors (range m, direction tangent rad), or None without them."""
        return self._multipath.copy() if self._multipath_chain else None

    @property
    def controller_covariance(self) -> np.ndarray | None:
        """Covariance of the controller estimate, (3, 3) m^2, or None before the first row."""
        return self._cov_controller.copy() if np.all(np.isfinite(self._cov_controller)) else None
