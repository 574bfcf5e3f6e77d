"""Phase calibration from reference tags: sign, period and offsets (pure functions).

The monostatic phase model (``docs/formats.md``, the scene's ``[reader]``):

    φ_k = s · 4π f_k d_k / c + θ_a + θ_ch + θ_tag + ε_k   (mod P)

for read k of a reference tag at a known distance d_k from its antenna a,
on carrier f_k of channel ch. s ∈ {+1, −1} is the reader's phase sign and
P ∈ {2π, π} its period. Only sums of offsets are identifiable: a constant
moved from every θ_ch into every θ_a (or from θ_a into θ_tag) changes no
prediction, so the antenna offsets are stated relative to the channels'
and each reference tag's own offset is estimated and dropped (the first
reference's is 0).

Everything works on the unit circle: with m = 2π/P, the read is the unit
phasor z_k = exp(j m φ_k), and a model explains the reads as well as the
mean resultant length R = |mean_k exp(j m (φ_k − model_k))| says: 1 for
a perfect fit, about 1/√n for phases that carry no geometry at all. The
offsets are the circular means of the residual phasors, found by
alternating over antennas, channels and tags (each step can only raise R:
it is coordinate ascent on Σ cos(residual)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scattertrack.physics import SPEED_OF_LIGHT

ITERATIONS = 30
"""Coordinate-ascent sweeps over the offsets (converged well before on our cases)."""


def round_trip_phase(frequency_hz: np.ndarray, distance_m: np.ndarray) -> np.ndarray:
    """4π f d / c: the geometric phase of a monostatic read, radians (not wrapped)."""
    return 4.0 * np.pi * np.asarray(frequency_hz, dtype=np.float64) * np.asarray(distance_m, dtype=np.float64) / SPEED_OF_LIGHT


def looks_mod_pi(phase_rad: np.ndarray, minimum_reads: int = 50) -> bool:
    """Whether a reader reports phase mod π: enough reads, none of them at or above π.

    A 2π reader puts half its phases above π; the chance that ``n`` uniform
    phases all fall below is 2⁻ⁿ, negligible at 50.
    """
    phase = np.asarray(phase_rad, dtype=np.float64)
    return phase.size >= minimum_reads and bool(np.all(phase < np.pi + 1e-6))


def mean_resultant(phasors: np.ndarray) -> complex:
    """The mean of unit phasors (its modulus is the coherence R, its angle the circular mean)."""
    return complex(np.mean(phasors)) if phasors.size else 0j


def group_means(phasors: np.ndarray, group: np.ndarray, count: int) -> np.ndarray:
    """Per group g < ``count``: the sum of the phasors in it (complex, 0 for an empty group)."""
    sums = np.zeros(count, dtype=complex)
    np.add.at(sums, group, phasors)
    return sums


@dataclass
class OffsetFit:
    """Offsets on the circle of m·φ (radians in (−π, π]) and how well they fit."""

    antenna: np.ndarray
    channel: np.ndarray
    tag: np.ndarray
    coherence: float
    """R of the residuals after the fit."""
    residual: np.ndarray
    """Per read, m·(φ − model) wrapped to (−π, π]."""


def fit_offsets(
    residual_rad: np.ndarray,
    antenna: np.ndarray,
    channel: np.ndarray,
    tag: np.ndarray,
    counts: tuple[int, int, int],
    iterations: int = ITERATIONS,
) -> OffsetFit:
    """θ_a + θ_ch + θ_tag that best explain ``residual_rad`` (already on the m-circle:
    m·(φ − s·4πfd/c)), indices per read into ``counts`` = (antennas, channels, tags).

    Coordinate ascent: each offset in turn becomes the circular mean of what
    the others leave. The first tag's offset is held at 0 and the channels'
    offsets have circular mean 0 (the free constants of the model).
    """
    n_antennas, n_channels, n_tags = counts
    z = np.exp(1j * np.asarray(residual_rad, dtype=np.float64))
    theta_a = np.zeros(n_antennas)
    theta_c = np.zeros(n_channels)
    theta_t = np.zeros(n_tags)
    for _ in range(iterations):
        left = z * np.exp(-1j * (theta_c[channel] + theta_t[tag]))
        theta_a = np.angle(group_means(left, antenna, n_antennas))
        left = z * np.exp(-1j * (theta_a[antenna] + theta_t[tag]))
        theta_c = np.angle(group_means(left, channel, n_channels))
        left = z * np.exp(-1j * (theta_a[antenna] + theta_c[channel]))
        theta_t = np.angle(group_means(left, tag, n_tags))
        # The free constants: the first tag at 0, the channels' mean at 0.
        theta_a = theta_a + theta_t[0]
        theta_t = theta_t - theta_t[0]
        shift = np.angle(np.mean(np.exp(1j * theta_c)))
        theta_c = theta_c - shift
        theta_a = theta_a + shift
    model = theta_a[antenna] + theta_c[channel] + theta_t[tag]
    residual = np.angle(z * np.exp(-1j * model))
    coherence = abs(mean_resultant(np.exp(1j * residual)))
    return OffsetFit(np.angle(np.exp(1j * theta_a)), np.angle(np.exp(1j * theta_c)), theta_t, coherence, residual)


def chance_coherence(
    antenna: np.ndarray, channel: np.ndarray, tag: np.ndarray, counts: tuple[int, int, int], seed: int = 0
) -> float:
    """The coherence the same offsets reach on phases that carry no geometry:
    the fit run on uniform random phases with the reads' own grouping (one
    seeded draw). A calibrated model must beat it clearly to be worth anything."""
    rng = np.random.default_rng(seed)
    random_phase = rng.uniform(-np.pi, np.pi, size=len(antenna))
    return fit_offsets(random_phase, antenna, channel, tag, counts).coherence
