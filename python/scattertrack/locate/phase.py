"""A static tag's position from carrier phase: coherence over positions (pure functions).

The calibrated scene leaves, per read k of one tag, the phasor

    z_k = exp(j m (φ_k − θ_a − θ_ch))  ≈  exp(j m (s 4π f_k d_k(p) / c + θ_tag))

with m = 2π/P and θ_tag the tag's own (unknown) offset. Profiling θ_tag
out, a position p explains the reads as well as their coherence

    R(p) = |Σ_k z_k exp(−j ψ_k(p))| / n,   ψ_k(p) = m s 4π f_k d_k(p) / c

says (1 for a perfect fit). Under von Mises noise of concentration κ the
profile log-likelihood is κ n R(p) + const, so R ranks candidate positions.

* **Hop ranging.** One antenna's reads over hop channels give its range:
  the per-antenna spectrum Rₐ(d) = |Σ_{k∈a} z_k exp(−j m s 4π f_k d / c)|
  peaks at the range, with a width of c/(2 B) for a band B (6 m for the
  US band) and no ambiguity within c/(2 · 500 kHz) = 300 m; the peak's
  centre is good to a few centimetres with a hundred reads.
* **Carrier refinement.** Near that, R(p) has a lattice of local maxima
  (λ/2 apart along each antenna's direction); each is refined by
  Gauss–Newton on the wrapped residuals, the offset re-profiled at each
  step.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import SPEED_OF_LIGHT

FOUR_PI_OVER_C = 4.0 * np.pi / SPEED_OF_LIGHT


def coherence(z: np.ndarray, wavenumber: np.ndarray, anchors: np.ndarray, points: np.ndarray) -> np.ndarray:
    """R(p) at each of ``points`` (n_points, 3) for reads with phasors ``z`` (n,),
    ``wavenumber`` = m s 4π f / c (rad/m, n) and antenna positions ``anchors`` (n, 3)."""
    distance = np.linalg.norm(points[:, None, :] - anchors[None, :, :], axis=2)  # (points, reads)
    return np.abs(np.exp(-1j * wavenumber[None, :] * distance) @ z) / len(z)


def range_spectrum(z: np.ndarray, wavenumber: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Rₐ(d) for one antenna's reads at each of ``ranges`` (m)."""
    return np.abs(np.exp(-1j * np.outer(ranges, wavenumber)) @ z) / len(z)


def hop_range(z: np.ndarray, wavenumber: np.ndarray, max_range_m: float) -> tuple[float, float]:
    """One antenna's range from its reads over several channels: (range m, 1-sigma m).

    A coarse scan at a tenth of the peak's width, then the parabola through
    the best three points. The sigma is the Cramér–Rao bound of a range
    from a phase slope: σ_φ / (std(k) √n), k the reads' wavenumbers
    m s 4π f / c, with σ_φ from the peak's coherence (R = exp(−σ²/2) for
    wrapped normal noise).
    """
    spread = float(np.std(wavenumber))
    if spread <= 0.0 or len(z) < 3:
        return float("nan"), float("inf")
    width = 1.0 / spread  # m: the peak's width in range
    step = 0.1 * width
    ranges = np.arange(0.0, max_range_m + step, step)
    spectrum = range_spectrum(z, wavenumber, ranges)
    best = float(ranges[int(np.argmax(spectrum))])
    # Gauss–Newton on the wrapped residuals (the offset re-profiled): the
    # phase slope against k is the range; a few steps from the scan's best.
    centred = wavenumber - wavenumber.mean()
    for _ in range(5):
        rotated = z * np.exp(-1j * wavenumber * best)
        residual = np.angle(rotated * np.exp(-1j * np.angle(np.sum(rotated))))
        best += float(np.dot(centred, residual) / np.dot(centred, centred))
    peak = float(range_spectrum(z, wavenumber, np.array([best]))[0])
    sigma_phase = np.sqrt(max(-2.0 * np.log(max(peak, 1e-6)), 1e-6))
    return float(best), float(sigma_phase / (spread * np.sqrt(len(z))))


def refine(z: np.ndarray, wavenumber: np.ndarray, anchors: np.ndarray, start: np.ndarray, axes: int = 3, iterations: int = 8) -> tuple[np.ndarray, float]:
    """The local maximum of R(p) near ``start``: (position, its R).

    Gauss–Newton on r_k = arg(z_k e^{−jψ_k(p)} e^{−jθ}) with θ re-profiled
    each step; the offset's column is removed by centring the Jacobian.
    ``axes`` = 2 keeps z fixed (a planar scene).
    """
    p = np.array(start, dtype=np.float64)
    for _ in range(iterations):
        offset = p[None, :] - anchors
        distance = np.linalg.norm(offset, axis=1)
        u = offset / distance[:, None]
        rotated = z * np.exp(-1j * wavenumber * distance)
        theta = np.angle(np.sum(rotated))
        r = np.angle(rotated * np.exp(-1j * theta))
        jacobian = (wavenumber[:, None] * u)[:, :axes]
        jacobian = jacobian - jacobian.mean(axis=0)
        step, *_ = np.linalg.lstsq(jacobian, r, rcond=None)
        p[:axes] += step
        if np.linalg.norm(step) < 1e-6:
            break
    return p, float(coherence(z, wavenumber, anchors, p[None, :])[0])


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
