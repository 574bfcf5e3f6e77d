"""Analytic flights for the fusion tests: truth, IMU and features made here.

The drone rests at the origin, climbs vertically (minimum-jerk) to its
altitude, then flies a horizontal circle whose angular rate ramps up
smoothly (minimum-jerk) to ``speed / radius``, yaw following the velocity.
Attitude is quadrotor kinematics (body z along the specific force), so the
IMU's specific force ``R^T (a + g e_z)`` comes from the analytic
acceleration and the gyro from the rotation's derivative (central
difference of the log map over 2e-5 s: error ~1e-9 rad/s). Features are the
exact range/direction/yaw from the controller plus Gaussian noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np
import pytest

from scattertrack.io.types import Features, Imu

GRAVITY = 9.80665


def _minimum_jerk(s):
    """Position, rate and acceleration of the 0 -> 1 minimum-jerk profile at s in [0, 1]."""
    s = min(max(s, 0.0), 1.0)
    return (10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3)


@dataclass
class CircleFlight:
    radius_m: float = 4.0
    speed_m_s: float = 1.5
    altitude_m: float = 2.0
    rest_s: float = 0.5
    climb_s: float = 3.0
    ramp_s: float = 3.0

    def kinematics(self, t: float):
        """Position (m), velocity (m/s), acceleration (m/s^2) and yaw (rad) at t (s)."""
        # Vertical: minimum-jerk climb.
        s, ds, dds = _minimum_jerk((t - self.rest_s) / self.climb_s)
        z = self.altitude_m * s
        vz = self.altitude_m * ds / self.climb_s
        az = self.altitude_m * dds / self.climb_s**2
        # Circle angle theta: its rate ramps 0 -> omega with a minimum-jerk profile.
        omega = self.speed_m_s / self.radius_m
        tau = (t - self.rest_s - self.climb_s) / self.ramp_s
        if tau <= 0.0:
            theta, rate, rate_dot = 0.0, 0.0, 0.0
        elif tau < 1.0:
            m, dm, _ = _minimum_jerk(tau)
            theta = omega * self.ramp_s * (2.5 * tau**4 - 3 * tau**5 + tau**6)
            rate, rate_dot = omega * m, omega * dm / self.ramp_s
        else:
            theta = omega * (0.5 * self.ramp_s + (tau - 1.0) * self.ramp_s)
            rate, rate_dot = omega, 0.0
        r = self.radius_m
        c, sn = math.cos(theta), math.sin(theta)
        # Centre at (-r, 0): the circle starts at the origin heading +y.
        position = np.array([-r + r * c, r * sn, z])
        velocity = np.array([-r * rate * sn, r * rate * c, vz])
        accel = np.array(
            [-r * rate_dot * sn - r * rate**2 * c, r * rate_dot * c - r * rate**2 * sn, az]
        )
        return position, velocity, accel, theta + math.pi / 2

    def rotation(self, t: float) -> np.ndarray:
        """world_T_body rotation: body z along the specific force, heading ``yaw``."""
        _, _, accel, yaw = self.kinematics(t)
        thrust = accel + np.array([0.0, 0.0, GRAVITY])
        z_b = thrust / np.linalg.norm(thrust)
        heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        y_b = np.cross(z_b, heading)
        y_b /= np.linalg.norm(y_b)
        x_b = np.cross(y_b, z_b)
        return np.column_stack([x_b, y_b, z_b])

    def gyro(self, t: float, h: float = 1e-5) -> np.ndarray:
        before, after = gtsam.Rot3(self.rotation(t - h)), gtsam.Rot3(self.rotation(t + h))
        return gtsam.Rot3.Logmap(before.between(after)) / (2 * h)


@dataclass
class Synthetic:
    imu: Imu
    features: Features
    controller: np.ndarray
    truth_time: np.ndarray  # (n,) feature epochs, s
    truth_position: np.ndarray  # (n, 3) m
    truth_rotation: np.ndarray  # (n, 3, 3)
    raw_position: np.ndarray  # (n, 3) features alone with the TRUE controller position, m


def make_flight(
    duration_s: float = 20.0,
    seed: int = 0,
    controller=(2.0, -14.0, 1.0),
    range_sigma: float = 0.5,
    angle_sigma: float = 0.05,
    yaw_sigma: float = 0.1,
    imu_rate_hz: float = 100.0,
    feature_rate_hz: float = 10.0,
    flight: CircleFlight | None = None,
) -> Synthetic:
    """A noisy take-off-and-circle flight (IMU noise: docs/marvel.md section 3)."""
    flight = flight or CircleFlight()
    rng = np.random.default_rng(seed)
    controller = np.asarray(controller, dtype=float)
    dt = 1.0 / imu_rate_hz
    imu_time = np.arange(0.0, duration_s + 1e-9, dt)
    n = len(imu_time)
    accel = np.empty((n, 3))
    gyro = np.empty((n, 3))
    height = np.empty(n)
    for i, t in enumerate(imu_time):
        position, _, acceleration, _ = flight.kinematics(t)
        rotation = flight.rotation(t)
        accel[i] = rotation.T @ (acceleration + np.array([0.0, 0.0, GRAVITY]))
        gyro[i] = flight.gyro(t)
        height[i] = position[2]
    # White noise sigma = density * sqrt(rate); biases: initial draw plus random walk.
    accel_bias = rng.normal(0.0, 0.02, 3) + np.cumsum(rng.normal(0.0, 1.0e-4 * math.sqrt(dt), (n, 3)), axis=0)
    gyro_bias = rng.normal(0.0, 0.002, 3) + np.cumsum(rng.normal(0.0, 2.0e-5 * math.sqrt(dt), (n, 3)), axis=0)
    accel = accel + accel_bias + rng.normal(0.0, 1.0e-3 * math.sqrt(imu_rate_hz), (n, 3))
    gyro = gyro + gyro_bias + rng.normal(0.0, 8.7e-5 * math.sqrt(imu_rate_hz), (n, 3))
    baro_offset = 37.0 + np.cumsum(rng.normal(0.0, 0.02 * math.sqrt(dt), n))
    baro = height + baro_offset + rng.normal(0.0, 0.1, n)
    imu = Imu(time_s=imu_time, accel=accel, gyro=gyro, baro_z=baro)

    feature_time = np.arange(0.05, duration_s, 1.0 / feature_rate_hz)
    m = len(feature_time)
    truth_position = np.empty((m, 3))
    truth_rotation = np.empty((m, 3, 3))
    for j, t in enumerate(feature_time):
        truth_position[j] = flight.kinematics(t)[0]
        truth_rotation[j] = flight.rotation(t)
    delta = truth_position - controller
    distance = np.linalg.norm(delta, axis=1)
    azimuth = np.arctan2(delta[:, 1], delta[:, 0]) + rng.normal(0.0, angle_sigma, m)
    elevation = np.arcsin(delta[:, 2] / distance) + rng.normal(0.0, angle_sigma, m)
    range_m = distance + rng.normal(0.0, range_sigma, m)
    yaw = np.arctan2(truth_rotation[:, 1, 0], truth_rotation[:, 0, 0]) + rng.normal(0.0, yaw_sigma, m)
    yaw = np.pi - np.mod(np.pi - yaw, 2 * np.pi)
    features = Features(
        time_s=feature_time,
        range_m=range_m,
        azimuth_rad=azimuth,
        elevation_rad=elevation,
        yaw_rad=yaw,
        range_sigma_m=np.full(m, range_sigma),
        angle_sigma_rad=np.full(m, angle_sigma),
        yaw_sigma_rad=np.full(m, yaw_sigma),
    )
    unit = np.column_stack(
        [np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)]
    )
    raw = controller + range_m[:, None] * unit
    return Synthetic(imu, features, controller, feature_time, truth_position, truth_rotation, raw)


def truncate(data: Synthetic, end_s: float) -> tuple[Imu, Features]:
    """IMU samples and feature rows at or before ``end_s`` (s)."""
    keep_imu = data.imu.time_s <= end_s
    keep = data.features.time_s <= end_s
    imu = Imu(data.imu.time_s[keep_imu], data.imu.accel[keep_imu], data.imu.gyro[keep_imu], data.imu.baro_z[keep_imu])
    f = data.features
    features = Features(
        f.time_s[keep], f.range_m[keep], f.azimuth_rad[keep], f.elevation_rad[keep], f.yaw_rad[keep],
        f.range_sigma_m[keep], f.angle_sigma_rad[keep], f.yaw_sigma_rad[keep],
    )
    return imu, features


def rotation_errors_deg(quaternions: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Geodesic angle (deg) between estimated ``(qw, qx, qy, qz)`` and true rotation matrices."""
    out = np.empty(len(quaternions))
    for i, (q, r) in enumerate(zip(quaternions, rotations)):
        estimated = gtsam.Rot3(*q)
        out[i] = math.degrees(np.linalg.norm(gtsam.Rot3.Logmap(estimated.between(gtsam.Rot3(r)))))
    return out


@pytest.fixture(scope="session")
def circle_flight() -> Synthetic:
    """20 s: 0.5 s rest, 3 s climb to 2 m, then a 4 m circle at up to 1.5 m/s."""
    return make_flight(duration_s=20.0, seed=1)


@pytest.fixture(scope="session")
def flight_factory():
    """:func:`make_flight`, for tests that need their own variant."""
    return make_flight


@pytest.fixture(scope="session")
def truncate_flight():
    """:func:`truncate`."""
    return truncate


@pytest.fixture(scope="session")
def rotation_errors():
    """:func:`rotation_errors_deg`."""
    return rotation_errors_deg


@pytest.fixture(scope="session")
def lift_off_flight() -> Synthetic:
    """20 s of the same flight whose log begins 0.3 s into the climb: no rest
    on the ground, the drone already rising (the outside lift-off case's start)."""
    return make_flight(duration_s=20.0, seed=3, flight=CircleFlight(rest_s=-0.3))
