"""Divergence of the fusion: when to stop trusting the smoother, and where to restart it.

A smoother that has run away (a controller at 1e108 m behind reflecting
walls, a drone at -49169 m after a log that began without its first
seconds of IMU) does not come back by itself: each new row is gated against
the wrong state, or pulls a wrong linearisation further. Two witnesses say
it has happened:

1. **Physical bounds** (:func:`physical_violation`): a speed above
   ``max_speed_m_s``, a controller farther than ``max_controller_range_m``
   from the drone, a drone farther than ``max_position_m`` from the take-off
   point. Such a solve is refused (the row is declined) and never output.
2. **Persistent innovations beyond their gate** (:class:`GateMonitor`):
   the range or the direction gated on at least ``divergence_gated_fraction``
   of the last ``divergence_window_epochs`` epochs. A single multipath
   outlier is gated and forgotten; a state that disagrees with every row
   is the state's fault.

Either restarts the smoother *from the features and the barometer*
(:func:`position_from_features`): the position the row gives from the
controller estimate, the height the barometer gives, a wide velocity
prior; not from the IMU's prediction, which is the diverged state itself.
A divergence counts as recovered once ``recovery_epochs`` epochs in a row
pass after the restart without another.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from scattertrack.fusion import factors


def physical_violation(position, velocity, controller, *, max_speed_m_s: float, max_controller_range_m: float, max_position_m: float) -> str | None:
    """The first physical bound a state breaks, as text, or None.

    ``position`` and ``controller`` m (world, origin at take-off),
    ``velocity`` m/s. Non-finite values break every bound.
    """
    position = np.asarray(position, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    controller = np.asarray(controller, dtype=float)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity)) and np.all(np.isfinite(controller))):
        return "non-finite state"
    speed = float(np.linalg.norm(velocity))
    if speed > max_speed_m_s:
        return f"drone at {speed:.3g} m/s (bound {max_speed_m_s:g} m/s)"
    reach = float(np.linalg.norm(controller - position))
    if reach > max_controller_range_m:
        return f"controller {reach:.3g} m from the drone (bound {max_controller_range_m:g} m)"
    distance = float(np.linalg.norm(position))
    if distance > max_position_m:
        return f"drone {distance:.3g} m from the take-off point (bound {max_position_m:g} m)"
    return None


class GateMonitor:
    """Sliding window of the last ``window`` epochs: was the range or the direction gated?"""

    def __init__(self, window: int, fraction: float):
        self.window = int(window)
        self.fraction = float(fraction)
        self._gated: deque[bool] = deque(maxlen=max(self.window, 1))

    def add(self, gated: bool) -> bool:
        """Records one epoch; True when the window is full and at least
        ``fraction`` of its epochs were gated (persistently beyond the gate)."""
        self._gated.append(bool(gated))
        if self.window <= 0 or len(self._gated) < self.window:
            return False
        return sum(self._gated) >= self.fraction * self.window

    def clear(self) -> None:
        self._gated.clear()


def position_from_features(controller, range_m: float, azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """The drone's position (m, world) a feature row gives from the controller:
    ``p = rho + d u(az, el)`` (docs/formats.md section 7: the drone seen from the controller)."""
    return np.asarray(controller, dtype=float) + float(range_m) * factors.direction(azimuth_rad, elevation_rad)


def feature_position_sigmas(range_m: float, range_sigma_m: float, angle_sigma_rad: float) -> float:
    """A per-axis 1-sigma (m) for :func:`position_from_features`: the larger of
    the range's sigma and the angle's sigma times the range (the tangential
    error), one isotropic number (the restart's prior is wide on purpose)."""
    return float(max(range_sigma_m, range_m * angle_sigma_rad))


def controller_from_origin(range_m: float, azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """The controller's position (m) if the drone was at the world origin when
    it measured the row: ``rho = -d u``."""
    return -float(range_m) * factors.direction(azimuth_rad, elevation_rad)


def is_plausible_controller(controller, drone_position, max_controller_range_m: float) -> bool:
    """Whether a controller estimate is finite and within reach of the drone (m)."""
    controller = np.asarray(controller, dtype=float)
    if not np.all(np.isfinite(controller)):
        return False
    return float(np.linalg.norm(controller - np.asarray(drone_position, dtype=float))) <= max_controller_range_m and math.isfinite(
        float(np.linalg.norm(controller))
    )


__all__ = [
    "GateMonitor",
    "controller_from_origin",
    "feature_position_sigmas",
    "is_plausible_controller",
    "physical_violation",
    "position_from_features",
]
