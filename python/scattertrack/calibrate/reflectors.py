"""Known reflectors refined from reference tags: where a declared wall really is.

A scene may declare reflectors (docs/formats.md section 1, ``[[reflectors]]``):
walls the user measured with a tape, a few centimetres off at best. A
tracker that models a wall 5 cm from where it is does worse than one that
ignores it (the ripple it predicts is out of step with the one in the
reads: docs/notes/glac-experiments.md, "Known reflectors"), so
``calibrate`` refines each declared plane's offset along its normal and
its coefficient Γ from the references' reads, and drops what they cannot
pin down.

The model is the calibration's (:mod:`~scattertrack.calibrate.phase`) with
the reflectors' round-trip excess added (:func:`scattertrack.physics.round_trip_channel`):

    φ_k = s · (4π f_k d_k / c + excess_k(walls)) + θ_a + θ_ch + θ_tag + ε_k   (mod P)

and a wall is scored by the offsets' fit (coordinate ascent) as the
log-likelihood of a von Mises residual with the concentration κ = 1 / σ²,
σ the best fit's residuals' robust spread (1.4826 × median |residual|): ``ℓ = κ Σ_k cos(residual_k)``, so that
``Δℓ = κ N ΔR`` in nats (R the coherence).

Per declared plane, holding the others at their current estimates:

1. a coarse search over the offset (``COARSE_STEP_M`` steps over
   ``±max(search_m, ALIAS_SPAN_M)``) and ``COARSE_COEFFICIENTS``: wider than
   the user's search, so that a better place outside it is seen;
2. a fine one (``FINE_STEP_M``, ``FINE_COEFFICIENT_STEP``) around the best;
3. checks: the best offset over the wide span must lie within
   ``±search_m`` (else the references put the wall somewhere the user did
   not allow: a 20 cm error searched within 5 cm would otherwise settle on
   a ripple alias there); the wall must raise ℓ by ``SEEN_NATS`` over no
   wall ("seen"); no offset farther than ``ALIAS_M`` from the best may come
   within ``ALIAS_NATS`` of it (a ripple repeats every half wavelength along the
   wall's normal, and few references cannot tell those apart); the offsets
   within 2 nats span the reported interval. A wall that fails a check is
   left out of the calibrated scene, with a ``warning:`` line.

A point scatterer keeps its position; only its coefficient is refined.
With several reflectors, each is refined twice: first with those before
it, then with every other one as refined so far.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from scattertrack.calibrate.phase import fit_offsets, round_trip_phase
from scattertrack.io.types import Reflector
from scattertrack.physics import round_trip_channel

COARSE_STEP_M = 0.005
"""Offset step of the coarse search, m (a sixteenth of λ/4 ≈ 8 cm, the shift after which the ripple repeats with the coefficient's sign flipped)."""
COARSE_COEFFICIENTS = (-0.6, -0.3, 0.3, 0.6)
"""Coefficients of the coarse search (signed: a conductor flips the phase)."""
FINE_STEP_M = 0.0005
FINE_SPAN_M = 0.006
"""The fine search covers the best coarse offset ± this, m."""
FINE_COEFFICIENT_STEP = 0.02
COEFFICIENT_LIMIT = 0.95
SEEN_NATS = 20.0
"""Gain in log-likelihood over no wall below which the references do not see it."""
ALIAS_M = 0.02
ALIAS_NATS = 10.0
"""An offset more than ALIAS_M from the best within ALIAS_NATS of it: the wall is ambiguous."""
SEARCH_M = 0.3
"""Default half-width of the offset search around the declared plane, m."""
ALIAS_SPAN_M = 0.3
"""The coarse search (and the alias check) always covers at least this either side of the declared plane, m."""
MAX_SEARCH_READS = 6000
"""Reads used by the searches (a seeded subsample beyond this; the final fit uses all)."""
SEARCH_ITERATIONS = 12
"""Coordinate-ascent sweeps per candidate wall (the offsets settle in a few)."""
DISCOVERY_REACH_M = 2.0
"""How far beyond the region and the antennas :func:`discover_walls` looks, m (default)."""
DISCOVERY_CLEARANCE_M = 0.05
"""Discovered planes start this far beyond the region and every antenna, m."""
DISCOVERY_NATS = 40.0
"""Gain a discovered wall needs (a declared one needs SEEN_NATS): the search tries thousands of planes."""
MAX_DISCOVERED = 3
"""Walls :func:`discover_walls` finds at most."""


@dataclass
class ReflectorFit:
    """What the references said about one declared reflector."""

    index: int
    kind: str
    kept: bool
    shift_m: float
    """Fitted offset along the normal from the declared plane, m (0 for points)."""
    interval_m: tuple[float, float]
    """Offsets (relative to the declared plane, m) within 2 nats of the best."""
    coefficient: float
    gain_nats: float
    """Log-likelihood of the references with the wall against without it."""
    reflector: dict
    """The refined reflector (plain values: ``kind``, ``point``/``normal`` or ``position``, ``coefficient``)."""
    reason: str = ""
    """Why it was left out (empty when kept)."""
    discovered: bool = False
    """Found by :func:`discover_walls`, not declared by the scene."""


@dataclass
class ReferenceReads:
    """The references' reads as the fits need them: per read the reported
    ``phase`` (rad), its carrier (Hz), its antenna's position ``anchor`` and
    the reference's ``position`` (m), and the offset fit's indices
    ``antenna``, ``channel``, ``tag`` into ``counts``; the calibrated
    ``sign`` and m = 2π/P. Build it with :func:`reference_reads`."""

    phase: np.ndarray
    frequency: np.ndarray
    anchor: np.ndarray
    position: np.ndarray
    antenna: np.ndarray
    channel: np.ndarray
    tag: np.ndarray
    counts: tuple
    sign: int
    m: int

    def subset(self, rows: np.ndarray) -> "ReferenceReads":
        take = lambda a: a[rows]  # noqa: E731
        return dataclasses.replace(
            self, phase=take(self.phase), frequency=take(self.frequency), anchor=take(self.anchor),
            position=take(self.position), antenna=take(self.antenna), channel=take(self.channel), tag=take(self.tag),
        )

    def fit(self, reflectors: list[dict], iterations: int = SEARCH_ITERATIONS):
        _, excess, _ = round_trip_channel(self.anchor, self.position, self.frequency, reflectors)
        distance = np.linalg.norm(self.position - self.anchor, axis=1)
        geometric = round_trip_phase(self.frequency, distance) + excess
        return fit_offsets(self.m * (self.phase - self.sign * geometric), self.antenna, self.channel, self.tag, self.counts, iterations)


def _shifted(reflector: dict, shift_m: float, coefficient: float) -> dict:
    out = dict(reflector, coefficient=float(coefficient))
    if reflector["kind"] == "plane":
        out["point"] = list(np.asarray(reflector["point"]) + shift_m * np.asarray(reflector["normal"]))
    return out


def reference_reads(phase, frequency_hz, anchor, position, antenna, channel, tag, counts, sign, m) -> ReferenceReads:
    """The references' reads as :class:`ReferenceReads`, subsampled (seeded) beyond MAX_SEARCH_READS."""
    problem = ReferenceReads(
        np.asarray(phase, float), np.asarray(frequency_hz, float), np.asarray(anchor, float), np.asarray(position, float),
        np.asarray(antenna), np.asarray(channel), np.asarray(tag), tuple(counts), int(sign), int(m),
    )
    if len(problem.phase) > MAX_SEARCH_READS:
        rows = np.sort(np.random.default_rng(0).choice(len(problem.phase), MAX_SEARCH_READS, replace=False))
        problem = problem.subset(rows)
    return problem


def _fit_one(problem: ReferenceReads, others: list[dict], reflector: dict, offsets: np.ndarray, allowed: tuple[float, float],
             index: int, beyond: str) -> ReflectorFit:
    """One reflector searched over ``offsets`` along its normal (a plane; a point keeps its place),
    with the ``others`` in the model, then checked: its best offset must lie within ``allowed``
    (``beyond`` says what to do when it does not), the references must see it, and no alias may
    come close (module doc)."""
    n = len(problem.phase)
    without = problem.fit(others)
    plane = reflector["kind"] == "plane"
    coarse = np.array([
        [problem.fit(others + [_shifted(reflector, s, g)]).coherence for g in COARSE_COEFFICIENTS] for s in offsets
    ])
    i, j = np.unravel_index(np.argmax(coarse), coarse.shape)
    best_s, best_g = float(offsets[i]), COARSE_COEFFICIENTS[j]
    # Fine: offset at the best coefficient, then the coefficient at the best offset, twice.
    fine_offsets = best_s + np.arange(-FINE_SPAN_M, FINE_SPAN_M + 1e-12, FINE_STEP_M) if plane else np.array([0.0])
    coefficients = np.arange(-COEFFICIENT_LIMIT, COEFFICIENT_LIMIT + 1e-12, FINE_COEFFICIENT_STEP)
    for _ in range(2):
        r_s = np.array([problem.fit(others + [_shifted(reflector, s, best_g)]).coherence for s in fine_offsets])
        best_s = float(fine_offsets[np.argmax(r_s)])
        near = coefficients[np.abs(coefficients - best_g) <= 0.15]
        r_g = np.array([problem.fit(others + [_shifted(reflector, best_s, g)]).coherence for g in near])
        best_g = float(near[np.argmax(r_g)])
    best = problem.fit(others + [_shifted(reflector, best_s, best_g)], iterations=30)
    # Robust (median absolute residual): an outlier read would otherwise halve κ.
    kappa = 1.0 / max((1.4826 * float(np.median(np.abs(best.residual)))) ** 2, 1e-6)
    nats = lambda r: kappa * n * (best.coherence - r)  # noqa: E731 - Δℓ below the best
    gain = kappa * n * (best.coherence - without.coherence)
    r_s = np.array([problem.fit(others + [_shifted(reflector, s, best_g)]).coherence for s in fine_offsets])
    inside = fine_offsets[nats(r_s) <= 2.0] if plane else np.zeros(1)
    interval = (float(inside.min()), float(inside.max())) if inside.size else (best_s, best_s)
    aliases = offsets[(np.abs(offsets - best_s) > ALIAS_M) & (nats(coarse.max(axis=1)) < ALIAS_NATS)] if plane else []
    reason = ""
    if not allowed[0] - FINE_STEP_M <= best_s <= allowed[1] + FINE_STEP_M:
        reason = f"the references fit it best {100 * best_s:+.1f} cm along its normal from where the scene puts it, {beyond}"
    elif gain < SEEN_NATS:
        reason = f"the references do not see it (the wall explains their phases by {gain:.0f} nats, {SEEN_NATS:.0f} needed)"
    elif len(aliases):
        alias = float(aliases[np.argmin(nats(coarse.max(axis=1))[np.isin(offsets, aliases)])])
        reason = (
            f"the references cannot tell its offset {100 * best_s:+.1f} cm from {100 * alias:+.1f} cm "
            f"(within {ALIAS_NATS:.0f} nats): add references nearer the wall or move one along it"
        )
    return ReflectorFit(
        index=index, kind=reflector["kind"], kept=not reason, shift_m=best_s, interval_m=interval,
        coefficient=best_g, gain_nats=float(gain), reflector=_shifted(reflector, best_s, best_g), reason=reason,
    )


def refine_reflectors(declared: list[Reflector], problem: ReferenceReads, search_m: float = SEARCH_M) -> list[ReflectorFit]:
    """Refine every ``declared`` reflector (the scene's) against the references' reads.
    Returns one :class:`ReflectorFit` per declared reflector, in order;
    those with ``kept`` False failed a check (see the module doc)."""
    span = max(search_m, ALIAS_SPAN_M)
    # Plain values, a plane's normal made unit (Reflector.from_dict): the searches move planes along it.
    plain = [Reflector.from_dict(r.as_dict()).as_dict() for r in declared]
    beyond = f"beyond the search's {100 * search_m:.0f} cm: check the declared plane, or widen --reflector-search-m"

    def fit(index: int, others: list[dict]) -> ReflectorFit:
        reflector = plain[index]
        offsets = np.arange(-span, span + 1e-12, COARSE_STEP_M) if reflector["kind"] == "plane" else np.zeros(1)
        return _fit_one(problem, others, reflector, offsets, (-search_m, search_m), index, beyond)

    # First pass: each reflector with the ones refined before it (and kept).
    fits: list[ReflectorFit] = []
    for index in range(len(plain)):
        fits.append(fit(index, [f.reflector for f in fits if f.kept]))
    if len(plain) < 2:
        return fits
    # Second pass: each again, with every other one as refined so far. In
    # the first pass a wall fitted before a stronger one had that wall's
    # ripple in its residuals (dev: a wall of 0.3 refined before a floor of
    # -0.4 was left out, or placed 6 mm off; after it, within 1 mm).
    for index in range(len(plain)):
        fits[index] = fit(index, [f.reflector for j, f in enumerate(fits) if j != index and f.kept])
    return fits


def discover_walls(
    known: list[dict],
    region: tuple[np.ndarray, np.ndarray],
    antennas: np.ndarray,
    problem: ReferenceReads,
    reach_m: float = DISCOVERY_REACH_M,
    first_index: int = 0,
) -> list[ReflectorFit]:
    """Walls nobody declared: planes parallel to the region's faces, beyond the region and every
    antenna (``region`` = (min, max), m; ``antennas`` (n, 3), m), up to ``reach_m`` further out.

    Greedy: each round searches the six directions with the ``known`` reflectors (plain values,
    as :class:`ReflectorFit` keeps them) and the walls
    found so far in the model, and takes the one that explains the references best; it is kept
    when it passes :func:`refine_reflectors`' checks and gains ``DISCOVERY_NATS`` (more than a
    declared wall needs: the search tries thousands of planes). At most ``MAX_DISCOVERED``."""
    low = np.minimum(np.asarray(region[0], float), np.asarray(antennas, float).min(axis=0)) - DISCOVERY_CLEARANCE_M
    high = np.maximum(np.asarray(region[1], float), np.asarray(antennas, float).max(axis=0)) + DISCOVERY_CLEARANCE_M
    # Shifts along each candidate's normal (which points into the room): negative moves it out.
    offsets = -np.arange(0.0, reach_m + 1e-12, COARSE_STEP_M)
    found: list[ReflectorFit] = []
    for _ in range(MAX_DISCOVERED):
        others = list(known) + [f.reflector for f in found]
        best = None
        for axis in range(3):
            for side, face in ((1.0, low), (-1.0, high)):
                normal = np.zeros(3)
                normal[axis] = side
                point = np.zeros(3)
                point[axis] = face[axis]
                candidate = {"kind": "plane", "point": list(point), "normal": list(normal), "coefficient": 0.3}
                fit = _fit_one(problem, others, candidate, offsets, (-reach_m, 0.0), first_index + len(found),
                               f"beyond the {100 * reach_m:.0f} cm searched")
                if best is None or fit.gain_nats > best.gain_nats:
                    best = fit
        if best is None or not best.kept or best.gain_nats < DISCOVERY_NATS:
            break
        found.append(dataclasses.replace(best, discovered=True))
    return found
