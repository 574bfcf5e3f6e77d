"""The records of one sensing epoch: the feature row that goes in, the estimate that comes out.

Pure data (SI units, world frame: origin at take-off, z up). A
:class:`FeatureRow` is a row of ``features.csv`` (docs/formats.md section 7)
after admission, its missing sigmas replaced by the defaults; an
:class:`Estimate` is what :meth:`MarvelEstimator.add_features` returns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Estimate:
    """The estimate of one sensing epoch (world frame, SI units)."""

    time_s: float
    position: np.ndarray
    """Body origin, (3,) m."""
    velocity: np.ndarray
    """(3,) m/s."""
    orientation: np.ndarray
    """world_T_body quaternion ``(qw, qx, qy, qz)``, ``qw >= 0``."""
    sigma: np.ndarray
    """1-sigma position along the world axes, (3,) m; nan when not computed."""
    controller: np.ndarray
    """Controller position ``rho``, (3,) m."""
    controller_sigma: np.ndarray
    """1-sigma of ``rho`` along the world axes, (3,) m; nan when not computed."""
    accel_bias: np.ndarray
    """(3,) m/s^2."""
    gyro_bias: np.ndarray
    """(3,) rad/s."""
    used: dict = field(default_factory=dict)
    """Which measurements of the row entered the graph: ``range``, ``direction``, ``yaw``, ``baro``."""
    wall_time_s: float = float("nan")
    """Wall time spent in :meth:`MarvelEstimator.add_features` for this row, s."""


@dataclass(frozen=True)
class FeatureRow:
    """One admitted feature row: the controller's view of the drone at ``time_s`` (s).

    ``range_m`` (m), ``azimuth_rad`` and ``elevation_rad`` (rad) finite;
    ``yaw_rad`` None when the row has none (or yaw is not used); the
    sigmas are the row's own where finite and positive, else the defaults.
    """

    time_s: float
    range_m: float
    azimuth_rad: float
    elevation_rad: float
    yaw_rad: float | None
    range_sigma_m: float
    angle_sigma_rad: float
    yaw_sigma_rad: float

    @property
    def restart_row(self) -> tuple[float, float, float, float | None]:
        """``(range m, azimuth rad, elevation rad, yaw rad or None)``: what a
        restart from the features needs (:mod:`scattertrack.fusion.restart`)."""
        return (self.range_m, self.azimuth_rad, self.elevation_rad, self.yaw_rad)


def finite_or(value: float, default: float) -> float:
    """``value`` when it is finite and positive (a usable sigma), else ``default``."""
    return float(value) if value is not None and math.isfinite(value) and value > 0.0 else default


__all__ = ["Estimate", "FeatureRow", "finite_or"]
