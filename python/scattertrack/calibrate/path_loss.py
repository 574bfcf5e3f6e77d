"""RSSI path loss per antenna from reference tags (log-distance model).

    RSSI = P₀ − 10 n log₁₀(d / 1 m) + X,   X ~ N(0, σ²)   (dBm)

fitted by least squares per antenna on the references' reads: P₀ the
power at 1 m (dBm), n the exponent (2 in free space for one way; a
monostatic backscatter link is two-way, 4 in free space), σ the spread
(dB) that ranging from RSSI must assume. With one distance per antenna (a
single static reference) n is not identifiable: the free-space value is
kept and said so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FREE_SPACE_EXPONENT = 4.0
"""A monostatic backscatter link loses 40 dB per decade of range in free space (two-way)."""


@dataclass
class PathLoss:
    reference_dbm: float
    """P₀: RSSI at 1 m, dBm."""
    exponent: float
    """n."""
    sigma_db: float
    """Spread of the residuals, dB."""
    reads: int
    fitted_exponent: bool
    """False when the distances did not spread enough to fit n (free-space n kept)."""


def fit_path_loss(rssi_dbm: np.ndarray, distance_m: np.ndarray, minimum_decades: float = 0.05) -> PathLoss | None:
    """The log-distance model of one antenna's reads; None without finite RSSI."""
    rssi = np.asarray(rssi_dbm, dtype=np.float64)
    distance = np.asarray(distance_m, dtype=np.float64)
    keep = np.isfinite(rssi) & (distance > 0)
    if np.count_nonzero(keep) < 3:
        return None
    x = np.log10(distance[keep])
    y = rssi[keep]
    fitted = bool(np.ptp(x) >= minimum_decades)
    if fitted:
        slope, intercept = np.polyfit(x, y, 1)
        exponent = -slope / 10.0
    else:
        exponent = FREE_SPACE_EXPONENT
        intercept = float(np.mean(y + 10.0 * exponent * x))
    residual = y - (intercept - 10.0 * exponent * x)
    dof = max(len(y) - (2 if fitted else 1), 1)
    return PathLoss(float(intercept), float(exponent), float(np.sqrt(np.sum(residual**2) / dof)), int(len(y)), fitted)
