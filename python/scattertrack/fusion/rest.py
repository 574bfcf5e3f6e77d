"""Is the drone at rest on the ground? A positive test over a window of IMU samples.

The fusion's ground factors ("at the origin, not moving, not turning",
zero-velocity and zero-rotation updates: docs/marvel.md section 8) are only
as good as the claim that the body is at rest. A log that begins as the
drone lifts off breaks the claim: the climb's acceleration then goes into
the accelerometer bias and the barometer's offset, and the height stays
near 0 while the drone climbs (measured on a lift-off log: 2.7 m mean
error). So rest is tested, never assumed; the test is the standard
zero-velocity detector of pedestrian and vehicle inertial navigation
(Skog et al., "Zero-velocity detection: an algorithm evaluation", IEEE
TBME 2010: specific force magnitude near g and low angular-rate energy
over a window), with the barometer's slope as a third witness.

At rest, for samples ``f_i`` (m/s^2), ``w_i`` (rad/s) over the window:

1. ``| |mean f| - g | <= force_tolerance`` (gravity alone; a climb's
   acceleration adds to it),
2. ``RMS(f_i - mean f) <= accel_rms_max`` (no vibration or manoeuvre),
3. ``RMS(|w_i|) <= gyro_rms_max`` (not turning; the gyroscope bias is
   inside this, so the bound is a few bias sigmas),
4. ``|slope of baro_z| <= baro_rate_max`` (m/s, least-squares line; not
   tested without barometer samples).

Pure functions: no estimator state. Units SI throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RestThresholds:
    """The four bounds of :func:`rest_test` (SI units)."""

    gravity_m_s2: float
    force_tolerance_m_s2: float
    accel_rms_m_s2: float
    gyro_rms_rad_s: float
    baro_rate_m_s: float


@dataclass(frozen=True)
class RestTest:
    """The verdict of :func:`rest_test` and the statistics behind it."""

    at_rest: bool
    reason: str
    """Empty when at rest; else the first check that failed (``"force"``,
    ``"accel_energy"``, ``"gyro_energy"``, ``"baro_slope"``, ``"too_few_samples"``)."""
    mean_force: np.ndarray
    """Mean specific force over the window, (3,) m/s^2 (its direction gives roll and pitch)."""
    force_error_m_s2: float
    """``| |mean f| - g |``, m/s^2."""
    accel_rms_m_s2: float
    gyro_rms_rad_s: float
    baro_rate_m_s: float
    """Least-squares slope of the barometer over the window, m/s (nan without samples)."""


def baro_slope(time_s, height_m) -> float:
    """Least-squares slope (m/s) of barometric heights over their times; nan for fewer than 3 samples."""
    t = np.asarray(time_s, dtype=float)
    z = np.asarray(height_m, dtype=float)
    keep = np.isfinite(t) & np.isfinite(z)
    t, z = t[keep], z[keep]
    if t.size < 3:
        return float("nan")
    centred = t - t.mean()
    spread = float(centred @ centred)
    if spread <= 0.0:
        return float("nan")
    return float(centred @ (z - z.mean()) / spread)


def rest_test(accel, gyro, thresholds: RestThresholds, baro_time_s=(), baro_z=(), min_samples: int = 5) -> RestTest:
    """Whether the IMU samples ``accel`` (n, 3) m/s^2 and ``gyro`` (n, 3) rad/s
    (and the barometer's ``baro_z`` m at ``baro_time_s`` s, optional) show a body
    at rest; see the module docstring for the four checks, made in that order."""
    accel = np.asarray(accel, dtype=float).reshape(-1, 3)
    gyro = np.asarray(gyro, dtype=float).reshape(-1, 3)
    nan = float("nan")
    if len(accel) < min_samples or len(gyro) != len(accel):
        return RestTest(False, "too_few_samples", np.full(3, nan), nan, nan, nan, nan)
    mean_force = accel.mean(axis=0)
    force_error = abs(float(np.linalg.norm(mean_force)) - thresholds.gravity_m_s2)
    accel_rms = math.sqrt(float(np.mean(np.sum((accel - mean_force) ** 2, axis=1))))
    gyro_rms = math.sqrt(float(np.mean(np.sum(gyro**2, axis=1))))
    rate = baro_slope(baro_time_s, baro_z)
    checks = (
        ("force", force_error <= thresholds.force_tolerance_m_s2),
        ("accel_energy", accel_rms <= thresholds.accel_rms_m_s2),
        ("gyro_energy", gyro_rms <= thresholds.gyro_rms_rad_s),
        ("baro_slope", not math.isfinite(rate) or abs(rate) <= thresholds.baro_rate_m_s),
    )
    failed = next((name for name, ok in checks if not ok), "")
    return RestTest(not failed, failed, mean_force, force_error, accel_rms, gyro_rms, rate)


def baro_contradicts_ground(window_mean_m: float, rest_mean_m: float, rise_m: float) -> bool:
    """Whether the barometer says the drone has left the ground: the window's
    mean height (m) is more than ``rise_m`` above (or below) the mean of the
    rest window. Either side: a barometer falling by that much is as
    incompatible with "still on the ground" as one rising."""
    if not (math.isfinite(window_mean_m) and math.isfinite(rest_mean_m)):
        return False
    return abs(window_mean_m - rest_mean_m) > rise_m


__all__ = ["RestTest", "RestThresholds", "baro_contradicts_ground", "baro_slope", "rest_test"]
