"""The first state of the Marvel estimator and where the controller starts.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`. The first
state ``X(0)`` is placed at the first IMU sample: at the world origin, roll
and pitch from the averaged accelerometer
(:func:`scattertrack.fusion.imu.tilt_from_specific_force`), yaw from the
first yaw feature. A log whose features begin before its IMU keeps its
first row (the anchor): when the IMU then begins in motion, the origin is
where the anchor row saw the drone. The controller ``rho`` starts where the
first row puts it, ``rho = p - d u``.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from scattertrack.fusion import divergence, factors
from scattertrack.fusion.imu import tilt_from_specific_force
from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS


class TakeOff:
    """First-state and controller methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_take_off(self) -> None:
        # Features before the first IMU sample (a log missing its first
        # seconds of IMU): the first such row anchors the world frame.
        self._anchor_row: tuple[float, float, float, float, float, float] | None = None
        self._anchor_used = False  # whether the anchor row placed the origin (the IMU began in motion)
        self._anchor_position_sigma = float("nan")  # m, the first state's spread about where the rows put it
        self._controller: np.ndarray | None = None
        self._controller_fallback = np.zeros(3)  # where the first row put the controller, m

    def _hold_anchor(self, row) -> None:
        """Keeps the first row before the IMU (a :class:`FeatureRow`): the
        world origin is where the drone was at the log's first row; without
        IMU yet, this row is all that ties the controller to it."""
        if self._anchor_row is None:
            self._anchor_row = (row.time_s, row.range_m, row.azimuth_rad, row.elevation_rad,
                                row.range_sigma_m, row.angle_sigma_rad)

    def _take_off(self, graph, initial, stamps, row) -> None:
        """State X(0) at the first IMU sample: at the origin, roll and pitch
        from the averaged accelerometer, yaw from the first yaw feature (this
        epoch's :class:`FeatureRow` ``row``, else 0); the velocity near zero
        if the IMU so far shows rest, else unknown. ``row`` also places the
        state for a log whose features began before its IMU."""
        p = self.params
        yaw_rad = row.yaw_rad if row.yaw_rad is not None else 0.0
        mean_force = self._tilt_sum / self._tilt_count if self._tilt_count else np.array([0.0, 0.0, 1.0])
        roll, pitch = tilt_from_specific_force(mean_force)
        position = np.zeros(3)
        position_sigma = p.prior_position_sigma_m
        provisional = self._provisional_rest()
        # A row before the IMU matters only if the IMU begins in motion: at
        # rest, the drone was where it is now (the origin) all along.
        self._anchor_used = self._anchor_row is not None and not provisional
        if self._anchor_used:
            # The IMU starts after the features: the origin is where the drone
            # was at the anchor row, and this state is where this row puts it
            # from there; loose (the controller's prior carries the anchor).
            _, d0, az0, el0, range_sigma0, angle_sigma0 = self._anchor_row
            controller = divergence.controller_from_origin(d0, az0, el0)
            position = divergence.position_from_features(controller, row.range_m, row.azimuth_rad, row.elevation_rad)
            # The two rows' spreads together: how far this state can be from
            # where they put it (the barometer's datum is checked against it).
            self._anchor_position_sigma = math.hypot(
                divergence.feature_position_sigmas(row.range_m, row.range_sigma_m, row.angle_sigma_rad),
                divergence.feature_position_sigmas(d0, range_sigma0, angle_sigma0),
            )
            position_sigma = 10.0 * self._anchor_position_sigma
        pose = gtsam.Pose3(gtsam.Rot3.Ypr(yaw_rad, pitch, roll), position)
        # Pose3 tangent: rotation about body x, y, z then translation.
        pose_sigmas = np.array(
            [p.prior_tilt_sigma_rad, p.prior_tilt_sigma_rad, p.prior_yaw_sigma_rad] + [position_sigma] * 3
        )
        # At rest (so far: the test's window may not be complete) the
        # velocity is near zero; otherwise it is unknown (a lift-off, a log
        # begun in flight): a wide zero-mean prior, the IMU and the rows find it.
        velocity_sigma = p.prior_velocity_sigma_m_s if provisional else p.moving_velocity_sigma_m_s
        velocity_noise = gtsam.noiseModel.Isotropic.Sigma(3, velocity_sigma)
        bias_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([p.accel_bias_sigma] * 3 + [p.gyro_bias_sigma] * 3))
        graph.add(gtsam.PriorFactorPose3(X(0), pose, gtsam.noiseModel.Diagonal.Sigmas(pose_sigmas)))
        graph.add(gtsam.PriorFactorVector(V(0), np.zeros(3), velocity_noise))
        graph.add(gtsam.PriorFactorConstantBias(B(0), gtsam.imuBias.ConstantBias(), bias_noise))
        initial.insert(X(0), pose)
        initial.insert(V(0), np.zeros(3))
        initial.insert(B(0), gtsam.imuBias.ConstantBias())
        for key in (X(0), V(0), B(0)):
            stamps[key] = self._first_imu_time
        self._nav = gtsam.NavState(pose, np.zeros(3))
        self._bias = gtsam.imuBias.ConstantBias()

    def _place_controller(self, graph, initial, row, predicted) -> None:
        """The controller's first estimate, from the first row: ``rho = p - d u``
        (or, with features before the IMU, where the anchor row puts it with
        that row's spread), and the range bias's prior when there is one."""
        self._controller = predicted.position() - row.range_m * factors.direction(row.azimuth_rad, row.elevation_rad)
        if self._anchor_used:
            _, d0, az0, el0, range_sigma0, angle_sigma0 = self._anchor_row
            self._controller = divergence.controller_from_origin(d0, az0, el0)
            spread = divergence.feature_position_sigmas(d0, range_sigma0, angle_sigma0)
            graph.add(gtsam.PriorFactorPoint3(CONTROLLER, self._controller, gtsam.noiseModel.Isotropic.Sigma(3, spread)))
        self._controller_fallback = self._controller.copy()
        initial.insert(CONTROLLER, self._controller)
        if self._has_range_bias():
            sigma = self.params.range_bias_sigma_m
            graph.add(gtsam.PriorFactorDouble(RANGE_BIAS, 0.0, gtsam.noiseModel.Isotropic.Sigma(1, sigma)))
            initial.insert(RANGE_BIAS, 0.0)


__all__ = ["TakeOff"]
