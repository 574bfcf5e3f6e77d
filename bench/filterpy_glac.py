"""GLAC written the way a researcher would with filterpy: the baseline of ``make bench``.

The same algorithm as the Rust tracker (``crates/core/src/track/glac.rs``,
``initial.rs``; Wang, Chen, Gong, "Mobility Improves Accuracy", sec. 3),
with the same defaults (``GlacParams::default``, ``InitialState::default``),
so that accuracy is comparable; it is not meant to be bit-identical:

* Initial state pruning (sec. 3.2.2), in numpy: per antenna, the two reads
  around a reference time t_x are unwrapped candidate by candidate and
  interpolated to t_x; candidate spheres (3D) or circles (2D, the paper's
  triangle with perimeter threshold D_th) of the best antenna triple are
  intersected; every point is refined by Gauss-Newton least squares against
  the nearest candidate of every antenna and kept if every range residual
  is small and it lies in the region; velocity from the projected
  velocities by least squares; likelihood L0 (eq. 10).
* One ``filterpy.kalman.ExtendedKalmanFilter`` (dim_x = 6, dim_z = 1) per
  hypothesis, held in a Python list: ``ekf.F``/``ekf.Q`` set per time step
  (constant velocity, eq. 3), ``ekf.predict()``, nearest-neighbour candidate
  (eq. 9) from the read's own wavelength and the scene's antenna and channel
  offsets, a 3-sigma innovation gate (GLAC's recovery), then
  ``ekf.update(z, HJacobian, Hx, R=...)``; the innovation log-likelihood,
  normalisation, quick stop, region constraint, loss of lock and merging of
  coinciding hypotheses, and re-initialisation.

Parameters: the tracker takes over the Rust tracker's current defaults
(``scattertrack.track.default_params()``) for every parameter it shares
with it (:func:`mirrored_defaults`), so that it follows tuning of those;
features of the Rust tracker beyond the above are not implemented here, and
:func:`mirrored_defaults` lists them.

Entry point: :func:`run_filterpy_glac` ``(scene, reads) -> Track`` (any
number of tags, one tracker per EPC), or :class:`FilterpyGlac` for one tag,
one read at a time. Units are SI (m, s, rad, Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from scattertrack.io.types import Reads, Scene, SkipReport, Track

SPEED_OF_LIGHT = 299_792_458.0
"""m/s."""


@dataclass
class GlacSettings:
    """GLAC's parameters (names as in ``scattertrack.track.default_params()``).

    The values here are the Rust ``GlacParams::default()`` /
    ``InitialState::default()`` when this file was written;
    :class:`FilterpyGlac` replaces them with the Rust tracker's current
    defaults at run time (``init_region_margin_m`` and
    ``init_merge_distance_m`` are not exposed by the Rust side and stay)."""

    q: float = 0.05
    """Acceleration noise spectral density of the constant-velocity model, m²/s³."""
    phase_noise_rad: float | None = None
    """1-sigma phase noise, rad; None: the scene's prior (0.1 if it has none)."""
    init_window_s: float = 0.3
    init_max_window_s: float = 1.0
    init_position_sigma_m: float = 0.01
    init_velocity_sigma_m_s: float = 0.1
    quick_stop: float = 1e-6
    gate_sigmas: float = 3.0
    max_consecutive_outliers: int = 8
    reinit_gap_s: float = 1.0
    region_margin_m: float = 0.05
    merge_distance_m: float = 0.002
    # initial state pruning (InitialState::default)
    perimeter_threshold_m: float = 0.06
    residual_threshold_m: float = 0.015
    interpolation_sigma_m: float = 0.004
    init_region_margin_m: float = 0.05
    init_merge_distance_m: float = 0.01
    init_max_hypotheses: int = 2000


FIXED_CHOICES = {"motion": "constant-velocity", "inference": "fast", "likelihood": "innovation"}
"""What this implementation always does, under the names of ``scattertrack.track.default_params()``."""


def mirrored_defaults() -> tuple[dict, dict]:
    """The Rust tracker's current defaults (``scattertrack.track.default_params()``),
    split into those this implementation takes over (same name as a
    :class:`GlacSettings` field, or a fixed choice it matches) and the rest
    (features of the Rust tracker this baseline does not implement, or
    choices that differ), so the baseline follows the Rust defaults and a
    report can say what is not mirrored."""
    from scattertrack.track import default_params

    names = {f.name for f in fields(GlacSettings)}
    mirrored, other = {}, {}
    for key, value in default_params().items():
        if key in names:
            mirrored[key] = value
        elif FIXED_CHOICES.get(key) == value or key == "max_hypotheses":  # the cap only bounds naive inference
            continue
        else:
            other[key] = value
    return mirrored, other


# --------------------------------------------------------------------------
# scene


class SceneModel:
    """The scene as the tracker needs it (mirrors ``crates/core/src/scene.rs``)."""

    def __init__(self, scene: Scene):
        self.dimensions = int(scene.dimensions)
        self.plane_z = float(scene.plane_z) if scene.plane_z is not None else 0.0
        self.phase_sign = float(scene.reader.phase_sign)
        self.period = float(scene.reader.period_rad)
        self.phase_noise_rad = float(scene.reader.phase_noise_rad) if scene.reader.phase_noise_rad else 0.1
        self.antenna_ids = [int(a.id) for a in scene.antennas]
        self.antennas = np.array([a.position for a in scene.antennas], dtype=float).reshape(-1, 3)
        self.offsets = np.array([a.phase_offset_rad for a in scene.antennas], dtype=float)
        self.channels = [(float(c.frequency_hz), float(c.phase_offset_rad)) for c in scene.channel_offsets]
        self._channel_cache: dict[float, float] = {}
        if scene.region is not None:
            self.region_min = np.asarray(scene.region.min, dtype=float)
            self.region_max = np.asarray(scene.region.max, dtype=float)
            self._region_lo = tuple(float(v) for v in self.region_min)
            self._region_hi = tuple(float(v) for v in self.region_max)
        else:
            self.region_min = self.region_max = None

    def channel_offset(self, frequency_hz: float) -> float:
        offset = self._channel_cache.get(frequency_hz)
        if offset is None:
            offset = next((o for f, o in self.channels if abs(f - frequency_hz) <= 1e3), 0.0)
            self._channel_cache[frequency_hz] = offset
        return offset

    def candidate_spacing(self, frequency_hz: float) -> float:
        """s = P λ / 4π (m)."""
        return self.period * SPEED_OF_LIGHT / (4.0 * math.pi * frequency_hz)

    def distance_residue(self, antenna: int, frequency_hz: float, phase_rad: float) -> float:
        """d0 ∈ [0, s) (m): every d0 + n s explains the phase."""
        offset = self.offsets[antenna] + self.channel_offset(frequency_hz)
        psi = (self.phase_sign * (phase_rad - offset)) % self.period
        if psi >= self.period:
            psi = 0.0
        return psi * SPEED_OF_LIGHT / (4.0 * math.pi * frequency_hz)

    def distance_bounds(self, antenna: int) -> tuple[float, float]:
        """Nearest and farthest distance (m) from an antenna to the region."""
        if self.region_min is None:
            return 0.0, 15.0
        lo, hi = self.region_min.copy(), self.region_max.copy()
        if self.dimensions == 2:
            lo[2] = hi[2] = self.plane_z
        a = self.antennas[antenna]
        below, above = lo - a, hi - a
        near = np.where(below > 0, below, np.where(above < 0, above, 0.0))
        far = np.maximum(np.abs(below), np.abs(above))
        return float(np.sqrt(np.sum(near**2))), float(np.sqrt(np.sum(far**2)))

    def contains(self, p, margin: float) -> bool:
        """Whether p (m) is in the region grown by ``margin`` (only x, y in 2D)."""
        if self.region_min is None:
            return True
        lo, hi = self._region_lo, self._region_hi
        for i in range(self.dimensions):
            if not (lo[i] - margin <= p[i] <= hi[i] + margin):
                return False
        return True

    def contains_many(self, points: np.ndarray, margin: float) -> np.ndarray:
        if self.region_min is None:
            return np.ones(len(points), dtype=bool)
        d = self.dimensions
        return np.all(points[:, :d] >= self.region_min[:d] - margin, axis=1) & np.all(
            points[:, :d] <= self.region_max[:d] + margin, axis=1
        )


def nearest_candidate(residue: float, spacing: float, predicted: float) -> float:
    """The candidate distance residue + n·spacing nearest to ``predicted`` (eq. 9), n >= 0."""
    n = max(round((predicted - residue) / spacing), 0)
    return residue + n * spacing


def log_gaussian(innovation: float, variance: float) -> float:
    return -0.5 * (innovation * innovation / variance + math.log(2.0 * math.pi * variance))


# --------------------------------------------------------------------------
# initial state pruning (crates/core/src/track/initial.rs)


def _synchronise(model: SceneModel, antenna: int, reads: list, t_x: float, margin: float):
    """Candidate (distance, range rate) pairs of one antenna at t_x, sorted by distance."""
    times = [r[0] for r in reads]
    after = next((i for i, t in enumerate(times) if t > t_x), len(reads))
    if after == 0:
        ia, ib = 0, 1
    elif after >= len(reads):
        ia, ib = len(reads) - 2, len(reads) - 1
    else:
        ia, ib = after - 1, after
    (ta, _, fa, pa), (tb, _, fb, pb) = reads[ia], reads[ib]
    res_a, s_a = model.distance_residue(antenna, fa, pa), model.candidate_spacing(fa)
    res_b, s_b = model.distance_residue(antenna, fb, pb), model.candidate_spacing(fb)
    lo, hi = model.distance_bounds(antenna)
    lo, hi = max(lo - margin, 0.0), hi + margin
    dt = max(tb - ta, 1e-6)
    alpha = (t_x - ta) / dt
    n_lo = max(math.floor((lo - res_a) / s_a), 0)
    n_hi = math.ceil((hi - res_a) / s_a) + 1
    d_a = res_a + np.arange(n_lo, n_hi + 1) * s_a
    d_b = res_b + np.maximum(np.round((d_a - res_b) / s_b), 0.0) * s_b
    distance = d_a + alpha * (d_b - d_a)
    keep = (distance >= lo) & (distance <= hi)
    distance, rate = distance[keep], ((d_b - d_a) / dt)[keep]
    order = np.argsort(distance, kind="stable")
    return distance[order], rate[order]


def _nearest_in(distances: np.ndarray, d: float) -> int:
    i = int(np.searchsorted(distances, d, side="left"))
    best = min(i, len(distances) - 1)
    if i > 0 and abs(distances[i - 1] - d) < abs(distances[best] - d):
        best = i - 1
    return best


def _best_triple(anchors: np.ndarray, axes: int):
    best, best_area = None, None
    n = len(anchors)
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                area = 0.5 * np.linalg.norm(np.cross(anchors[j] - anchors[i], anchors[k] - anchors[i]))
                if best is None or area > best_area:
                    best, best_area = (i, j, k), area
    if best is not None and (best_area > 1e-6 or axes == 2):
        return best
    return None


def _sphere_points(a0, a1, a2, r0, r1, r2, tolerance):
    """Vectorised trilateration of sphere triples (arrays of radii): both mirror points, and validity."""
    d_vec = a1 - a0
    d = np.linalg.norm(d_vec)
    ex = d_vec / d
    t = a2 - a0
    i = ex @ t
    ey = t - ex * i
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    j = ey @ t
    x = (r0 * r0 - r1 * r1 + d * d) / (2.0 * d)
    y = (r0 * r0 - r2 * r2 + i * i + j * j) / (2.0 * j) - (i / j) * x
    z2 = r0 * r0 - x * x - y * y
    valid = (z2 >= 0.0) | (z2 > -2.0 * tolerance * np.maximum(r0, tolerance))
    z = np.sqrt(np.clip(z2, 0.0, None))
    base = a0 + x[:, None] * ex + y[:, None] * ey
    return base + z[:, None] * ez, base - z[:, None] * ez, valid


def _circle_pairs(c1, r1, c2, r2, tolerance):
    """Intersections of circles (centres c1, c2 (2,), radius grids r1[:, None], r2[None, :]): (n1, n2, 2, 2), valid."""
    delta = c2 - c1
    d = np.linalg.norm(delta)
    u = delta / d
    r1, r2 = r1[:, None], r2[None, :]
    valid = ~((d > r1 + r2 + tolerance) | (d < np.abs(r1 - r2) - tolerance))
    a = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d)
    h = np.sqrt(np.clip(r1 * r1 - a * a, 0.0, None))
    base = c1 + a[..., None] * u
    normal = np.array([-u[1], u[0]])
    points = np.stack([base + h[..., None] * normal, base - h[..., None] * normal], axis=2)
    return points, valid & np.isfinite(r1) & np.isfinite(r2)


def _multilaterate(anchors: np.ndarray, distances: np.ndarray, p: np.ndarray, axes: int, iterations: int):
    """Gauss-Newton least squares of Σ (|p − aᵢ| − dᵢ)²; None if singular."""
    p = p.copy()
    for _ in range(max(iterations, 1)):
        diff = p - anchors
        r = np.maximum(np.linalg.norm(diff, axis=1), 1e-9)
        u = diff / r[:, None]
        if axes == 2:
            u[:, 2] = 0.0
        jtj = u.T @ u
        jtr = u.T @ (distances - r)
        if axes == 2:
            jtj[2, 2] = 1.0
        try:
            step = np.linalg.solve(jtj, jtr)
        except np.linalg.LinAlgError:
            return None
        p += step
        if np.linalg.norm(step) < 1e-7:
            break
    return p


def _projected_velocity(p, anchors, rates, axes):
    e = p - anchors
    e /= np.linalg.norm(e, axis=1)[:, None]
    if axes == 2:
        e[:, 2] = 0.0
    ata = e.T @ e
    atb = e.T @ rates
    if axes == 2:
        ata[2, 2] = 1.0
    try:
        return np.linalg.solve(ata, atb)
    except np.linalg.LinAlgError:
        return np.zeros(3)


def initial_hypotheses(model: SceneModel, reads: list, settings: GlacSettings, range_sigma_m: float):
    """(t_x, [(state (6,), log L0)]) best first, or None (the Rust ``initial_hypotheses``).

    ``reads``: time-ordered (time_s, antenna index, frequency_hz, phase_rad) tuples.
    """
    per_antenna = [[] for _ in range(len(model.antennas))]
    for r in reads:
        per_antenna[r[1]].append(r)
    usable = [a for a in range(len(model.antennas)) if len(per_antenna[a]) >= 2]
    if len(usable) < 3:
        return None
    t_x = min(per_antenna[a][-1][0] for a in usable)
    axes = model.dimensions
    margin = settings.init_region_margin_m
    lists = [_synchronise(model, a, per_antenna[a], t_x, margin) for a in usable]
    if any(len(d) == 0 for d, _ in lists):
        return None
    anchors = model.antennas[usable]
    triple = _best_triple(anchors, axes)
    if triple is None:
        return None
    tolerance = settings.residual_threshold_m
    (d0, _), (d1, _), (d2, _) = (lists[k] for k in triple)
    a0, a1, a2 = (anchors[k] for k in triple)
    # Every candidate triple (c0, c1, c2), skipping pairs of spheres that cannot meet.
    g0, g1, g2 = np.meshgrid(d0, d1, d2, indexing="ij")
    meet = np.abs(g0 - g1) <= np.linalg.norm(a0 - a1) + tolerance
    if axes == 3:
        plus, minus, valid = _sphere_points(a0, a1, a2, g0[meet], g1[meet], g2[meet], tolerance)
        pairs = np.stack([plus, minus], axis=1)[valid].reshape(-1, 3)
        points = pairs[model.contains_many(pairs, margin)]
    else:
        # The paper's triangle (Fig. 4a): circles in the plane z = plane_z.
        radii = []
        for a, d in zip((a0, a1, a2), (d0, d1, d2)):
            r2 = d * d - (model.plane_z - a[2]) ** 2
            radii.append(np.where(r2 >= 0.0, np.sqrt(np.clip(r2, 0.0, None)), np.nan))
        centres = [a0[:2], a1[:2], a2[:2]]
        p01, v01 = _circle_pairs(centres[0], radii[0], centres[1], radii[1], tolerance)
        p12, v12 = _circle_pairs(centres[1], radii[1], centres[2], radii[2], tolerance)
        p02, v02 = _circle_pairs(centres[0], radii[0], centres[2], radii[2], tolerance)
        # (n0, n1, n2, 2 [a], 2 [b], 2 [c], xy)
        pa = p01[:, :, None, :, None, None, :]
        pb = p12[None, :, :, None, :, None, :]
        pc = p02[:, None, :, None, None, :, :]
        perimeter = (
            np.linalg.norm(pa - pb, axis=-1) + np.linalg.norm(pb - pc, axis=-1) + np.linalg.norm(pc - pa, axis=-1)
        )
        centroid = (pa + pb + pc) / 3.0
        n0, n1, n2 = len(d0), len(d1), len(d2)
        flat = perimeter.reshape(n0, n1, n2, 8)
        best = np.argmin(flat, axis=-1)
        best_perimeter = np.take_along_axis(flat, best[..., None], axis=-1)[..., 0]
        best_centroid = np.take_along_axis(
            np.broadcast_to(centroid, (n0, n1, n2, 2, 2, 2, 2)).reshape(n0, n1, n2, 8, 2), best[..., None, None], axis=3
        )[..., 0, :]
        ok = meet & v01[:, :, None] & v12[None, :, :] & v02[:, None, :] & (best_perimeter <= settings.perimeter_threshold_m)
        xy = best_centroid[ok]
        points = np.column_stack([xy, np.full(len(xy), model.plane_z)])
        points = points[model.contains_many(points, margin)]

    r0 = range_sigma_m**2 + settings.interpolation_sigma_m**2
    hypotheses = []
    distances = np.zeros(len(lists))
    rates = np.zeros(len(lists))
    for start in points:
        p = start
        for _ in range(2):
            for k, (dist, rate) in enumerate(lists):
                i = _nearest_in(dist, float(np.linalg.norm(p - anchors[k])))
                distances[k], rates[k] = dist[i], rate[i]
            p = _multilaterate(anchors, distances, p, axes, 6)
            if p is None:
                break
        if p is None or not model.contains(p, margin):
            continue
        log_likelihood, max_residual = 0.0, 0.0
        for k, (dist, rate) in enumerate(lists):
            d = float(np.linalg.norm(p - anchors[k]))
            i = _nearest_in(dist, d)
            distances[k], rates[k] = dist[i], rate[i]
            max_residual = max(max_residual, abs(d - dist[i]))
            log_likelihood += log_gaussian(d - dist[i], r0)
        if max_residual > settings.residual_threshold_m:
            continue
        velocity = _projected_velocity(p, anchors, rates, axes)
        hypotheses.append((np.concatenate([p, velocity]), log_likelihood))
    hypotheses.sort(key=lambda h: -h[1])
    kept = []
    for state, log_likelihood in hypotheses:
        if all(np.linalg.norm(k[0][:3] - state[:3]) > settings.init_merge_distance_m for k in kept):
            kept.append((state, log_likelihood))
            if len(kept) >= settings.init_max_hypotheses:
                break
    return (t_x, kept) if kept else None


# --------------------------------------------------------------------------
# the tracker


def hx_range(x, antenna):
    """h(x) = |p − a| (m), eq. 4."""
    return math.sqrt((x[0] - antenna[0]) ** 2 + (x[1] - antenna[1]) ** 2 + (x[2] - antenna[2]) ** 2)


def jacobian_range(x, antenna, axes):
    """H = ∂h/∂x = [uᵀ, 0, 0, 0] with u the unit line of sight; (1, 6)."""
    diff = x[:3] - antenna
    H = np.zeros((1, 6))
    H[0, :axes] = diff[:axes] / max(float(np.linalg.norm(diff)), 1e-9)
    return H


@dataclass
class FilterpyEstimate:
    time_s: float
    position: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray
    hypotheses: int
    weight: float


@dataclass
class Counters:
    measurements: int = 0
    out_of_order: int = 0
    outliers: int = 0
    initialising: int = 0
    reinitialisations: int = 0
    max_hypotheses: int = 0
    filter_updates: int = 0
    extra: dict = field(default_factory=dict)


class FilterpyGlac:
    """GLAC for one tag over filterpy EKFs: ``step(time_s, antenna_index, frequency_hz, phase_rad)``."""

    def __init__(self, scene: Scene, *, mirror_rust_defaults: bool = True, **params):
        """``params`` override the settings: by default the Rust tracker's
        current defaults where they apply (:func:`mirrored_defaults`), else
        the :class:`GlacSettings` defaults."""
        base = mirrored_defaults()[0] if mirror_rust_defaults else {}
        self.settings = GlacSettings(**(base | params))
        self.model = SceneModel(scene)
        self.axes = self.model.dimensions
        noise = self.settings.phase_noise_rad
        self.phase_noise = float(noise) if noise is not None else self.model.phase_noise_rad
        self.initialising = True
        self.buffer: list[tuple] = []
        self.ekfs: list[ExtendedKalmanFilter] = []
        self.log_likelihood: list[float] = []
        """Normalised log-likelihood of each hypothesis (parallel to ``ekfs``)."""
        self.outliers: list[int] = []
        """Consecutive gated reads of each hypothesis."""
        self.time_s = -math.inf
        self.last_time_s = -math.inf
        self.counters = Counters()

    @property
    def hypothesis_count(self) -> int:
        return len(self.ekfs)

    def range_variance(self, frequency_hz: float) -> float:
        sigma = self.phase_noise * SPEED_OF_LIGHT / (4.0 * math.pi * frequency_hz)
        return sigma * sigma

    def transition(self, dt: float):
        """Constant velocity per moving axis: F = [[1, dt], [0, 1]], Q = q [[dt³/3, dt²/2], [dt²/2, dt]]."""
        q = self.settings.q
        F = np.eye(6)
        Q = np.zeros((6, 6))
        for i in range(self.axes):
            F[i, i + 3] = dt
            Q[i, i] = q * dt**3 / 3.0
            Q[i, i + 3] = Q[i + 3, i] = q * dt**2 / 2.0
            Q[i + 3, i + 3] = q * dt
        return F, Q

    def _restart(self):
        self.initialising = True
        self.ekfs = []
        self.log_likelihood = []
        self.outliers = []
        self.counters.reinitialisations += 1

    def step(self, time_s: float, antenna: int, frequency_hz: float, phase_rad: float) -> FilterpyEstimate | None:
        """One read of this tag (``antenna`` is the index into the scene's antennas)."""
        self.counters.measurements += 1
        if time_s < self.last_time_s:
            self.counters.out_of_order += 1
            return None
        if not self.initialising and time_s - self.last_time_s > self.settings.reinit_gap_s:
            self._restart()
        self.last_time_s = time_s
        read = (time_s, antenna, frequency_hz, phase_rad)
        if self.initialising:
            self.counters.initialising += 1
            self.buffer.append(read)
            if not self._try_initialise():
                return None
            return self._best(time_s)
        self._track(read)
        if not self.ekfs:
            self._restart()
            self.buffer.append(read)
            self.counters.initialising += 1
            return None
        return self._best(time_s)

    def _try_initialise(self) -> bool:
        s = self.settings
        first, last = self.buffer[0][0], self.buffer[-1][0]
        span = last - first
        if span < s.init_window_s:
            return False
        counts = np.bincount([r[1] for r in self.buffer], minlength=len(self.model.antennas))
        all_twice = bool(np.all((counts == 0) | (counts >= 2)))
        if not all_twice and span < s.init_max_window_s:
            return False
        range_sigma = math.sqrt(self.range_variance(self.buffer[0][2]))
        found = initial_hypotheses(self.model, self.buffer, s, range_sigma)
        if found is None:
            keep_from = last - s.init_max_window_s
            self.buffer = [r for r in self.buffer if r[0] >= keep_from]
            return False
        t_x, initial = found
        P0 = np.zeros((6, 6))
        for i in range(self.axes):
            P0[i, i] = s.init_position_sigma_m**2
            P0[i + 3, i + 3] = s.init_velocity_sigma_m_s**2
        self.ekfs = []
        for state, _ in initial:
            ekf = ExtendedKalmanFilter(dim_x=6, dim_z=1)
            x = state.copy()
            if self.axes == 2:
                x[2] = self.model.plane_z
                x[5] = 0.0
            ekf.x = x
            ekf.P = P0.copy()
            self.ekfs.append(ekf)
        self.log_likelihood = [float(ll) for _, ll in initial]
        self.outliers = [0] * len(initial)
        self._normalise()
        self.counters.max_hypotheses = max(self.counters.max_hypotheses, len(self.ekfs))
        self.time_s = t_x
        self.initialising = False
        replay = [r for r in self.buffer if r[0] > t_x]
        self.buffer = []
        for r in replay:
            self._track(r)
            if not self.ekfs:
                self._restart()
                return False
        return True

    def _track(self, read):
        """Fast inference (eqs. 5-9, 11-13) for one read through every hypothesis."""
        time_s, antenna, frequency_hz, phase_rad = read
        s = self.settings
        F, Q = self.transition(max(time_s - self.time_s, 0.0))
        position = self.model.antennas[antenna]
        residue = self.model.distance_residue(antenna, frequency_hz, phase_rad)
        spacing = self.model.candidate_spacing(frequency_hz)
        r = self.range_variance(frequency_hz)
        gate2 = s.gate_sigmas**2
        for i, ekf in enumerate(self.ekfs):
            ekf.F = F
            ekf.Q = Q
            ekf.predict()
            d = hx_range(ekf.x, position)
            z = nearest_candidate(residue, spacing, d)
            H = jacobian_range(ekf.x, position, self.axes)
            S = float((H @ ekf.P @ H.T)[0, 0]) + r
            nu = z - d
            if nu * nu <= gate2 * S:
                self.outliers[i] = 0
                ekf.update(z, jacobian_range, hx_range, R=r, args=(position, self.axes), hx_args=(position,))
                self.log_likelihood[i] += log_gaussian(nu, S)
            else:
                self.outliers[i] += 1
                self.log_likelihood[i] += -0.5 * (gate2 + math.log(2.0 * math.pi * S))
        self.counters.filter_updates += len(self.ekfs)
        self.time_s = time_s
        self._prune()

    def _normalise(self) -> None:
        """Log-sum-exp normalisation: Σ exp(log_likelihood) = 1."""
        peak = max(self.log_likelihood)
        norm = peak + math.log(sum(math.exp(ll - peak) for ll in self.log_likelihood))
        self.log_likelihood = [ll - norm for ll in self.log_likelihood]

    def _prune(self):
        """Normalise, quick stop, region constraint, loss of lock, merging."""
        if not self.ekfs:
            return
        s = self.settings
        self._normalise()
        threshold = math.log(s.quick_stop) if s.quick_stop > 0 else -math.inf
        alive = [
            self.log_likelihood[i] >= threshold
            and self.outliers[i] < s.max_consecutive_outliers
            and bool(np.isfinite(ekf.x).all())
            and self.model.contains(ekf.x, s.region_margin_m)
            for i, ekf in enumerate(self.ekfs)
        ]
        self._keep(alive)
        n = len(self.ekfs)
        if 1 < n <= 64 and s.merge_distance_m > 0:
            keep = [True] * n
            for i in range(n):
                if not keep[i]:
                    continue
                for j in range(i + 1, n):
                    if keep[j] and np.linalg.norm(self.ekfs[i].x[:3] - self.ekfs[j].x[:3]) < s.merge_distance_m:
                        if self.log_likelihood[i] >= self.log_likelihood[j]:
                            keep[j] = False
                        else:
                            keep[i] = False
                            break
            self._keep(keep)
        if self.ekfs:
            self._normalise()
        self.counters.max_hypotheses = max(self.counters.max_hypotheses, len(self.ekfs))

    def _keep(self, mask: list[bool]):
        if all(mask):
            return
        self.ekfs = [ekf for ekf, k in zip(self.ekfs, mask) if k]
        self.log_likelihood = [ll for ll, k in zip(self.log_likelihood, mask) if k]
        self.outliers = [o for o, k in zip(self.outliers, mask) if k]

    def _best(self, time_s: float) -> FilterpyEstimate | None:
        if not self.ekfs:
            return None
        best = max(range(len(self.ekfs)), key=self.log_likelihood.__getitem__)
        ekf = self.ekfs[best]
        return FilterpyEstimate(
            time_s,
            ekf.x[:3].copy(),
            ekf.x[3:].copy(),
            ekf.P.copy(),
            len(self.ekfs),
            float(math.exp(self.log_likelihood[best])),
        )


def run_filterpy_glac(scene: Scene, reads: Reads, *, progress: bool = False, **params) -> Track:
    """Tracks every tag in ``reads`` (one :class:`FilterpyGlac` per EPC) and
    returns one row per estimate, in time order (causal, as ``scattertrack.track.run``)."""
    index = {a.id: i for i, a in enumerate(scene.antennas)}
    order = np.argsort(reads.time_s, kind="stable")
    trackers: dict[str, FilterpyGlac] = {}
    rows: list[tuple] = []
    times = reads.time_s[order]
    epcs = reads.epc[order]
    antennas = reads.antenna[order]
    frequencies = reads.frequency_hz[order]
    phases = reads.phase_rad[order]
    iterator = range(len(order))
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, unit="read", desc="filterpy glac", leave=False)
    for k in iterator:
        epc = str(epcs[k])
        tracker = trackers.get(epc)
        if tracker is None:
            tracker = trackers[epc] = FilterpyGlac(scene, **params)
        if int(antennas[k]) not in index:
            raise ValueError(f"reads name antenna {int(antennas[k])}, which the scene does not define")
        e = tracker.step(float(times[k]), index[int(antennas[k])], float(frequencies[k]), float(phases[k]))
        if e is not None:
            rows.append((e.time_s, epc, e.position, e.velocity, np.sqrt(np.clip(np.diag(e.covariance)[:3], 0, None))))
    skipped = SkipReport()
    for tracker in trackers.values():
        if tracker.counters.out_of_order:
            skipped.add("read out of time order (declined by tracker)", n=tracker.counters.out_of_order)
    track = Track(
        time_s=np.array([r[0] for r in rows], dtype=float),
        epc=np.array([r[1] for r in rows], dtype=str) if rows else np.zeros(0, dtype=str),
        position=np.array([r[2] for r in rows], dtype=float).reshape(-1, 3),
        velocity=np.array([r[3] for r in rows], dtype=float).reshape(-1, 3),
        sigma=np.array([r[4] for r in rows], dtype=float).reshape(-1, 3),
        skipped=skipped,
    )
    track.stats = {epc: t.counters for epc, t in trackers.items()}  # type: ignore[attr-defined]
    return track
