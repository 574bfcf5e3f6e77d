"""Measurement models of the fusion: values, and every Jacobian against finite differences.

The pure functions are checked with central differences in the world frame;
the GTSAM factors with gtsam's own ``numericalDerivative`` on the Pose3
manifold (its ``retract``: rotation and translation perturbed in the body
frame), so a wrong chain rule onto the manifold fails here.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, M, O, X
from gtsam.utils.numerical_derivative import (
    numericalDerivative21,
    numericalDerivative22,
    numericalDerivative31,
    numericalDerivative32,
    numericalDerivative33,
)

from scattertrack.fusion import factors

RNG = np.random.default_rng(42)
# Random but fixed states: drone ~ tens of metres from the controller, tilted body.
CASES = [
    (
        RNG.normal(0.0, 3.0, 3) + np.array([0.0, 0.0, 2.0]),
        RNG.normal(0.0, 5.0, 3) + np.array([2.0, -14.0, 1.0]),
        gtsam.Rot3.Ypr(RNG.uniform(-3.0, 3.0), RNG.uniform(-0.4, 0.4), RNG.uniform(-0.4, 0.4)),
    )
    for _ in range(5)
]


def central_difference(function, x: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """d function / d x (m, n) by central differences in each coordinate of x."""
    x = np.asarray(x, dtype=float)
    columns = []
    for j in range(len(x)):
        dx = np.zeros_like(x)
        dx[j] = step
        columns.append((np.atleast_1d(function(x + dx)) - np.atleast_1d(function(x - dx))) / (2 * step))
    return np.column_stack(columns)


def unit_noise(dim: int):
    # Unit sigmas: the linearised factor's Jacobian is then the raw one
    # (GTSAM linearises e(x + dx) ~ e + H dx into A = H, b = -e).
    return gtsam.noiseModel.Unit.Create(dim)


def linearised(factor, values):
    """Jacobian blocks of a factor, one per key in the factor's key order."""
    jacobian, _ = factor.linearize(values).jacobian()
    blocks, column = [], 0
    for key in factor.keys():
        dim = _dimension(key)
        blocks.append(jacobian[:, column : column + dim])
        column += dim
    return blocks


def _dimension(key) -> int:
    letter = chr(gtsam.Symbol(key).chr())
    return {"x": 6, "l": 3, "o": 1, "m": 3}[letter]


# --- pure models -------------------------------------------------------------


def test_wrap_angle_interval():
    angles = np.array([-math.pi, math.pi, 3 * math.pi, -3 * math.pi + 1e-9, 0.0, 7.0, -7.0])
    wrapped = factors.wrap_angle(angles)
    assert np.all(wrapped > -math.pi) and np.all(wrapped <= math.pi)
    assert wrapped[0] == pytest.approx(math.pi) and wrapped[1] == pytest.approx(math.pi)
    assert np.allclose(np.cos(wrapped), np.cos(angles)) and np.allclose(np.sin(wrapped), np.sin(angles))


def test_direction_basis_is_orthonormal_and_perpendicular():
    for azimuth, elevation in [(0.3, 0.1), (2.5, -0.7), (-1.0, 1.5)]:
        basis = factors.direction_basis(azimuth, elevation)
        u = factors.direction(azimuth, elevation)
        assert np.allclose(basis.T @ basis, np.eye(2), atol=1e-12)
        assert np.allclose(basis.T @ u, 0.0, atol=1e-12)


@pytest.mark.parametrize("position, controller, _", CASES)
def test_range_residual_jacobians(position, controller, _):
    measured = np.linalg.norm(position - controller) + 0.3
    residual, (h_position, h_controller) = factors.range_residual(position, controller, measured, jacobians=True)
    assert residual[0] == pytest.approx(-0.3)
    numeric_p = central_difference(lambda p: factors.range_residual(p, controller, measured), position)
    numeric_c = central_difference(lambda c: factors.range_residual(position, c, measured), controller)
    assert np.allclose(h_position, numeric_p, atol=1e-8)
    assert np.allclose(h_controller, numeric_c, atol=1e-8)


@pytest.mark.parametrize("position, controller, _", CASES)
def test_direction_residual_jacobians(position, controller, _):
    delta = position - controller
    azimuth = math.atan2(delta[1], delta[0]) + 0.02
    elevation = math.asin(delta[2] / np.linalg.norm(delta)) - 0.03
    residual, (h_position, h_controller) = factors.direction_residual(
        position, controller, azimuth, elevation, jacobians=True
    )
    numeric_p = central_difference(lambda p: factors.direction_residual(p, controller, azimuth, elevation), position)
    numeric_c = central_difference(lambda c: factors.direction_residual(position, c, azimuth, elevation), controller)
    assert np.allclose(h_position, numeric_p, atol=1e-8)
    assert np.allclose(h_controller, numeric_c, atol=1e-8)
    # Small-angle meaning of the residual: (cos(el) (az - az_hat), el - el_hat).
    assert residual[0] == pytest.approx(-0.02 * math.cos(elevation), abs=2e-3)
    assert residual[1] == pytest.approx(0.03, abs=2e-3)


def test_direction_residual_is_the_papers_cross_product():
    """Eq. 12: a_hat x w written in the basis (e_el, -e_az) is the residual, exactly."""
    for position, controller, _ in CASES:
        delta = position - controller
        unit = delta / np.linalg.norm(delta)
        azimuth, elevation = 0.7, -0.2
        a_hat = factors.direction(azimuth, elevation)
        e_az, e_el = factors.direction_basis(azimuth, elevation).T
        cross = np.cross(a_hat, unit)
        residual = factors.direction_residual(position, controller, azimuth, elevation)
        assert np.allclose(residual, [cross @ e_el, -cross @ e_az], atol=1e-12)
        assert cross @ a_hat == pytest.approx(0.0, abs=1e-12)  # the rank-deficient third component


def test_direction_residual_zero_at_truth():
    controller = np.array([1.0, -10.0, 0.5])
    position = np.array([3.0, 4.0, 6.0])
    delta = position - controller
    azimuth = math.atan2(delta[1], delta[0])
    elevation = math.asin(delta[2] / np.linalg.norm(delta))
    assert np.allclose(factors.direction_residual(position, controller, azimuth, elevation), 0.0, atol=1e-12)


@pytest.mark.parametrize("_, __, rotation", CASES)
def test_yaw_residual_jacobian_on_right_perturbation(_, __, rotation):
    measured = factors.yaw_of(rotation.matrix()) - 0.1
    residual, h_omega = factors.yaw_residual(rotation.matrix(), measured, jacobians=True)
    assert residual[0] == pytest.approx(0.1)
    numeric = central_difference(lambda w: factors.yaw_residual(rotation.retract(w).matrix(), measured), np.zeros(3))
    assert np.allclose(h_omega, numeric, atol=1e-7)


def test_yaw_residual_wraps():
    rotation = gtsam.Rot3.Ypr(math.pi - 0.01, 0.0, 0.0).matrix()
    assert factors.yaw_residual(rotation, -math.pi + 0.01)[0] == pytest.approx(-0.02, abs=1e-12)
    assert factors.yaw_of(gtsam.Rot3.Ypr(1.2, 0.3, -0.2).matrix()) == pytest.approx(1.2)


def test_height_residual_jacobians():
    residual, (h_height, h_offset) = factors.height_residual(2.0, 30.0, 31.5, jacobians=True)
    assert residual[0] == pytest.approx(0.5)
    numeric_z = central_difference(lambda z: factors.height_residual(z[0], 30.0, 31.5), np.array([2.0]))
    numeric_o = central_difference(lambda o: factors.height_residual(2.0, o[0], 31.5), np.array([30.0]))
    assert numeric_z[0, 0] == pytest.approx(h_height[0, 0])
    assert numeric_o[0, 0] == pytest.approx(h_offset[0, 0])


# --- GTSAM factors on the Pose3 manifold ----------------------------------------


def _pose_controller_values(pose, controller):
    values = gtsam.Values()
    values.insert(X(1), pose)
    values.insert(L(0), np.asarray(controller, dtype=float))
    return values


@pytest.mark.parametrize("position, controller, rotation", CASES)
def test_range_and_direction_factor_jacobians_on_manifold(position, controller, rotation):
    pose = gtsam.Pose3(rotation, position)
    delta = position - controller
    azimuth = math.atan2(delta[1], delta[0]) + 0.05
    elevation = math.asin(delta[2] / np.linalg.norm(delta)) + 0.04
    built = [
        factors.range_factor(X(1), L(0), float(np.linalg.norm(delta)) - 0.2, unit_noise(1)),
        factors.direction_factor(X(1), L(0), azimuth, elevation, unit_noise(2)),
    ]
    for factor in built:

        def error(p, c, factor=factor):
            return factor.unwhitenedError(_pose_controller_values(p, c))

        h_pose, h_controller = linearised(factor, _pose_controller_values(pose, controller))
        numeric_pose = numericalDerivative21(error, pose, np.asarray(controller, dtype=float))
        numeric_controller = numericalDerivative22(error, pose, np.asarray(controller, dtype=float))
        assert np.allclose(h_pose, numeric_pose, atol=1e-7)
        assert np.allclose(h_controller, numeric_controller, atol=1e-7)


@pytest.mark.parametrize("_, __, rotation", CASES)
def test_yaw_factor_jacobian_on_manifold(_, __, rotation):
    pose = gtsam.Pose3(rotation, np.array([1.0, 2.0, 3.0]))
    factor = factors.yaw_factor(X(1), factors.yaw_of(rotation.matrix()) + 0.2, unit_noise(1))

    def error(p):
        values = gtsam.Values()
        values.insert(X(1), p)
        return factor.unwhitenedError(values)

    values = gtsam.Values()
    values.insert(X(1), pose)
    (h_pose,) = linearised(factor, values)
    numeric = numericalDerivative21(lambda p, _: error(p), pose, 0.0)
    assert np.allclose(h_pose, numeric, atol=1e-7)
    assert np.allclose(numeric[:, 3:], 0.0)  # a translation does not turn the heading


def test_height_factor_jacobian_on_manifold():
    pose = gtsam.Pose3(gtsam.Rot3.Ypr(0.4, 0.2, -0.3), np.array([1.0, 2.0, 3.0]))
    factor = factors.height_factor(X(1), O(1), 40.2, unit_noise(1))

    def error(p, offset):
        values = gtsam.Values()
        values.insert(X(1), p)
        values.insert(O(1), float(np.squeeze(offset)))
        return factor.unwhitenedError(values)

    values = gtsam.Values()
    values.insert(X(1), pose)
    values.insert(O(1), 37.0)
    h_pose, h_offset = linearised(factor, values)
    numeric_pose = numericalDerivative21(error, pose, np.array([37.0]))
    numeric_offset = numericalDerivative22(error, pose, np.array([37.0]))
    assert np.allclose(h_pose, numeric_pose, atol=1e-7)
    assert np.allclose(h_offset, numeric_offset, atol=1e-7)


def test_factor_jacobian_sign_convention():
    """linearize() of a unit-noise factor returns A = H (the Jacobian) and b = -error."""
    pose = gtsam.Pose3(gtsam.Rot3(), np.array([0.0, 0.0, 0.0]))
    factor = factors.range_factor(X(1), L(0), 5.0, unit_noise(1))
    values = _pose_controller_values(pose, np.array([0.0, -10.0, 0.0]))
    jacobian, b = factor.linearize(values).jacobian()
    assert b[0] == pytest.approx(-5.0)  # -(10 - 5)
    assert jacobian[0, 4] == pytest.approx(1.0)  # d|p - rho| / d p_y = +1 (body y = world y here)


# --- multipath (Gauss-Markov) states ------------------------------------------


def test_gauss_markov_residual_jacobians():
    previous, current, decay = np.array([0.3, -0.02, 0.01]), np.array([0.25, -0.01, 0.0]), np.array([0.9, 0.5, 0.1])
    residual, (h_previous, h_current) = factors.gauss_markov_residual(previous, current, decay, jacobians=True)
    assert np.allclose(residual, current - decay * previous)
    assert np.allclose(h_previous, central_difference(lambda m: factors.gauss_markov_residual(m, current, decay), previous))
    assert np.allclose(h_current, central_difference(lambda m: factors.gauss_markov_residual(previous, m, decay), current))


@pytest.mark.parametrize("position, controller, rotation", CASES)
def test_multipath_factor_jacobians_on_manifold(position, controller, rotation):
    pose = gtsam.Pose3(rotation, position)
    multipath = np.array([0.4, -0.03, 0.02])
    delta = position - controller
    azimuth = math.atan2(delta[1], delta[0]) + 0.05
    elevation = math.asin(delta[2] / np.linalg.norm(delta)) + 0.04
    built = [
        factors.range_factor_multipath(X(1), L(0), M(1), float(np.linalg.norm(delta)) - 0.2, unit_noise(1)),
        factors.direction_factor_multipath(X(1), L(0), M(1), azimuth, elevation, unit_noise(2)),
    ]

    def values_of(p, c, m):
        values = _pose_controller_values(p, c)
        values.insert(M(1), np.asarray(m, dtype=float))
        return values

    for factor in built:

        def error(p, c, m, factor=factor):
            return factor.unwhitenedError(values_of(p, c, m))

        blocks = linearised(factor, values_of(pose, controller, multipath))
        args = (pose, np.asarray(controller, dtype=float), multipath)
        for block, derivative in zip(blocks, (numericalDerivative31, numericalDerivative32, numericalDerivative33)):
            assert np.allclose(block, derivative(error, *args), atol=1e-7)


def test_multipath_factors_add_the_error_to_the_plain_residuals():
    """Range and direction with the multipath state equal the plain residuals plus m."""
    pose = gtsam.Pose3(gtsam.Rot3.Ypr(0.3, 0.1, -0.1), np.array([1.0, 2.0, 2.0]))
    controller = np.array([0.0, -15.0, 1.0])
    multipath = np.array([0.7, 0.01, -0.02])
    values = _pose_controller_values(pose, controller)
    values.insert(M(1), multipath)
    plain_range = factors.range_factor(X(1), L(0), 16.0, unit_noise(1)).unwhitenedError(values)
    with_range = factors.range_factor_multipath(X(1), L(0), M(1), 16.0, unit_noise(1)).unwhitenedError(values)
    assert with_range[0] == pytest.approx(plain_range[0] + 0.7)
    plain = factors.direction_factor(X(1), L(0), 1.5, 0.1, unit_noise(2)).unwhitenedError(values)
    with_direction = factors.direction_factor_multipath(X(1), L(0), M(1), 1.5, 0.1, unit_noise(2)).unwhitenedError(values)
    assert np.allclose(with_direction, plain + multipath[1:])


def test_gauss_markov_factor_jacobians():
    factor = factors.gauss_markov_factor(M(1), M(2), [0.9, 0.8, 0.7], unit_noise(3))

    def error(a, b):
        values = gtsam.Values()
        values.insert(M(1), np.asarray(a, dtype=float))
        values.insert(M(2), np.asarray(b, dtype=float))
        return factor.unwhitenedError(values)

    a, b = np.array([0.1, 0.2, -0.3]), np.array([0.0, 0.1, 0.2])
    values = gtsam.Values()
    values.insert(M(1), a)
    values.insert(M(2), b)
    h_a, h_b = linearised(factor, values)
    assert np.allclose(h_a, numericalDerivative21(error, a, b), atol=1e-7)
    assert np.allclose(h_b, numericalDerivative22(error, a, b), atol=1e-7)
    assert np.allclose(error(a, b), b - np.array([0.9, 0.8, 0.7]) * a)
