"""Rotations as plain vectorised numpy functions (docs/marvel.md section 1).

Conventions: Hamilton unit quaternions ``q = (qw, qx, qy, qz)`` in the last
axis of an array of any leading shape, ``q = world_T_body`` so that
``p_W = R(q) p_B``. Rotation matrices have shape ``(..., 3, 3)``. Yaw is the
heading of body x about world +z, ``yaw = atan2(R[1, 0], R[0, 0])``, and
the Euler convention is ZYX (``R = Rz(yaw) Ry(pitch) Rx(roll)``), the one
whose yaw is exactly that heading. Angles in radians.

Nothing here loops over samples: every function takes arrays of any leading
shape, so the simulator and the fusion can share them.
"""

from __future__ import annotations

import numpy as np

from scattertrack.physics import wrap_angle


def quat_multiply(p, q) -> np.ndarray:
    """Hamilton product ``p * q`` (rotate by q first, then by p), shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_conjugate(q) -> np.ndarray:
    """The inverse rotation of a unit quaternion, shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q) -> np.ndarray:
    """``q / |q|`` along the last axis."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) (normalised first)."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def matrix_to_quat(matrix) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation matrices (..., 3, 3), with ``qw >= 0``.

    Shepperd's method: of the four ways to get the quaternion from the
    matrix, each sample uses the one with the largest square root argument,
    so no branch divides by a number near zero.
    """
    m = np.asarray(matrix, dtype=float)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    # 4 * (each squared component): w^2, x^2, y^2, z^2 up to a factor.
    candidates = np.stack([trace, m00, m11, m22], axis=-1)
    best = np.argmax(candidates, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    # Branch w: s = 4 w.
    s = np.sqrt(np.maximum(1.0 + trace, 1e-300)) * 2.0
    qw = np.stack([0.25 * s, (m[..., 2, 1] - m[..., 1, 2]) / s, (m[..., 0, 2] - m[..., 2, 0]) / s,
                   (m[..., 1, 0] - m[..., 0, 1]) / s], axis=-1)
    s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    qx = np.stack([(m[..., 2, 1] - m[..., 1, 2]) / s, 0.25 * s, (m[..., 0, 1] + m[..., 1, 0]) / s,
                   (m[..., 0, 2] + m[..., 2, 0]) / s], axis=-1)
    s = np.sqrt(np.maximum(1.0 - m00 + m11 - m22, 1e-300)) * 2.0
    qy = np.stack([(m[..., 0, 2] - m[..., 2, 0]) / s, (m[..., 0, 1] + m[..., 1, 0]) / s, 0.25 * s,
                   (m[..., 1, 2] + m[..., 2, 1]) / s], axis=-1)
    s = np.sqrt(np.maximum(1.0 - m00 - m11 + m22, 1e-300)) * 2.0
    qz = np.stack([(m[..., 1, 0] - m[..., 0, 1]) / s, (m[..., 0, 2] + m[..., 2, 0]) / s,
                   (m[..., 1, 2] + m[..., 2, 1]) / s, 0.25 * s], axis=-1)
    for index, branch in enumerate((qw, qx, qy, qz)):
        pick = best == index
        q[pick] = branch[pick]
    q = np.where(q[..., :1] < 0.0, -q, q)
    return quat_normalize(q)


def rotate(q, vectors) -> np.ndarray:
    """``R(q) v`` for unit quaternions (..., 4) and vectors (..., 3) (broadcast)."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(vectors, dtype=float)
    w = q[..., :1]
    u = q[..., 1:]
    # v' = v + 2 w (u x v) + 2 u x (u x v): cheaper than building matrices.
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def quat_from_euler_zyx(yaw, pitch, roll) -> np.ndarray:
    """``q = qz(yaw) * qy(pitch) * qx(roll)``, i.e. ``R = Rz(yaw) Ry(pitch) Rx(roll)``; radians.

    The product is written out, so the result is continuous in the angles
    (no sign flips as yaw grows past pi: useful for a spinning turntable).
    """
    cy, sy = np.cos(np.asarray(yaw, float) / 2.0), np.sin(np.asarray(yaw, float) / 2.0)
    cp, sp = np.cos(np.asarray(pitch, float) / 2.0), np.sin(np.asarray(pitch, float) / 2.0)
    cr, sr = np.cos(np.asarray(roll, float) / 2.0), np.sin(np.asarray(roll, float) / 2.0)
    return np.stack(
        [
            cy * cp * cr + sy * sp * sr,
            cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr,
            sy * cp * cr - cy * sp * sr,
        ],
        axis=-1,
    )


def euler_zyx_from_quat(q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(yaw, pitch, roll) radians of unit quaternions, ZYX convention; yaw in (-pi, pi]."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    pitch = np.arcsin(np.clip(2.0 * (w * y - x * z), -1.0, 1.0))
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    return wrap_angle(yaw), pitch, roll


def yaw_of_quat(q) -> np.ndarray:
    """Heading of body x about world +z, ``atan2(R[1,0], R[0,0])``, radians in (-pi, pi]."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return wrap_angle(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def yaw_of_matrix(matrix) -> np.ndarray:
    """Heading of body x about world +z, ``atan2(R[1,0], R[0,0])``, radians in (-pi, pi]."""
    m = np.asarray(matrix, dtype=float)
    return wrap_angle(np.arctan2(m[..., 1, 0], m[..., 0, 0]))


def quat_exp(rotation_vector) -> np.ndarray:
    """Unit quaternion of a rotation vector (..., 3) (axis times angle, radians)."""
    v = np.asarray(rotation_vector, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(a/2)/a -> 1/2 as a -> 0; the series keeps full precision there.
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), scale * v], axis=-1)


def quat_log(q) -> np.ndarray:
    """Rotation vector (..., 3), radians, of unit quaternions; the angle is in [0, pi]."""
    q = quat_normalize(q)
    q = np.where(q[..., :1] < 0.0, -q, q)  # the shorter of the two equivalent rotations
    w = np.clip(q[..., :1], -1.0, 1.0)
    u = q[..., 1:]
    norm_u = np.linalg.norm(u, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(norm_u, w)
    small = norm_u < 1e-12
    scale = np.where(small, 2.0 / np.where(small, w, 1.0), angle / np.where(small, 1.0, norm_u))
    return scale * u


def angular_velocity_body(q_before, q_after, dt: float) -> np.ndarray:
    """Body-frame angular velocity (rad/s) that turns ``q_before`` into ``q_after`` in ``dt`` seconds.

    ``log(q_before^-1 q_after) / dt``: for a symmetric pair ``q(t - h)``,
    ``q(t + h)`` and ``dt = 2 h`` this is the angular velocity at ``t`` up to
    O(h^2).
    """
    return quat_log(quat_multiply(quat_conjugate(q_before), q_after)) / dt
