"""The IMU stream of the Marvel estimator: samples in, preintegration between epochs (paper sec. IV-B).

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`. Between
two epochs the IMU samples are preintegrated into one ``CombinedImuFactor``
(eq. 13, the bias random walk inside); each sample enters on the trapezoid
between it and the previous one. The first ``tilt_window_s`` of specific
force gives the first state's roll and pitch, and the barometer's samples
are kept for ``baro_window_s`` (:mod:`scattertrack.fusion.barometer`).
"""

from __future__ import annotations

import math
import time
from collections import deque

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from scattertrack.fusion.declines import IMU_DECLINE_REASONS
from scattertrack.fusion.imu_noise import ImuNoiseMeter, density_in_use


def tilt_from_specific_force(specific_force) -> tuple[float, float]:
    """Roll and pitch (rad) of a body at rest from its accelerometer (m/s^2).

    At rest ``f = R^T (0, 0, g)``; with ``R = Rz(yaw) Ry(pitch) Rx(roll)``
    that is ``g (-sin pitch, cos pitch sin roll, cos pitch cos roll)``.
    """
    f = np.asarray(specific_force, dtype=float)
    return math.atan2(f[1], f[2]), math.atan2(-f[0], math.hypot(f[1], f[2]))


def preintegration_params(p, accel_density: float | None = None, gyro_density: float | None = None) -> gtsam.PreintegrationCombinedParams:
    """GTSAM's preintegration parameters from :class:`MarvelParams` ``p``:
    continuous-time densities squared (GTSAM divides by dt when it
    discretises); gravity along -z (MakeSharedU). ``accel_density`` and
    ``gyro_density`` replace the stated white-noise densities (the measured
    ones, :mod:`scattertrack.fusion.imu_noise`); ``imu_noise_scale`` multiplies
    either."""
    params = gtsam.PreintegrationCombinedParams.MakeSharedU(p.gravity_m_s2)
    eye = np.eye(3)
    accel = p.accel_noise_density if accel_density is None else accel_density
    gyro = p.gyro_noise_density if gyro_density is None else gyro_density
    params.setAccelerometerCovariance(eye * (accel * p.imu_noise_scale) ** 2)
    params.setGyroscopeCovariance(eye * (gyro * p.imu_noise_scale) ** 2)
    params.setBiasAccCovariance(eye * p.accel_bias_random_walk**2)
    params.setBiasOmegaCovariance(eye * p.gyro_bias_random_walk**2)
    params.setIntegrationCovariance(eye * p.integration_sigma**2)
    return params


class ImuStream:
    """IMU methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_imu_stream(self) -> None:
        self.imu_samples = 0
        self.imu_wall_time_s = 0.0
        """Wall time spent in :meth:`add_imu`, all samples together, s."""
        self.imu_declined: dict[str, int] = {key: 0 for key in IMU_DECLINE_REASONS}
        self._imu_params = preintegration_params(self.params)
        self._preintegrated = gtsam.PreintegratedCombinedMeasurements(self._imu_params)
        self._noise_meter = ImuNoiseMeter()
        self.imu_noise_measured: tuple[float, float] | None = None
        """The newest (accelerometer m/s^2/√Hz, gyroscope rad/s/√Hz) white-noise
        densities measured from the samples; None before enough samples."""
        self.imu_noise_used = (self.params.accel_noise_density, self.params.gyro_noise_density)
        """The densities the preintegration uses now (before ``imu_noise_scale``)."""
        # The newest sample (time s, specific force m/s^2, rate rad/s) and
        # the time the preintegration has reached.
        self._first_imu_time: float | None = None
        self._last_sample: tuple[float, np.ndarray, np.ndarray] | None = None
        self._integrated_to: float | None = None
        self._tilt_sum = np.zeros(3)
        self._tilt_count = 0
        self._baro: deque[tuple[float, float]] = deque()

    def add_imu(self, time_s: float, accel, gyro, baro_z: float = float("nan")) -> None:
        """One IMU sample: specific force (m/s^2) and angular rate (rad/s) in
        the body frame, optional barometric height (m). Samples must come in
        increasing time; a sample not after the previous one, or with a
        non-finite value, is ignored and counted in :attr:`imu_declined`.

        The first sample after an epoch first runs the work between epochs
        (timed apart: :mod:`scattertrack.fusion.between_epochs`)."""
        if self._between_epochs_due:
            self._run_between_epochs()
        started = time.perf_counter()
        try:
            self._add_imu(float(time_s), np.asarray(accel, dtype=float), np.asarray(gyro, dtype=float), baro_z)
        finally:
            self.imu_wall_time_s += time.perf_counter() - started

    def _add_imu(self, time_s: float, accel: np.ndarray, gyro: np.ndarray, baro_z) -> None:
        if not (math.isfinite(time_s) and np.all(np.isfinite(accel)) and np.all(np.isfinite(gyro))):
            self.imu_declined["non_finite"] += 1
            return
        if self._last_sample is not None and time_s <= self._last_sample[0]:
            self.imu_declined["not_after_previous"] += 1
            return
        self.imu_samples += 1
        if self.params.imu_noise_from_data:
            self._noise_meter.add(time_s, accel, gyro)
        if self._rest_state == "pending":
            self._collect_rest(time_s, accel, gyro, baro_z)
        elif self._rest_state == "rest" and not self._left_ground:
            self._watch_take_off(time_s, accel, gyro)
        if self._first_imu_time is None:
            self._first_imu_time = time_s
            self._integrated_to = time_s
        elif time_s > self._integrated_to:
            # Trapezoid over (integrated_to, t] on the line between the
            # previous sample and this one: second order in dt, where holding
            # the old sample would lag the signal by half a period.
            t_prev, a_prev, w_prev = self._last_sample
            span = time_s - t_prev
            fraction = (self._integrated_to - t_prev) / span
            a_start = a_prev + fraction * (accel - a_prev)
            w_start = w_prev + fraction * (gyro - w_prev)
            self._preintegrated.integrateMeasurement(
                0.5 * (a_start + accel), 0.5 * (w_start + gyro), time_s - self._integrated_to
            )
            self._integrated_to = time_s
        self._last_sample = (time_s, accel, gyro)
        if self._key < 0 and time_s <= self._first_imu_time + self.params.tilt_window_s:
            self._tilt_sum += accel
            self._tilt_count += 1
        if baro_z is not None and math.isfinite(baro_z):
            self._baro.append((time_s, float(baro_z)))
            while self._baro and self._baro[0][0] <= time_s - self.params.baro_window_s:
                self._baro.popleft()

    def predict(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The newest state propagated by the IMU to ``time_s`` (s): position (m),
        velocity (m/s), world_R_body (3x3); None before the first epoch.

        Causal: it uses the IMU samples received so far (the newest one held up
        to ``time_s``). The pose sensing calls it to remove the translational
        Doppler shift of the epoch at ``time_s`` before that epoch's features
        exist (paper sec. III-B: "the super-accuracy algorithm corrects the
        drift and feeds back"). ``time_s`` must not precede the newest sample.
        """
        if self._nav is None or self._last_sample is None:
            return None
        self._integrate_to(time_s)
        state = self._preintegrated.predict(self._nav, self._bias)
        return np.asarray(state.position(), dtype=float), np.asarray(state.velocity(), dtype=float), np.asarray(
            state.attitude().matrix(), dtype=float
        )

    def _integrate_to(self, time_s: float) -> None:
        """Extends the preintegration to ``time_s`` holding the newest sample
        (the next one is not known yet: causal)."""
        if time_s > self._integrated_to:
            _, accel, gyro = self._last_sample
            self._preintegrated.integrateMeasurement(accel, gyro, time_s - self._integrated_to)
            self._integrated_to = time_s

    def _add_imu_factor(self, graph, initial, previous: int) -> None:
        """The preintegrated IMU between state ``previous`` and the newest, ``k``;
        ``k``'s initial values are the previous estimate pushed through the
        preintegration (prior-free: the gate's prediction), and the gate's
        position and yaw covariances grow by the preintegration's."""
        k = self._key
        graph.add(gtsam.CombinedImuFactor(X(previous), V(previous), X(k), V(k), B(previous), B(k), self._preintegrated))
        predicted = self._preintegrated.predict(self._nav, self._bias)
        dt = self._preintegrated.deltaTij()
        if np.all(np.isfinite(self._cov_position)):
            rotation = self._nav.attitude().matrix()
            preintegrated_cov = np.asarray(self._preintegrated.preintMeasCov())
            # preintMeasCov order: rotation, position, velocity, biases;
            # position in the previous body frame.
            self._cov_position = (
                self._cov_position
                + dt * dt * self._cov_velocity
                + rotation @ preintegrated_cov[3:6, 3:6] @ rotation.T
            )
            self._cov_yaw = self._cov_yaw + preintegrated_cov[2, 2]
        initial.insert(X(k), predicted.pose())
        initial.insert(V(k), predicted.velocity())
        initial.insert(B(k), self._bias)
        self._nav = predicted

    def _restart_integration(self) -> None:
        """The next interval integrates from now against the newest bias
        estimate, with the white-noise densities the samples have shown."""
        if self._refresh_imu_noise():
            self._preintegrated = gtsam.PreintegratedCombinedMeasurements(self._imu_params, self._bias)
        else:
            self._preintegrated.resetIntegrationAndSetBias(self._bias)

    def _refresh_imu_noise(self) -> bool:
        """Whether the densities in use changed (then ``_imu_params`` is rebuilt):
        each sensor's is the stated one unless the measured one is more than
        ``imu_noise_agreement`` times larger; a change under 10 % is not made
        (the measurement wanders by a few per cent between epochs)."""
        p = self.params
        if not p.imu_noise_from_data:
            return False
        measured = self._noise_meter.densities()
        if measured is None:
            return False
        self.imu_noise_measured = measured
        wanted = (
            density_in_use(p.accel_noise_density, measured[0], p.imu_noise_agreement),
            density_in_use(p.gyro_noise_density, measured[1], p.imu_noise_agreement),
        )
        if all(abs(w - u) <= 0.1 * u for w, u in zip(wanted, self.imu_noise_used)):
            return False
        self.imu_noise_used = wanted
        self._imu_params = preintegration_params(p, *wanted)
        return True


__all__ = ["ImuStream", "preintegration_params", "tilt_from_specific_force"]
