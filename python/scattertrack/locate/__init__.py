"""Static tags located from every cue a calibrated scene supports, with honest sigmas.

:func:`locate` ``(scene, reads) -> list[Location]``: one :class:`Location`
per tag, its candidates best first. Where GLAC needs motion to resolve
the λ/2 ambiguity, a static tag has two other sources:

* **frequency diversity** — over hop channels, each antenna's phase slope
  against frequency is its range, to a few centimetres
  (:func:`~scattertrack.locate.phase.hop_range`); the ranges pick the
  carrier-phase lattice point, which the carrier refines to millimetres;
* **RSSI path loss** — the calibrated log-distance model per antenna
  (``[calibration] path_loss``), decimetres to a metre.

On one fixed channel neither range nor lattice is fixed by the phase alone:
every local maximum of the phase coherence in the region is a candidate,
and they are all listed (``candidate`` 2, 3, …), weighted by their
likelihood (tempered, :data:`TEMPERATURE`), with the best row's sigma
covering them. Where the phase does not follow the geometry (the scene's
calibration says phase is not usable, or the tag's own reads reach no
coherence above :data:`COHERENCE_USABLE`), the phase is not used and the
position comes from RSSI alone — never a confident phase answer from
phases that carry none.

Sigmas: the phase fit's Fisher covariance at the read-to-read noise the
fit shows, scaled for the reads' correlation (the error of real readers
wanders over about half a second, so reads within one antenna's 0.5 s
count once), plus the consider covariance of a per-antenna phase bias of
:data:`BIAS_SIGMA_RAD` (calibration residuals, wander), plus the spread of
the competing candidates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scattertrack import _core
from scattertrack.io.types import Reads, Scene
from scattertrack.locate import rssi as rssi_cue
from scattertrack.locate.phase import FOUR_PI_OVER_C, fisher_covariance

TEMPERATURE = 1.0
"""Candidate weights ∝ exp(Δℓ / T): correlated phase errors overcount evidence (as in GLAC)."""
COHERENCE_USABLE = 0.8
"""A tag whose best position explains its phases with less coherence is located by RSSI."""
BIAS_SIGMA_RAD = 0.07
"""Per-antenna phase bias left after calibration (wander, residuals), 1-sigma."""
CORRELATION_S = 0.5
"""Reads of one antenna within this long count as one independent error."""
MAX_CANDIDATES = 5
MIN_WEIGHT = 1e-3
HOPPING_SPREAD_HZ = 2e6
"""Carriers spread (std) at least this wide: the reads range by frequency diversity."""


@dataclass
class Candidate:
    position: np.ndarray
    covariance: np.ndarray
    """3×3, m²."""
    weight: float
    cue: str
    """"phase", "phase+rssi", "rssi" or "region" (no usable cue)."""
    coherence: float = math.nan


@dataclass
class Location:
    epc: str
    reads: int
    candidates: list = field(default_factory=list)
    """Best first; the first one's covariance covers the others."""
    note: str = ""
    """Why the phase was not used, when it was not."""


def _region_box(scene: Scene, anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if scene.region is not None:
        low, high = np.array(scene.region.min, float), np.array(scene.region.max, float)
    else:
        low, high = anchors.min(axis=0) - 1.0, anchors.max(axis=0) + 1.0
    if scene.dimensions == 2:
        low[2] = high[2] = float(scene.plane_z)
    return low, high


def _independent_reads(reads_time: np.ndarray, antenna: np.ndarray, wavenumber: np.ndarray) -> int:
    """Reads that carry independent errors: per antenna and channel, one per CORRELATION_S."""
    bins = np.floor(reads_time / CORRELATION_S).astype(np.int64)
    return len(set(zip(antenna.tolist(), np.round(wavenumber, 6).tolist(), bins.tolist())))


def _multilaterate(anchors: np.ndarray, ranges: np.ndarray, sigmas: np.ndarray, start: np.ndarray, axes: int) -> tuple[np.ndarray, np.ndarray]:
    p = start.astype(np.float64).copy()
    weight = 1.0 / sigmas**2
    for _ in range(20):
        offset = p[None, :] - anchors
        d = np.linalg.norm(offset, axis=1)
        u = (offset / d[:, None])[:, :axes]
        h = u.T @ (u * weight[:, None])
        step = np.linalg.lstsq(h, u.T @ (weight * (ranges - d)), rcond=None)[0]
        p[:axes] += step
        if np.linalg.norm(step) < 1e-7:
            break
    try:
        covariance = np.linalg.inv(h)
    except np.linalg.LinAlgError:
        covariance = np.full((axes, axes), np.inf)
    return p, covariance


def _phase_candidates(z, k, anchors, time_s, antenna, scene, low, high) -> list[Candidate]:
    axes = scene.dimensions
    spacing = 2.0 * np.pi / float(np.mean(np.abs(k)))  # m: ψ turns once per this much range (λ/2, λ/4 mod π)
    frequency_spread = float(np.std(np.abs(k))) / FOUR_PI_OVER_C
    hopping = frequency_spread >= HOPPING_SPREAD_HZ and len(np.unique(np.round(np.abs(k), 6))) >= 4
    box = (low, high)
    if hopping:
        centre, coarse = _hop_centre(z, k, anchors, antenna, low, high, axes)
        hopping = centre is not None and bool(np.all(np.isfinite(coarse)))
    if hopping:
        # The carrier's lattice of maxima near the hop ranges' position: the
        # box they allow (at least one lattice step each way).
        half = np.minimum(np.maximum(3.0 * np.sqrt(np.clip(np.diag(coarse), 0, None)), 0.5 * spacing), 0.5)
        half = np.r_[half, np.zeros(3 - axes)]
        box = (np.maximum(centre - half, low - 0.05), np.minimum(centre + half, high + 0.05))
    # The grid, its seeds and their refinement run in the Rust core
    # (scattertrack_core::locate::search): one call per tag.
    unique_anchors, anchor_index = np.unique(anchors, axis=0, return_inverse=True)
    positions, coherences = _core.locate_search(
        np.ascontiguousarray(z.real), np.ascontiguousarray(z.imag), np.ascontiguousarray(k),
        anchor_index.reshape(-1).astype(np.int64), np.ascontiguousarray(unique_anchors),
        tuple(float(v) for v in box[0]), tuple(float(v) for v in box[1]), axes, 100_000, 4 * MAX_CANDIDATES,
    )
    refined = [(positions[i], float(coherences[i])) for i in range(len(coherences))]
    if not refined:
        return []
    best_r = refined[0][1]
    sigma = math.sqrt(max(-2.0 * math.log(max(best_r, 1e-6)), 1e-6))
    n = len(z)
    independent = _independent_reads(time_s, antenna, k)
    kappa_n = independent / (sigma * sigma)  # the log-likelihood per unit of coherence
    loglik = np.array([kappa_n * r for _, r in refined])
    weight = np.exp((loglik - loglik.max()) / TEMPERATURE)
    weight /= weight.sum()
    candidates = []
    for (position, r), w in zip(refined, weight):
        if w < MIN_WEIGHT:
            continue
        covariance = np.zeros((3, 3))
        fisher = fisher_covariance(k, anchors, position, sigma, axes) * (n / max(independent, 1))
        covariance[:axes, :axes] = fisher + _bias_consider(anchors, position, float(np.mean(np.abs(k))), axes)
        candidates.append(Candidate(position, covariance, float(w), "phase", r))
    total = sum(c.weight for c in candidates)
    for c in candidates:
        c.weight /= total
    return candidates


def _hop_centre(z, k, anchors, antenna, low, high, axes: int):
    """Frequency diversity's position: per antenna its hop range (the phase
    slope across channels; the carrier's own constant is the tag's offset,
    common to all antennas, so one antenna alone has no lattice), then
    multilateration. Returns (position, its covariance), or (None, None)."""
    max_range = float(np.max(np.linalg.norm(np.stack([low, high])[:, None, :] - anchors[None, :, :], axis=2))) + 1.0
    where, hop, sigma = [], [], []
    for a in np.unique(antenna):
        rows = antenna == a
        found = _core.locate_hop_range(np.ascontiguousarray(z[rows].real), np.ascontiguousarray(z[rows].imag), np.ascontiguousarray(k[rows]), max_range)
        d, s = found if found is not None else (math.nan, math.nan)
        if math.isfinite(d) and math.isfinite(s):
            where.append(anchors[np.flatnonzero(rows)[0]])
            hop.append(d)
            sigma.append(max(s, 1e-3))
    if len(hop) < axes:
        return None, None
    return _multilaterate(np.array(where), np.array(hop), np.array(sigma), 0.5 * (low + high), axes)


def _bias_consider(anchors: np.ndarray, position: np.ndarray, k_mean: float, axes: int) -> np.ndarray:
    """σ_b² / k² (UᵀU)⁻¹ over the antennas: a per-antenna phase bias σ_b moves a
    least-squares position by this covariance (U the unit vectors to the tag)."""
    unique = np.unique(anchors, axis=0)
    offset = position[None, :] - unique
    u = (offset / np.linalg.norm(offset, axis=1)[:, None])[:, :axes]
    try:
        return np.linalg.inv(u.T @ u) * (BIAS_SIGMA_RAD / k_mean) ** 2
    except np.linalg.LinAlgError:
        return np.full((axes, axes), np.inf)


COVER_WEIGHT = 0.005
"""Candidates at least this likely lie within 2.5 sigma of the best row, on every axis."""


def _mixture(candidates: list[Candidate]) -> np.ndarray:
    """Second moment of the candidates about the best one, widened so that
    every candidate of weight ≥ :data:`COVER_WEIGHT` lies within its 3 sigma.

    The second moment alone does not cover a far, unlikely mode: a
    candidate of weight w at distance D sits at D / (√w D) = 1/√w sigmas,
    beyond 3 once w < 1/9. A user reading "3 sigma" expects the listed
    alternatives inside it, so the sigma is at least their distance / 2.5
    (inside 3 sigma with a margin)."""
    best = candidates[0].position
    total = np.zeros((3, 3))
    for c in candidates:
        d = c.position - best
        total += c.weight * (c.covariance + np.outer(d, d))
    reach = np.zeros(3)
    for c in candidates:
        if c.weight >= COVER_WEIGHT:
            reach = np.maximum(reach, np.abs(c.position - best) / 2.5)
    total[np.diag_indices(3)] += np.maximum(reach**2 - np.diag(total), 0.0)
    return total


def _channel_offsets(scene: Scene, frequency_hz: np.ndarray) -> np.ndarray:
    """The scene's channel offset of every read (matched within 1 kHz, 0 if none), vectorised."""
    if not scene.channel_offsets:
        return np.zeros(len(frequency_hz))
    table = np.array([c.frequency_hz for c in scene.channel_offsets])
    values = np.array([c.phase_offset_rad for c in scene.channel_offsets])
    order = np.argsort(table)
    table, values = table[order], values[order]
    i = np.clip(np.searchsorted(table, frequency_hz), 1, len(table) - 1) if len(table) > 1 else np.zeros(len(frequency_hz), dtype=int)
    nearest = np.where(np.abs(table[i - 1] - frequency_hz) < np.abs(table[i] - frequency_hz), i - 1, i) if len(table) > 1 else i
    return np.where(np.abs(table[nearest] - frequency_hz) <= 1e3, values[nearest], 0.0)


def locate_tag(scene: Scene, reads: Reads, epc: str, rows: np.ndarray | None = None) -> Location:
    """One tag's :class:`Location` from its reads (``rows``: their indices, if known)."""
    if rows is None:
        rows = np.flatnonzero(np.asarray(reads.epc).astype(str) == epc)
    location = Location(epc, int(len(rows)))
    antennas = {a.id: a for a in scene.antennas}
    rows = rows[np.isin(np.asarray(reads.antenna)[rows], list(antennas))]
    antenna = np.asarray(reads.antenna)[rows]
    anchors = np.array([antennas[int(a)].position for a in antenna]).reshape(-1, 3)
    low, high = _region_box(scene, anchors if len(anchors) else np.array([a.position for a in scene.antennas]))
    calibration = scene.extra.get("calibration", {}) if isinstance(scene.extra.get("calibration"), dict) else {}
    path_loss = rssi_cue.models(calibration)
    m = 2 if scene.reader.phase_period == "pi" else 1
    frequency = np.asarray(reads.frequency_hz, dtype=np.float64)[rows]
    offsets = np.array([antennas[int(a)].phase_offset_rad for a in antenna]) + _channel_offsets(scene, frequency)
    z = np.exp(1j * m * (np.asarray(reads.phase_rad, dtype=np.float64)[rows] - offsets))
    k = m * scene.reader.phase_sign * FOUR_PI_OVER_C * frequency
    time_s = np.asarray(reads.time_s, dtype=np.float64)[rows]
    phase_candidates = []
    if calibration.get("phase_usable", True) is False:
        location.note = "the scene's calibration found phase not usable in this room"
    elif len(np.unique(antenna)) < scene.dimensions or len(rows) < 3 * scene.dimensions:
        location.note = f"phase needs reads on at least {scene.dimensions} antennas"
    else:
        phase_candidates = _phase_candidates(z, k, anchors, time_s, antenna, scene, low, high)
        if not phase_candidates:
            location.note = "the tag's phases fit no position in the region"
        elif phase_candidates[0].coherence < COHERENCE_USABLE:
            location.note = f"the tag's phases reach a coherence of only {phase_candidates[0].coherence:.2f} at any position"
            phase_candidates = []
    rssi = np.asarray(reads.rssi_dbm, dtype=np.float64)[rows]
    if phase_candidates:
        if path_loss:
            # RSSI re-weighs the phase candidates by its likelihood at each.
            loglik = np.array([rssi_cue.log_likelihood(path_loss, antenna, rssi, anchors, c.position[None, :])[0] for c in phase_candidates])
            weights = np.array([c.weight for c in phase_candidates]) * np.exp((loglik - loglik.max()) / TEMPERATURE)
            for c, w in zip(phase_candidates, weights / weights.sum()):
                c.weight, c.cue = float(w), "phase+rssi"
            phase_candidates.sort(key=lambda c: -c.weight)
        best = phase_candidates[0]
        # Every candidate counts in the best row's sigma; the rows list the likeliest few.
        location.candidates = [Candidate(best.position, _mixture(phase_candidates), best.weight, best.cue, best.coherence)] + phase_candidates[1:MAX_CANDIDATES]
        return location
    if path_loss and np.isfinite(rssi).any():
        location.candidates = [rssi_cue.locate(path_loss, antenna, rssi, anchors, low, high, scene.dimensions)]
        return location
    centre = 0.5 * (low + high)
    spread = np.diag(((high - low) ** 2) / 12.0)
    location.candidates = [Candidate(centre, spread, 1.0, "region")]
    location.note = (location.note + "; " if location.note else "") + "no usable cue: the region's centre, with the region's spread"
    return location


def locate(scene: Scene, reads: Reads) -> list[Location]:
    """Every tag in ``reads`` (see the module docstring), in order of first appearance."""
    names, first, tag = np.unique(np.asarray(reads.epc).astype(str), return_index=True, return_inverse=True)
    order = np.argsort(tag, kind="stable")
    bounds = np.searchsorted(tag[order], np.arange(len(names) + 1))
    return [locate_tag(scene, reads, str(names[t]), order[bounds[t] : bounds[t + 1]]) for t in np.argsort(first)]
