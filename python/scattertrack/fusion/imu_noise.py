"""How noisy the IMU really is, measured from its own samples (issue 16).

The preintegration (paper sec. IV-B, eq. 13) weighs the IMU against the
features by the white-noise densities ``accel_noise_density`` and
``gyro_noise_density``. A stated density that is too small makes the
dead reckoning look better than it is: the smoother then bends the features
to the IMU and its sigmas are too small. The samples themselves tell the
white noise apart from the motion, because a body's specific force and
angular rate are smooth at the IMU's rate while white noise is not:

    d²_k = s_{k+1} - 2 s_k + s_{k-1},    Var(d²_k) = 6 σ²   (white noise σ per sample)

and a drone's own motion adds ``s'' Δt²`` to it, a few 1e-3 m/s² at 100 Hz
for a snap of 50 m/s^4, small against any MEMS noise floor. The scale is
taken robustly, ``σ = 1.4826 median|d²| / √6`` (the median absolute
deviation of a zero-mean normal), so a manoeuvre's spikes or a knock do not
inflate it, and the density is ``N = σ √Δt`` (units/√Hz: a white noise of
density N sampled every Δt has the per-sample σ = N / √Δt, the convention of
the parameters and of GTSAM's ``setAccelerometerCovariance``). Propeller
vibration is counted as noise, which is what it is to the preintegration.

Triples whose two intervals differ by more than :data:`INTERVAL_TOLERANCE`
(a dropped sample, jitter) are left out: across unequal steps the motion's
slope no longer cancels.
"""

from __future__ import annotations

import math

import numpy as np

MAD_TO_SIGMA = 1.4826
"""σ of a zero-mean normal per median absolute value (1 / Φ⁻¹(3/4))."""
INTERVAL_TOLERANCE = 0.1
"""Relative difference of a triple's two sample intervals beyond which it is not used."""
WINDOW_SAMPLES = 1000
"""Second differences kept per sensor (each of three axes), the newest: 10 s at 100 Hz."""
MIN_SAMPLES = 50
"""Second differences (per axis) before a measurement is given: 0.5 s at 100 Hz, about ±6 % (1 σ)."""


def white_noise_density(second_differences: np.ndarray, interval_s: float) -> float:
    """The white-noise density (units/√Hz) of samples every ``interval_s`` (s)
    whose second differences are ``second_differences`` (any shape, pooled):
    ``1.4826 median|d²| / √6 · √Δt``. NaN when there are none."""
    d = np.abs(np.asarray(second_differences, dtype=float)).ravel()
    if d.size == 0 or not interval_s > 0.0:
        return math.nan
    return MAD_TO_SIGMA * float(np.median(d)) / math.sqrt(6.0) * math.sqrt(interval_s)


class ImuNoiseMeter:
    """A running measurement of the accelerometer's and gyroscope's white-noise
    densities from the newest :data:`WINDOW_SAMPLES` samples (flat ring buffers)."""

    def __init__(self, window: int = WINDOW_SAMPLES):
        self._window = int(window)
        self._accel = np.zeros((self._window, 3))
        self._gyro = np.zeros((self._window, 3))
        self._interval = np.zeros(self._window)
        self._count = 0  # second differences ever written
        self._last: list[tuple[float, np.ndarray, np.ndarray]] = []  # the newest two samples

    @property
    def samples(self) -> int:
        """Second differences in the window (per axis)."""
        return min(self._count, self._window)

    def add(self, time_s: float, accel: np.ndarray, gyro: np.ndarray) -> None:
        """One IMU sample (s, m/s^2, rad/s), in increasing time."""
        self._last.append((time_s, accel, gyro))
        if len(self._last) < 3:
            return
        (t0, a0, w0), (t1, a1, w1), (t2, a2, w2) = self._last
        self._last.pop(0)
        first, second = t1 - t0, t2 - t1
        if not (first > 0.0 and second > 0.0) or abs(second - first) > INTERVAL_TOLERANCE * min(first, second):
            return
        slot = self._count % self._window
        self._accel[slot] = a2 - 2.0 * a1 + a0
        self._gyro[slot] = w2 - 2.0 * w1 + w0
        self._interval[slot] = 0.5 * (first + second)
        self._count += 1

    def densities(self) -> tuple[float, float] | None:
        """(accelerometer m/s^2/√Hz, gyroscope rad/s/√Hz) measured over the
        window, or None before :data:`MIN_SAMPLES` second differences."""
        n = self.samples
        if n < MIN_SAMPLES:
            return None
        interval = float(np.median(self._interval[:n]))
        return white_noise_density(self._accel[:n], interval), white_noise_density(self._gyro[:n], interval)


def density_in_use(stated: float, measured: float, agreement: float) -> float:
    """The density the preintegration uses: the ``stated`` one unless the
    ``measured`` one exceeds it by more than the factor ``agreement`` (a
    measurement's own spread, and a stated margin, are not overruled); never
    below the stated one, which is the user's floor."""
    if math.isfinite(measured) and measured > agreement * stated:
        return measured
    return stated


__all__ = ["ImuNoiseMeter", "density_in_use", "white_noise_density"]
