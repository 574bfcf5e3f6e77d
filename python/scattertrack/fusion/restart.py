"""Restarts of the Marvel estimator's smoother: after a failed solve, and after divergence.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`: a failed
solve (GTSAM's indeterminate system) restarts from the IMU's prediction with
priors as wide as the last covariances; a diverged state (physical bounds,
persistent gating: :mod:`scattertrack.fusion.divergence`) restarts from the
features and the barometer, counted.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from scattertrack.fusion import divergence
from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS


class Diverged(RuntimeError):
    """A solve whose state left the physical bounds (``MarvelParams.max_speed_m_s``,
    ``max_controller_range_m``, ``max_position_m``): the row is refused and the
    smoother restarts from the features (:mod:`scattertrack.fusion.divergence`)."""


def _spread(covariance: np.ndarray, default: float) -> np.ndarray:
    """Three times the 1-sigmas of a (3, 3) covariance (at least 0.03), or
    ``3 default`` when it is not finite: a restart's loose priors."""
    diagonal = np.diag(covariance) if np.all(np.isfinite(covariance)) else np.full(3, default**2)
    return np.sqrt(np.maximum(diagonal, 1e-4)) * 3.0


class Restarts:
    """Restart methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_restarts(self) -> None:
        self.restarts = 0
        """Times the smoother was restarted after a solver failure."""
        self.divergences = 0
        """Times the state was found diverged (bounds or persistent gating) and restarted from the features."""
        self.divergences_recovered = 0
        """Of those, the ones followed by ``recovery_epochs`` accepted epochs
        without another (all since the last recovery count then)."""
        self._since_divergence: int | None = None  # accepted epochs since the last divergence, None when recovered
        self.divergence_reasons: list[str] = []

    def _restart(self, k: int, time_s: float, predicted) -> None:
        """A fresh smoother holding state ``k`` (the IMU prediction ``predicted``), the bias and
        the controller, each with a prior as wide as its last covariance (or a loose default):
        the recovery from a failed solve, whose state was sound before it."""
        pose_sigmas = np.concatenate([np.full(3, 0.05), _spread(self._cov_position, 1.0)])
        self._restart_with(
            k, time_s, predicted, pose_sigmas, _spread(self._cov_velocity, 0.5), self._bias,
            self._controller, _spread(self._cov_controller, 5.0),
        )

    def _restart_from_features(self, k: int, time_s: float, predicted, row) -> None:
        """A fresh smoother holding state ``k`` where the feature ``row`` and the
        barometer put it (:mod:`scattertrack.fusion.divergence`): the recovery
        from a diverged state, which the IMU's prediction would carry on.

        ``row``: (range m, azimuth rad, elevation rad, yaw rad or None). The
        controller stays where it was if that is plausible (within
        ``max_controller_range_m`` of the take-off point), else it goes back
        to where the first row put it. Position ``rho + d u``, its height from
        the barometer's datum when there is one; velocity 0 with
        ``moving_velocity_sigma_m_s``; roll and pitch kept, the yaw the row's
        (else kept) with a loose sigma; the biases kept when plausible.
        """
        p = self.params
        range_m, azimuth_rad, elevation_rad, yaw_rad = row
        controller_ok = self._controller is not None and divergence.is_plausible_controller(
            self._controller, np.zeros(3), p.max_controller_range_m
        )
        controller = self._controller if controller_ok else self._controller_fallback
        controller_sigmas = _spread(self._cov_controller, 5.0) if controller_ok else np.full(3, 5.0)
        position = divergence.position_from_features(controller, range_m, azimuth_rad, elevation_rad)
        samples = self._baro_samples(time_s)
        if p.use_baro and samples and math.isfinite(self._baro_datum):
            position[2] = float(np.mean(samples)) - self._baro_datum
        position_sigma = divergence.feature_position_sigmas(range_m, p.range_sigma_m, p.angle_sigma_rad) * 3.0
        rotation = predicted.attitude() if np.all(np.isfinite(predicted.attitude().matrix())) else gtsam.Rot3()
        ypr = rotation.ypr()
        yaw_sigma = p.prior_yaw_sigma_rad
        if yaw_rad is not None and math.isfinite(yaw_rad):
            ypr = (float(yaw_rad), ypr[1], ypr[2])
        rotation = gtsam.Rot3.Ypr(*ypr)
        nav = gtsam.NavState(gtsam.Pose3(rotation, position), np.zeros(3))
        pose_sigmas = np.array([0.1, 0.1, yaw_sigma] + [position_sigma] * 3)
        bias = self._bias
        accel_bias = np.asarray(bias.accelerometer(), dtype=float)
        gyro_bias = np.asarray(bias.gyroscope(), dtype=float)
        if not (np.all(np.abs(accel_bias) <= 10.0 * p.accel_bias_sigma) and np.all(np.abs(gyro_bias) <= 10.0 * p.gyro_bias_sigma)):
            bias = gtsam.imuBias.ConstantBias()
        self._restart_with(
            k, time_s, nav, pose_sigmas, np.full(3, p.moving_velocity_sigma_m_s), bias, controller, controller_sigmas
        )
        # The gate's covariances: the restart's priors (the old ones belong to the diverged state).
        self._cov_position = np.eye(3) * position_sigma**2
        self._cov_velocity = np.eye(3) * p.moving_velocity_sigma_m_s**2
        self._cov_controller = np.diag(controller_sigmas**2)
        self._cov_yaw = yaw_sigma**2

    def _restart_with(self, k, time_s, nav, pose_sigmas, velocity_sigmas, bias, controller, controller_sigmas) -> None:
        """A fresh smoother holding state ``k`` = ``nav`` (a NavState), ``bias`` and the
        ``controller`` (m) with the given 1-sigma priors (Pose3 tangent order:
        rotation rad, then translation m)."""
        p = self.params
        self._smoother = self._new_smoother()
        self._lag = self.params.smoother_lag_s
        self._pending_removals = []
        self._ground_factor_indices = {}
        self._ground_epochs = []
        graph = gtsam.NonlinearFactorGraph()
        initial = gtsam.Values()
        pose = nav.pose()
        graph.add(gtsam.PriorFactorPose3(X(k), pose, gtsam.noiseModel.Diagonal.Sigmas(np.asarray(pose_sigmas, dtype=float))))
        graph.add(gtsam.PriorFactorVector(V(k), nav.velocity(), gtsam.noiseModel.Diagonal.Sigmas(np.asarray(velocity_sigmas, dtype=float))))
        bias_sigmas = np.array([p.accel_bias_sigma] * 3 + [p.gyro_bias_sigma] * 3)
        graph.add(gtsam.PriorFactorConstantBias(B(k), bias, gtsam.noiseModel.Diagonal.Sigmas(bias_sigmas)))
        graph.add(gtsam.PriorFactorPoint3(CONTROLLER, controller, gtsam.noiseModel.Diagonal.Sigmas(np.asarray(controller_sigmas, dtype=float))))
        if self._has_range_bias():
            # Its prior sigma: its marginal is not kept (one more marginal per
            # epoch for the rare restart).
            graph.add(gtsam.PriorFactorDouble(RANGE_BIAS, self._range_bias, gtsam.noiseModel.Isotropic.Sigma(1, p.range_bias_sigma_m)))
        initial.insert(X(k), pose)
        initial.insert(V(k), nav.velocity())
        initial.insert(B(k), bias)
        initial.insert(CONTROLLER, controller)
        stamps = {X(k): time_s, V(k): time_s, B(k): time_s, CONTROLLER: time_s}
        if self._has_range_bias():
            initial.insert(RANGE_BIAS, self._range_bias)
            stamps[RANGE_BIAS] = time_s
        self._baro_chain = False  # a new barometer offset chain starts with the next epoch
        self._multipath_chain = False  # and a new multipath chain
        self._smoother_update(graph, initial, {key: self._stamp(t) for key, t in stamps.items()})
        self._nav = nav
        self._bias = bias
        self._controller = np.asarray(controller, dtype=float).copy()

    def _diverge(self, k: int, time_s: float, predicted, reason: str, row, detail: str = "") -> None:
        """The state has diverged (``reason``: a key of :data:`DECLINE_REASONS`):
        counted, the row refused, the smoother restarted from the features."""
        self.divergences += 1
        self.divergence_reasons.append(f"{time_s:.2f} s: {detail or reason}")
        self._since_divergence = 0
        self._release(math.inf, revise=False)
        self._restart_from_features(k, time_s, predicted, row)
        self._last_epoch_time = time_s
        self._restart_integration()
        self.restarts += 1
        self._gate_monitor.clear()
        self._declined_run = 0
        self._range_declined_run = 0
        return self._decline(reason)

    def _solver_failed(self, k: int, time_s: float, predicted) -> None:
        """The smoother's linear system failed (GTSAM throws on an
        ill-conditioned, IndeterminateLinearSystem, one) or its solve was not
        finite: its state is unusable. The row is declined and the smoother
        restarts from the predicted state, with priors as wide as the last
        covariances, so a bad row never ends the run; the states in the
        failed smoother's window keep their causal estimates."""
        self._release(math.inf, revise=False)
        self._restart(k, time_s, predicted)
        self._last_epoch_time = time_s
        self._restart_integration()
        self.restarts += 1
        return self._decline("solver_failure")

    def _count_recovery(self) -> None:
        """After an accepted epoch: a divergence is recovered once
        ``recovery_epochs`` accepted epochs followed it without another (one
        that followed another within them superseded it)."""
        if self._since_divergence is not None:
            self._since_divergence += 1
            if self._since_divergence >= self.params.recovery_epochs:
                self.divergences_recovered = self.divergences
                self._since_divergence = None
