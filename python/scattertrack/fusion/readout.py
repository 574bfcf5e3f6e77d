"""Reading the newest state out of the Marvel estimator's smoother after an update.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`: the
newest pose, velocity, biases and controller (refused when not finite or
beyond the physical bounds, :mod:`scattertrack.fusion.divergence`), the
barometer's and the multipath states' estimates, and the marginal
covariances the gate and the reported 1-sigmas need.
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from scattertrack.fusion import divergence
from scattertrack.fusion.estimate import Estimate
from scattertrack.fusion.keys import CONTROLLER
from scattertrack.fusion.restart import Diverged
from scattertrack.fusion.revised import _quaternion, _world_position_covariance


class Readout:
    """Read-out methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _read_estimate(self, time_s: float, used: dict) -> Estimate:
        """The :class:`Estimate` of the newest state at ``time_s`` (s), with the
        row's ``used`` measurements (:meth:`_read_state`)."""
        pose, velocity = self._read_state()
        if self.params.compute_sigma:
            sigma = np.sqrt(np.clip(np.diag(self._cov_position), 0.0, None))
            controller_sigma = np.sqrt(np.clip(np.diag(self._cov_controller), 0.0, None))
        else:
            sigma = np.full(3, np.nan)
            controller_sigma = np.full(3, np.nan)
        return Estimate(
            time_s=time_s,
            position=np.asarray(pose.translation(), dtype=float),
            velocity=velocity,
            orientation=_quaternion(pose),
            sigma=sigma,
            controller=self._controller.copy(),
            controller_sigma=controller_sigma,
            accel_bias=np.asarray(self._bias.accelerometer(), dtype=float),
            gyro_bias=np.asarray(self._bias.gyroscope(), dtype=float),
            used=used,
        )

    def _read_state(self):
        """The newest state ``k``'s pose and velocity from the smoother; the
        estimator's newest-state caches (navigation state, bias, controller,
        barometer offset, multipath, covariances) follow it.

        Raises RuntimeError for a non-finite estimate and :class:`Diverged`
        for one beyond the physical bounds, before any cache changes."""
        k = self._key
        smoother = self._smoother
        pose = smoother.calculateEstimatePose3(X(k))
        velocity = np.asarray(smoother.calculateEstimateVector(V(k)), dtype=float)
        controller = np.asarray(smoother.calculateEstimatePoint3(CONTROLLER), dtype=float)
        if not (np.all(np.isfinite(pose.matrix())) and np.all(np.isfinite(velocity)) and np.all(np.isfinite(controller))):
            # A solve that overflowed (measured in a reflecting room at IQ
            # level: a position of inf) is a solver failure like a thrown
            # one: the caller declines the row and restarts the smoother.
            raise RuntimeError("non-finite estimate")
        p = self.params
        violation = divergence.physical_violation(
            np.asarray(pose.translation(), dtype=float), velocity, controller,
            max_speed_m_s=p.max_speed_m_s, max_controller_range_m=p.max_controller_range_m, max_position_m=p.max_position_m,
        )
        if violation is not None:
            raise Diverged(violation)
        self._bias = smoother.calculateEstimateConstantBias(B(k))
        self._controller = controller
        self._read_baro(smoother)
        self._read_multipath(smoother)
        self._nav = gtsam.NavState(pose, velocity)
        if p.compute_sigma or self._gate is not None:
            self._read_covariances(k, pose)
        return pose, velocity

    def _read_covariances(self, k: int, pose) -> None:
        """The marginal covariances of state ``k`` (its ``pose``) and the
        controller: position (world, m^2), yaw (rad^2), velocity, controller."""
        smoother = self._smoother
        pose_cov = np.asarray(smoother.marginalCovariance(X(k)))
        self._cov_position = _world_position_covariance(pose, pose_cov)
        self._cov_yaw = float(pose_cov[2, 2])
        self._cov_velocity = np.asarray(smoother.marginalCovariance(V(k)))
        self._cov_controller = np.asarray(smoother.marginalCovariance(CONTROLLER))


__all__ = ["Readout"]
