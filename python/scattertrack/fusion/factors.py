"""Measurement models of the backscatter-inertial fusion (paper sec. IV, eq. 12).

Pure functions first: each model takes plain numpy arrays (world frame, SI
units) and returns its residual ``r = predicted - measured`` and, on request,
the Jacobians of ``r`` with respect to its arguments. Then thin wrappers turn
them into ``gtsam.CustomFactor``s on the graph's variables:

- ``X(k)``: ``gtsam.Pose3`` world_T_body of epoch k. GTSAM perturbs a pose on
  the right, ``T * Exp([omega, v])``: ``omega`` (rad) is a rotation in the
  body frame and ``v`` (m) a translation in the body frame, so the chain rule
  from a world-frame position Jacobian ``J_p`` to the pose is ``[0, J_p R]``,
  and from a body rotation-vector Jacobian ``J_omega`` it is ``[J_omega, 0]``.
- ``L(0)``: the controller's position ``rho`` (m, world frame, a Point3).
- ``O(k)``: the barometer's offset (m, a double), see :func:`height_residual`.
- ``M(k)``: the features' multipath errors of epoch k (a 3-vector: range m,
  then the direction's two tangent components rad), a first-order
  Gauss-Markov process between epochs, see :func:`gauss_markov_residual`.

Symbols: ``p`` drone (body origin) position, ``rho`` controller position,
``delta = p - rho``, ``r = |delta|`` range, ``w = delta / r`` direction from
the controller to the drone, ``R`` world_T_body rotation matrix.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np

from scattertrack.physics import wrap_angle  # noqa: F401 - factors.wrap_angle: the estimator's name for it

# --- pure models -------------------------------------------------------------


def direction(azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """Unit direction ``u = (cos el cos az, cos el sin az, sin el)`` from the controller to the drone."""
    ce = math.cos(elevation_rad)
    return np.array([ce * math.cos(azimuth_rad), ce * math.sin(azimuth_rad), math.sin(elevation_rad)])


def direction_basis(azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """Orthonormal basis (3, 2) of the plane perpendicular to ``u(az, el)``.

    Columns: ``e_az = (-sin az, cos az, 0)`` (the direction of growing
    azimuth; ``du/daz = cos(el) e_az``) and ``e_el = du/del = (-sin el cos az,
    -sin el sin az, cos el)``. Both are defined at every direction, so the
    residual below has no singularity at the zenith.
    """
    sa, ca = math.sin(azimuth_rad), math.cos(azimuth_rad)
    se, ce = math.sin(elevation_rad), math.cos(elevation_rad)
    return np.array([[-sa, -se * ca], [ca, -se * sa], [0.0, ce]])


def range_residual(position, controller, measured_range_m: float, jacobians: bool = False):
    """Range residual ``e_d = |p - rho| - d_hat`` (metres), paper eq. 12 first row.

    The paper writes the squared form ``|d_hat^2 - |p - rho|^2|``; its noise
    grows with ``2 d`` and its absolute value has no derivative at zero, so
    we use the plain difference of ranges: linear in the range error, whose
    1-sigma ``range_sigma_m`` the features give directly (the squared form
    would need the state-dependent sigma ``2 d sigma``).

    Returns ``residual (1,)`` or, with ``jacobians``, ``(residual, (H_p (1, 3),
    H_rho (1, 3)))``: ``d e / d p = w^T``, ``d e / d rho = -w^T``.
    """
    delta = np.asarray(position, dtype=float) - np.asarray(controller, dtype=float)
    distance = float(np.linalg.norm(delta))
    residual = np.array([distance - measured_range_m])
    if not jacobians:
        return residual
    # At delta = 0 the range has no gradient; any unit vector is a valid
    # subgradient and keeps the linear system finite.
    unit = delta / distance if distance > 0.0 else np.array([1.0, 0.0, 0.0])
    h_position = unit.reshape(1, 3)
    return residual, (h_position, -h_position)


def direction_residual(position, controller, azimuth_rad: float, elevation_rad: float, jacobians: bool = False):
    """Direction residual (radians, 2-vector), paper eq. 12 second row.

    ``e_a = E^T w`` with ``w = (p - rho) / |p - rho|`` and ``E = [e_az, e_el]``
    the basis of the plane perpendicular to the measured direction ``a_hat =
    u(az_hat, el_hat)`` (:func:`direction_basis`). This is the paper's
    cross-product residual ``a_hat x (p - rho)`` divided by the range and
    written in the 2-D basis ``(a_hat x e_az, a_hat x e_el) = (e_el, -e_az)``:
    the cross product has a third component (along ``a_hat``) that is always
    zero, so its 3x3 covariance is singular, and its size grows with the
    range; the projection is full rank and in radians. To first order
    ``e_a = (cos(el) (az - az_hat), el - el_hat)``, so its 1-sigma is
    ``(cos(el_hat) sigma_angle, sigma_angle)`` (see :func:`direction_sigmas`).

    Returns ``residual (2,)`` or ``(residual, (H_p (2, 3), H_rho (2, 3)))`` with
    ``d w / d p = (I - w w^T) / r``.
    """
    delta = np.asarray(position, dtype=float) - np.asarray(controller, dtype=float)
    distance = float(np.linalg.norm(delta))
    basis = direction_basis(azimuth_rad, elevation_rad)
    if distance <= 0.0:
        # Drone on the controller: no direction; a zero residual with zero
        # gradient leaves the state to the other factors.
        residual = np.zeros(2)
        return (residual, (np.zeros((2, 3)), np.zeros((2, 3)))) if jacobians else residual
    unit = delta / distance
    residual = basis.T @ unit
    if not jacobians:
        return residual
    h_position = basis.T @ (np.eye(3) - np.outer(unit, unit)) / distance
    return residual, (h_position, -h_position)


def direction_sigmas(elevation_rad: float, angle_sigma_rad: float, floor_rad: float = 1e-3) -> np.ndarray:
    """1-sigma (radians) of the two components of :func:`direction_residual`.

    An azimuth error ``d az`` moves the direction by ``cos(el) d az`` along
    ``e_az``; the floor keeps the weight finite when the drone is nearly
    above the controller (where azimuth carries no information).
    """
    return np.array([max(math.cos(elevation_rad) * angle_sigma_rad, floor_rad), max(angle_sigma_rad, floor_rad)])


def yaw_of(rotation) -> float:
    """Heading of body x about +z, ``atan2(R[1,0], R[0,0])`` (radians), docs/marvel.md section 1."""
    rotation = np.asarray(rotation, dtype=float)
    return math.atan2(rotation[1, 0], rotation[0, 0])


def yaw_residual(rotation, measured_yaw_rad: float, jacobians: bool = False):
    """Yaw residual ``e_psi = wrap(yaw(R) - psi_hat)`` (radians), paper eq. 12 third row.

    The paper builds a full measured attitude from the yaw and the IMU's
    roll and pitch and takes ``2 [q_hat^-1 q]_xyz``; roll and pitch are
    already in the IMU factors, so only the measured quantity, the heading,
    enters here (one dimension, no double counting of the accelerometer).
    Wrapping makes 359 deg vs 1 deg a 2 deg error.

    Jacobian with respect to a body-frame rotation vector ``omega`` applied
    on the right (``R Exp(omega)``, GTSAM's convention): the body x axis in
    the world, ``c = R e_x``, moves by ``d c = -R [e_x]_x omega`` and
    ``d yaw / d c = (-c_y, c_x, 0) / (c_x^2 + c_y^2)``. Singular only when
    body x points straight up or down, which a flying multirotor avoids.

    Returns ``residual (1,)`` or ``(residual, H_omega (1, 3))``.
    """
    rotation = np.asarray(rotation, dtype=float)
    residual = np.array([float(wrap_angle(yaw_of(rotation) - measured_yaw_rad))])
    if not jacobians:
        return residual
    c_x, c_y = rotation[0, 0], rotation[1, 0]
    horizontal = max(c_x * c_x + c_y * c_y, 1e-12)
    d_yaw_d_c = np.array([-c_y, c_x, 0.0]) / horizontal
    # [e_x]_x omega = e_x x omega = (0, -omega_z, omega_y).
    skew_x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    h_omega = (d_yaw_d_c @ (-rotation @ skew_x)).reshape(1, 3)
    return residual, h_omega


def height_residual(height_m: float, offset_m: float, measured_height_m: float, jacobians: bool = False):
    """Barometer residual ``e_b = p_z + o - b_hat`` (metres).

    The barometer measures height plus a slowly wandering offset ``o``
    (weather, temperature: docs/marvel.md section 3, a random walk of
    0.02 m/sqrt(s)); ``o`` is a state of its own with a random-walk between
    epochs, which keeps consecutive residuals independent (differencing raw
    readings between epochs would correlate neighbouring factors).

    Returns ``residual (1,)`` or ``(residual, (H_z (1, 1), H_o (1, 1)))``.
    """
    residual = np.array([height_m + offset_m - measured_height_m])
    if not jacobians:
        return residual
    return residual, (np.ones((1, 1)), np.ones((1, 1)))


def gauss_markov_residual(previous, current, decay, jacobians: bool = False):
    """Gauss-Markov transition residual ``e = m_k - a * m_{k-1}`` (per component).

    A first-order Gauss-Markov process ``m_k = a m_{k-1} + w`` with decay
    ``a = phi`` (the correlation between epochs, one per component); the
    noise model carries the walk ``w``'s 1-sigma (the estimator chooses it so
    that ``m_k`` keeps the 1-sigma of its row, see
    ``MarvelEstimator._add_multipath``).
    The standard model of time-correlated errors in aided navigation
    (Farrell, *Aided Navigation*, 2008, sec. 4.9): a state per error instead
    of inflating the measurement noise.

    Returns ``residual (n,)`` or ``(residual, (H_previous (n, n), H_current (n, n)))``.
    """
    previous = np.asarray(previous, dtype=float)
    decay = np.asarray(decay, dtype=float)
    residual = np.asarray(current, dtype=float) - decay * previous
    if not jacobians:
        return residual
    return residual, (-np.diag(decay), np.eye(residual.size))


# --- chain rule onto gtsam's manifolds ---------------------------------------


def position_to_pose_jacobian(h_position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``[0, H_p R]`` (m, 6): a world-position Jacobian onto the Pose3 tangent ``[omega, v]``."""
    return np.hstack([np.zeros((h_position.shape[0], 3)), h_position @ rotation])


def rotation_to_pose_jacobian(h_omega: np.ndarray) -> np.ndarray:
    """``[H_omega, 0]`` (m, 6): a body rotation-vector Jacobian onto the Pose3 tangent."""
    return np.hstack([h_omega, np.zeros((h_omega.shape[0], 3))])


# --- gtsam factors -----------------------------------------------------------


def range_factor(pose_key: int, controller_key: int, measured_range_m: float, noise) -> gtsam.CustomFactor:
    """:func:`range_residual` between the pose ``X(k)`` and the controller ``L(0)``."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        pose = values.atPose3(this.keys()[0])
        controller = values.atPoint3(this.keys()[1])
        if jacobians is None:
            return range_residual(pose.translation(), controller, measured_range_m)
        residual, (h_position, h_controller) = range_residual(
            pose.translation(), controller, measured_range_m, jacobians=True
        )
        jacobians[0] = position_to_pose_jacobian(h_position, pose.rotation().matrix())
        jacobians[1] = h_controller
        return residual

    return gtsam.CustomFactor(noise, [pose_key, controller_key], error)


def direction_factor(
    pose_key: int, controller_key: int, azimuth_rad: float, elevation_rad: float, noise
) -> gtsam.CustomFactor:
    """:func:`direction_residual` between the pose ``X(k)`` and the controller ``L(0)``."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        pose = values.atPose3(this.keys()[0])
        controller = values.atPoint3(this.keys()[1])
        if jacobians is None:
            return direction_residual(pose.translation(), controller, azimuth_rad, elevation_rad)
        residual, (h_position, h_controller) = direction_residual(
            pose.translation(), controller, azimuth_rad, elevation_rad, jacobians=True
        )
        jacobians[0] = position_to_pose_jacobian(h_position, pose.rotation().matrix())
        jacobians[1] = h_controller
        return residual

    return gtsam.CustomFactor(noise, [pose_key, controller_key], error)


def range_factor_multipath(
    pose_key: int,
    controller_key: int,
    multipath_key: int,
    measured_range_m: float,
    noise,
    bias_key: int | None = None,
) -> gtsam.CustomFactor:
    """:func:`range_residual` plus the epoch's multipath range error ``m_0`` (m)
    and, with ``bias_key``, a constant range bias ``beta`` (m, a double: the
    excess delay of walls): ``e = |p - rho| + m_0 + beta - d_hat``, between
    ``X(k)``, ``L(0)``, ``M(k)`` (and the bias)."""
    keys = [pose_key, controller_key, multipath_key] + ([] if bias_key is None else [bias_key])

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        pose = values.atPose3(this.keys()[0])
        controller = values.atPoint3(this.keys()[1])
        offset = values.atVector(this.keys()[2])[0]
        if bias_key is not None:
            offset += values.atDouble(this.keys()[3])
        if jacobians is None:
            return range_residual(pose.translation(), controller, measured_range_m) + offset
        residual, (h_position, h_controller) = range_residual(
            pose.translation(), controller, measured_range_m, jacobians=True
        )
        jacobians[0] = position_to_pose_jacobian(h_position, pose.rotation().matrix())
        jacobians[1] = h_controller
        jacobians[2] = np.array([[1.0, 0.0, 0.0]])
        if bias_key is not None:
            jacobians[3] = np.ones((1, 1))
        return residual + offset

    return gtsam.CustomFactor(noise, keys, error)


def direction_factor_multipath(
    pose_key: int, controller_key: int, multipath_key: int, azimuth_rad: float, elevation_rad: float, noise
) -> gtsam.CustomFactor:
    """:func:`direction_residual` plus the epoch's multipath direction error
    ``(m_1, m_2)`` (rad, along ``e_az`` and ``e_el``): to first order the
    measured direction is the true one moved by ``m_1 e_az + m_2 e_el``, so
    ``E^T w = -(m_1, m_2)`` and the residual is ``E^T w + (m_1, m_2)``."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        pose = values.atPose3(this.keys()[0])
        controller = values.atPoint3(this.keys()[1])
        multipath = values.atVector(this.keys()[2])
        if jacobians is None:
            return direction_residual(pose.translation(), controller, azimuth_rad, elevation_rad) + multipath[1:3]
        residual, (h_position, h_controller) = direction_residual(
            pose.translation(), controller, azimuth_rad, elevation_rad, jacobians=True
        )
        jacobians[0] = position_to_pose_jacobian(h_position, pose.rotation().matrix())
        jacobians[1] = h_controller
        jacobians[2] = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        return residual + multipath[1:3]

    return gtsam.CustomFactor(noise, [pose_key, controller_key, multipath_key], error)


def yaw_factor_multipath(
    pose_key: int, multipath_key: int, measured_yaw_rad: float, elevation_rad: float, noise
) -> gtsam.CustomFactor:
    """:func:`yaw_residual` plus the azimuth's multipath error: the pose
    sensing solves the yaw relative to the *measured* azimuth (paper eq. 8),
    so the azimuth error ``m_1 / cos(el)`` (``m_1`` rad along ``e_az``) is
    in the measured yaw as well: ``e = wrap(yaw(R) + m_1 / cos(el) - psi_hat)``,
    between ``X(k)`` and ``M(k)``. The noise model carries the rest (the
    rotational Doppler's own error)."""
    secant = 1.0 / max(math.cos(elevation_rad), 1e-3)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        rotation = values.atPose3(this.keys()[0]).rotation().matrix()
        azimuth_error = values.atVector(this.keys()[1])[1] * secant
        if jacobians is None:
            return wrap_angle(yaw_residual(rotation, measured_yaw_rad) + azimuth_error)
        residual, h_omega = yaw_residual(rotation, measured_yaw_rad, jacobians=True)
        jacobians[0] = rotation_to_pose_jacobian(h_omega)
        jacobians[1] = np.array([[0.0, secant, 0.0]])
        return wrap_angle(residual + azimuth_error)

    return gtsam.CustomFactor(noise, [pose_key, multipath_key], error)


def gauss_markov_factor(previous_key: int, current_key: int, decay, noise) -> gtsam.CustomFactor:
    """:func:`gauss_markov_residual` between two vector states ``M(k-1)`` and ``M(k)``."""
    decay = np.asarray(decay, dtype=float).copy()

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        previous = values.atVector(this.keys()[0])
        current = values.atVector(this.keys()[1])
        if jacobians is None:
            return gauss_markov_residual(previous, current, decay)
        residual, (h_previous, h_current) = gauss_markov_residual(previous, current, decay, jacobians=True)
        jacobians[0] = h_previous
        jacobians[1] = h_current
        return residual

    return gtsam.CustomFactor(noise, [previous_key, current_key], error)


def yaw_factor(pose_key: int, measured_yaw_rad: float, noise) -> gtsam.CustomFactor:
    """:func:`yaw_residual` on the pose ``X(k)``."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        rotation = values.atPose3(this.keys()[0]).rotation().matrix()
        if jacobians is None:
            return yaw_residual(rotation, measured_yaw_rad)
        residual, h_omega = yaw_residual(rotation, measured_yaw_rad, jacobians=True)
        jacobians[0] = rotation_to_pose_jacobian(h_omega)
        return residual

    return gtsam.CustomFactor(noise, [pose_key], error)


def height_factor(pose_key: int, offset_key: int, measured_height_m: float, noise) -> gtsam.CustomFactor:
    """:func:`height_residual` between the pose ``X(k)`` and the barometer offset ``O(k)``."""

    def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        pose = values.atPose3(this.keys()[0])
        offset = values.atDouble(this.keys()[1])
        if jacobians is None:
            return height_residual(pose.translation()[2], offset, measured_height_m)
        residual, (h_height, h_offset) = height_residual(
            pose.translation()[2], offset, measured_height_m, jacobians=True
        )
        # p_z = e_z^T t: its world-position Jacobian is e_z^T.
        jacobians[0] = position_to_pose_jacobian(h_height @ np.array([[0.0, 0.0, 1.0]]), pose.rotation().matrix())
        jacobians[1] = h_offset
        return residual

    return gtsam.CustomFactor(noise, [pose_key, offset_key], error)


__all__ = [
    "direction",
    "direction_basis",
    "direction_factor",
    "direction_factor_multipath",
    "direction_residual",
    "direction_sigmas",
    "gauss_markov_factor",
    "gauss_markov_residual",
    "height_factor",
    "height_residual",
    "position_to_pose_jacobian",
    "range_factor",
    "range_factor_multipath",
    "range_residual",
    "rotation_to_pose_jacobian",
    "wrap_angle",
    "yaw_factor",
    "yaw_factor_multipath",
    "yaw_of",
    "yaw_residual",
]
