"""The phase model of a static tag's reads, and the covariance of a phase fit.

The calibrated scene leaves, per read k of one tag, the phasor

    z_k = exp(j m (φ_k − θ_a − θ_ch))  ≈  exp(j m (s 4π f_k d_k(p) / c + θ_tag))

with m = 2π/P and θ_tag the tag's own, unknown offset. With k_k =
m s 4π f_k / c (rad/m), a position p explains the reads as well as their
coherence R(p) = |Σ_k z_k exp(−j k_k d_k(p))| / n says, θ_tag profiled out.
The search over p (hop ranging, the grid, Gauss–Newton refinement) is in
the Rust core, ``scattertrack_core::locate`` (``_core.locate_search``,
``_core.locate_hop_range``); this module keeps what the Python side adds:
the covariance of a fit.
"""

from __future__ import annotations

import numpy as np

from scattertrack.physics import FOUR_PI_OVER_C


def fisher_covariance(wavenumber: np.ndarray, anchors: np.ndarray, p: np.ndarray, sigma_rad: float, axes: int = 3) -> np.ndarray:
    """Position covariance (axes × axes, m²) of the phase fit at ``p``: σ² (J̃ᵀ J̃)⁻¹
    with J̃ the Jacobian centred over reads (the tag's offset is a nuisance)."""
    offset = p[None, :] - anchors
    u = offset / np.linalg.norm(offset, axis=1)[:, None]
    jacobian = (wavenumber[:, None] * u)[:, :axes]
    jacobian = jacobian - jacobian.mean(axis=0)
    information = jacobian.T @ jacobian / (sigma_rad * sigma_rad)
    try:
        return np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return np.full((axes, axes), np.inf)
