"""Static tags located from every cue a calibrated scene supports, with honest sigmas.

:func:`locate` ``(scene, reads) -> list[Location]``: one :class:`Location`
per tag, its candidates best first. Where GLAC needs motion to resolve
the λ/2 ambiguity, a static tag has two other sources:

* **frequency diversity** — over hop channels, each antenna's phase slope
  against frequency is its range, to a few centimetres
  (``scattertrack_core::locate::hop_range``); the ranges pick the
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

The phase model: the calibrated scene leaves, per read k of one tag, the
phasor z_k = exp(j m (φ_k − θ_a − θ_ch)) ≈ exp(j (k_k d_k(p) + θ_tag)) with
m = 2π/P (2 for a mod-π reader), k_k = m s 4π f_k / c (rad/m, s the phase
sign) and θ_tag the tag's own, unknown offset; a position p explains the
reads as well as their coherence R(p) = |Σ_k z_k exp(−j k_k d_k(p))| / n
says, θ_tag profiled out. The search over p, the weights and covariances
run in the Rust core (``scattertrack_core::locate``, one threaded call for
every tag); this module adds RSSI, the fallbacks and the rows. The scene's
known reflectors (``[[reflectors]]``, placed by ``scattertrack calibrate``)
enter the model there: d_k(p) is then each read's apparent range, because
a wall's excess phase turns across the band and would otherwise move the
hop ranges by decimetres onto a wrong lattice point (docs/calibration.md).

Sigmas: the phase fit's Fisher covariance at the read-to-read noise the
fit shows, scaled for the reads' correlation (the error of real readers
wanders over about half a second, so reads within one antenna's 0.5 s
count once), plus the consider covariance of a per-antenna phase bias of
:data:`BIAS_SIGMA_RAD` (calibration residuals, wander), plus the spread of
the competing candidates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scattertrack import _core
from scattertrack.io.types import Reads, Scene
from scattertrack.locate import rssi as rssi_cue
from scattertrack.locate.candidate import Candidate, Location
from scattertrack.physics import FOUR_PI_OVER_C

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


def _region_box(scene: Scene, anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if scene.region is not None:
        low, high = np.array(scene.region.min, float), np.array(scene.region.max, float)
    else:
        low, high = anchors.min(axis=0) - 1.0, anchors.max(axis=0) + 1.0
    if scene.dimensions == 2:
        low[2] = high[2] = float(scene.plane_z)
    return low, high


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
    return _locate_tags(scene, reads, [(epc, np.asarray(rows))])[0]


def locate(scene: Scene, reads: Reads) -> list[Location]:
    """Every tag in ``reads`` (see the module docstring), in order of first appearance."""
    names, first, tag = np.unique(np.asarray(reads.epc).astype(str), return_index=True, return_inverse=True)
    order = np.argsort(tag, kind="stable")
    bounds = np.searchsorted(tag[order], np.arange(len(names) + 1))
    return _locate_tags(scene, reads, [(str(names[t]), order[bounds[t] : bounds[t + 1]]) for t in np.argsort(first)])


@dataclass
class _Phasors:
    """Every read's calibrated phasor z and wavenumber k (the phase model in
    the module docstring), computed once for all tags."""

    known: np.ndarray
    """Reads whose antenna is in the scene."""
    anchor: np.ndarray
    """Index into ``anchors`` (valid where ``known``)."""
    anchors: np.ndarray
    z: np.ndarray
    k: np.ndarray
    multiplier: int
    """m of k = m s 4π f / c: 2 for a mod-π reader."""

    @classmethod
    def of(cls, scene: Scene, reads: Reads) -> _Phasors:
        ids = np.array(sorted(a.id for a in scene.antennas), dtype=np.int64)
        by_id = {a.id: a for a in scene.antennas}
        antenna = np.asarray(reads.antenna).astype(np.int64)
        anchor = np.clip(np.searchsorted(ids, antenna), 0, max(len(ids) - 1, 0))
        known = (ids[anchor] == antenna) if len(ids) else np.zeros(len(antenna), bool)
        anchors = np.array([by_id[int(i)].position for i in ids], dtype=np.float64).reshape(-1, 3)
        antenna_offsets = np.array([by_id[int(i)].phase_offset_rad for i in ids], dtype=np.float64)
        m = 2 if scene.reader.phase_period == "pi" else 1
        frequency = np.asarray(reads.frequency_hz, dtype=np.float64)
        offsets = (antenna_offsets[anchor] if len(ids) else 0.0) + _channel_offsets(scene, frequency)
        z = np.exp(1j * m * (np.asarray(reads.phase_rad, dtype=np.float64) - offsets))
        return cls(known, anchor, anchors, z, m * scene.reader.phase_sign * FOUR_PI_OVER_C * frequency, m)


def _locate_tags(scene: Scene, reads: Reads, tags: list[tuple[str, np.ndarray]]) -> list[Location]:
    """The tags' locations: the phase search of every tag that can use it in
    one threaded call to the core, then RSSI and the fallbacks per tag."""
    phasors = _Phasors.of(scene, reads)
    calibration = scene.extra.get("calibration", {}) if isinstance(scene.extra.get("calibration"), dict) else {}
    path_loss = rssi_cue.models(calibration)
    phase_usable = calibration.get("phase_usable", True) is not False
    antenna_ids = np.asarray(reads.antenna)
    rssi_all = np.asarray(reads.rssi_dbm, dtype=np.float64)
    time_all = np.asarray(reads.time_s, dtype=np.float64)
    fixed_box = _region_box(scene, phasors.anchors) if scene.region is not None or not len(phasors.anchors) else None
    work = []  # (location, rows, low, high) per tag
    searched = []  # indices into work of the tags the phase search takes
    for epc, rows in tags:
        location = Location(epc, int(len(rows)))
        rows = rows[phasors.known[rows]]
        used = np.unique(phasors.anchor[rows])
        low, high = fixed_box if fixed_box is not None else _region_box(scene, phasors.anchors[used] if len(used) else phasors.anchors)
        if not phase_usable:
            location.note = "the scene's calibration found phase not usable in this room"
        elif len(used) < scene.dimensions or len(rows) < 3 * scene.dimensions:
            location.note = f"phase needs reads on at least {scene.dimensions} antennas"
        else:
            searched.append(len(work))
        work.append((location, rows, low, high))
    found = _phase_search(phasors, time_all, scene.dimensions, [work[i] for i in searched], scene)
    candidates_of = dict(zip(searched, found))
    locations = []
    for i, (location, rows, low, high) in enumerate(work):
        antenna, rssi, anchors = antenna_ids[rows], rssi_all[rows], phasors.anchors[phasors.anchor[rows]]
        phase_candidates = candidates_of.get(i, [])
        if i in candidates_of:
            if not phase_candidates:
                location.note = "the tag's phases fit no position in the region"
            elif phase_candidates[0].coherence < COHERENCE_USABLE:
                location.note = f"the tag's phases reach a coherence of only {phase_candidates[0].coherence:.2f} at any position"
                phase_candidates = []
        locations.append(_choose(location, phase_candidates, path_loss, antenna, rssi, anchors, low, high, scene.dimensions))
    return locations


def _phase_search(phasors: _Phasors, time_s: np.ndarray, axes: int, work: list, scene: Scene) -> list[list[Candidate]]:
    """The phase candidates of every tag in ``work``: one call to the Rust
    core (``scattertrack_core::locate``, threaded over tags), with the
    scene's known reflectors in the phase model."""
    if not work:
        return []
    rows = np.concatenate([w[1] for w in work])
    bounds = np.r_[0, np.cumsum([len(w[1]) for w in work])].astype(np.int64)
    z = phasors.z[rows]
    positions, covariances, weights, coherences, candidate_bounds = _core.locate_batch(
        np.ascontiguousarray(z.real), np.ascontiguousarray(z.imag), np.ascontiguousarray(phasors.k[rows]),
        np.ascontiguousarray(time_s[rows]), phasors.anchor[rows].astype(np.int64), np.ascontiguousarray(phasors.anchors),
        bounds, np.array([w[2] for w in work], dtype=np.float64).reshape(-1, 3), np.array([w[3] for w in work], dtype=np.float64).reshape(-1, 3), axes,
        temperature=TEMPERATURE, bias_sigma_rad=BIAS_SIGMA_RAD, correlation_s=CORRELATION_S, max_candidates=MAX_CANDIDATES,
        min_weight=MIN_WEIGHT, hopping_spread_hz=HOPPING_SPREAD_HZ,
        scene=scene if scene.reflectors else None, phase_multiplier=float(phasors.multiplier),
    )
    return [
        [Candidate(positions[c], covariances[c], float(weights[c]), "phase", float(coherences[c])) for c in range(candidate_bounds[t], candidate_bounds[t + 1])]
        for t in range(len(work))
    ]


def _choose(location: Location, phase_candidates: list, path_loss: dict, antenna, rssi, anchors, low, high, dimensions: int) -> Location:
    """The tag's rows from its usable cue: phase (re-weighed by RSSI when calibrated), else RSSI, else the region."""
    if phase_candidates:
        if path_loss:
            # RSSI re-weighs the phase candidates by its likelihood at each.
            loglik = rssi_cue.log_likelihood(path_loss, antenna, rssi, anchors, np.array([c.position for c in phase_candidates]))
            weights = np.array([c.weight for c in phase_candidates]) * np.exp((loglik - loglik.max()) / TEMPERATURE)
            for c, w in zip(phase_candidates, weights / weights.sum()):
                c.weight, c.cue = float(w), "phase+rssi"
            phase_candidates.sort(key=lambda c: -c.weight)
        best = phase_candidates[0]
        # Every candidate counts in the best row's sigma; the rows list the likeliest few.
        location.candidates = [Candidate(best.position, _mixture(phase_candidates), best.weight, best.cue, best.coherence)] + phase_candidates[1:MAX_CANDIDATES]
        return location
    if path_loss and np.isfinite(rssi).any():
        location.candidates = [rssi_cue.locate(path_loss, antenna, rssi, anchors, low, high, dimensions)]
        return location
    centre = 0.5 * (low + high)
    spread = np.diag(((high - low) ** 2) / 12.0)
    location.candidates = [Candidate(centre, spread, 1.0, "region")]
    location.note = (location.note + "; " if location.note else "") + "no usable cue: the region's centre, with the region's spread"
    return location
