"""The RSSI cue: ranges from the calibrated log-distance path loss (pure functions).

Per antenna a (``[calibration] path_loss``): RSSI = P₀ₐ − 10 nₐ log₁₀ d + X,
X ~ N(0, σₐ²). A tag's log-likelihood at p sums over its reads; the
posterior over a grid of the region (flat prior) gives the RSSI-only
position as its mean and its covariance — decimetres to a metre, and
honest about it, because the spread is the posterior's own.
"""

from __future__ import annotations

import numpy as np

from scattertrack.locate.candidate import Candidate

GRID_STEP_M = 0.05


def models(calibration: dict) -> dict:
    """Antenna id -> (P₀ dBm, n, σ dB) from a ``[calibration]`` table."""
    found = {}
    for entry in calibration.get("path_loss", []) or []:
        if isinstance(entry, dict) and {"antenna", "reference_dbm", "exponent", "sigma_db"} <= set(entry):
            found[int(entry["antenna"])] = (float(entry["reference_dbm"]), float(entry["exponent"]), max(float(entry["sigma_db"]), 0.1))
    return found


def _log_likelihood(path_loss: dict, antenna: np.ndarray, rssi_dbm: np.ndarray, anchors: np.ndarray, points: np.ndarray, per_read: bool) -> np.ndarray:
    """Σ over antennas of −½ w (x̄ − μ(p))² / σ² at each of ``points``, with x̄ the
    antenna's mean RSSI, μ(p) its path-loss prediction and w its number of
    reads (``per_read``) or 1 (its reads count as one: see :func:`locate`).
    Reads without RSSI or without a model are skipped.

    Σ (x − μ)² = Σ (x − x̄)² + N (x̄ − μ)²: the first term does not depend on p."""
    keep = np.isfinite(rssi_dbm) & np.isin(antenna, list(path_loss))
    total = np.zeros(len(points))
    for a in np.unique(antenna[keep]):
        rows = keep & (antenna == a)
        p0, n, sigma = path_loss[int(a)]
        distance = np.maximum(np.linalg.norm(points - anchors[rows][0][None, :], axis=1), 0.05)
        weight = np.count_nonzero(rows) if per_read else 1.0
        total += -0.5 * weight * (rssi_dbm[rows].mean() - (p0 - 10.0 * n * np.log10(distance))) ** 2 / sigma**2
    return total


def log_likelihood(path_loss: dict, antenna: np.ndarray, rssi_dbm: np.ndarray, anchors: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Σ_k log N(RSSI_k; P₀ − 10 n log₁₀ d_k(p), σ²) at each of ``points``, up to a constant
    (reads without RSSI or model skipped)."""
    return _log_likelihood(path_loss, antenna, rssi_dbm, anchors, points, per_read=True)


def locate(path_loss: dict, antenna: np.ndarray, rssi_dbm: np.ndarray, anchors: np.ndarray, low: np.ndarray, high: np.ndarray, dimensions: int):
    """The RSSI-only :class:`~scattertrack.locate.Candidate`: the grid posterior's mean and covariance.

    The readings of one antenna are correlated (the same multipath and tag
    orientation for a static tag), so an antenna's reads count as one
    independent reading per antenna: the spread σₐ, not σₐ/√N, sets the width.
    """
    axes = [np.arange(lo, hi + 0.5 * GRID_STEP_M, GRID_STEP_M) if hi > lo else np.array([lo]) for lo, hi in zip(low, high)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    loglik = _log_likelihood(path_loss, antenna, rssi_dbm, anchors, points, per_read=False)
    weight = np.exp(loglik - loglik.max())
    weight /= weight.sum()
    mean = weight @ points
    centred = points - mean
    covariance = (centred * weight[:, None]).T @ centred
    # The grid's own resolution, so that a sharp posterior never claims less.
    covariance += np.diag([GRID_STEP_M**2 / 12.0 if hi > lo else 0.0 for lo, hi in zip(low, high)])
    return Candidate(mean, covariance, 1.0, "rssi")
