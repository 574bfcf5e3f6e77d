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
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from scattertrack.calibrate.phase import fit_offsets, round_trip_phase
from scattertrack.physics import round_trip_channel

COARSE_STEP_M = 0.005
"""Offset step of the coarse search, m (a tenth of the ripple's λ/4 period along the normal)."""
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


def as_dict(reflector) -> dict:
    """A reflector (``scattertrack.io.Reflector`` or a dict) as a plain dict of lists."""
    get = (lambda k: reflector.get(k)) if isinstance(reflector, dict) else (lambda k: getattr(reflector, k, None))
    out = {"kind": str(get("kind")), "coefficient": float(get("coefficient"))}
    for key in ("point", "normal", "position"):
        value = get(key)
        if value is not None:
            out[key] = [float(v) for v in np.asarray(value, dtype=float)]
    if out["kind"] == "plane":
        normal = np.asarray(out["normal"], dtype=float)
        out["normal"] = list(normal / np.linalg.norm(normal))
    return out


@dataclass
class _Problem:
    """The references' reads as the fits need them."""

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

    def subset(self, rows: np.ndarray) -> "_Problem":
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


def refine_reflectors(
    declared: list,
    phase: np.ndarray,
    frequency_hz: np.ndarray,
    anchor: np.ndarray,
    position: np.ndarray,
    antenna: np.ndarray,
    channel: np.ndarray,
    tag: np.ndarray,
    counts: tuple,
    sign: int,
    m: int,
    search_m: float = SEARCH_M,
) -> list[ReflectorFit]:
    """Refine every ``declared`` reflector against the reference reads (per
    read: reported ``phase`` rad, carrier Hz, antenna position ``anchor`` m,
    reference ``position`` m, and the offset fit's indices ``antenna``,
    ``channel``, ``tag`` into ``counts``; the calibrated ``sign`` and
    m = 2π/P). Returns one :class:`ReflectorFit` per declared reflector, in
    order; those with ``kept`` False failed a check (see the module doc)."""
    problem = _Problem(
        np.asarray(phase, float), np.asarray(frequency_hz, float), np.asarray(anchor, float), np.asarray(position, float),
        np.asarray(antenna), np.asarray(channel), np.asarray(tag), tuple(counts), int(sign), int(m),
    )
    if len(problem.phase) > MAX_SEARCH_READS:
        rows = np.sort(np.random.default_rng(0).choice(len(problem.phase), MAX_SEARCH_READS, replace=False))
        problem = problem.subset(rows)
    n = len(problem.phase)
    current = [as_dict(r) for r in declared]
    fits: list[ReflectorFit] = []
    for index, reflector in enumerate(current):
        # The walls refined so far (and kept); the later ones join as they are refined.
        others = [f.reflector for f in fits if f.kept]
        without = problem.fit(others)
        # κ of the residuals: set from the best fit below; the coherences are compared first.
        plane = reflector["kind"] == "plane"
        span = max(search_m, ALIAS_SPAN_M)
        offsets = np.arange(-span, span + 1e-12, COARSE_STEP_M) if plane else np.zeros(1)
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
        if abs(best_s) > search_m + FINE_STEP_M:
            reason = (
                f"the references fit it best {100 * best_s:+.1f} cm along its normal from where the scene puts it, "
                f"beyond the search's {100 * search_m:.0f} cm: check the declared plane, or widen --reflector-search-m"
            )
        elif gain < SEEN_NATS:
            reason = f"the references do not see it (the wall explains their phases by {gain:.0f} nats, {SEEN_NATS:.0f} needed)"
        elif len(aliases):
            alias = float(aliases[np.argmin(nats(coarse.max(axis=1))[np.isin(offsets, aliases)])])
            reason = (
                f"the references cannot tell its offset {100 * best_s:+.1f} cm from {100 * alias:+.1f} cm "
                f"(within {ALIAS_NATS:.0f} nats): add references nearer the wall or move one along it"
            )
        fits.append(ReflectorFit(
            index=index, kind=reflector["kind"], kept=not reason, shift_m=best_s, interval_m=interval,
            coefficient=best_g, gain_nats=float(gain), reflector=_shifted(reflector, best_s, best_g), reason=reason,
        ))
    return fits
