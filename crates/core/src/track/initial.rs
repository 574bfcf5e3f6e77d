//! GLAC initial state pruning (sec. 3.2.2): a handful of initial positions
//! and velocities from the first fraction of a second of asynchronous reads.
//!
//! 1. Synchronise: per antenna, two reads around a common reference time
//!    t_x are unwrapped and interpolated to t_x. Unwrapping is done in the
//!    distance domain, candidate by candidate (the second read's candidate
//!    nearest the first's), so reads on different hop channels, whose
//!    wavelengths differ by up to 3 %, unwrap correctly.
//! 2. Trilaterate: every combination of candidate spheres (3D) or circles
//!    (2D) of a well-conditioned antenna triple gives intersection points.
//!    2D follows the paper: of the six pairwise circle intersections, the
//!    closest three make a triangle whose centroid is the estimate, and a
//!    triangle with perimeter above D_th is dropped. 3D has no triangle:
//!    three spheres meet in two mirror points (the region keeps one);
//!    the analogue of the perimeter test is the residual test below.
//! 3. Every point is refined by least squares against the nearest candidate
//!    of every antenna and kept only if each range residual is below
//!    `residual_threshold_m` and it lies in the region.
//! 4. Velocity: the interpolated phase slope of antenna i is the projected
//!    velocity |Vᵢ| = Δφᵢ λ / (4π Δt) = eᵢ · V; least squares over antennas.
//! 5. Likelihood (eq. 10): L₀ = Πᵢ F(dᵢ; zᵢ*, R₀).

use nalgebra::{Matrix3, Vector2, Vector3};

use super::candidates::nearest_candidate;
use super::read_budget::Budget;
use super::PhaseRead;
use crate::filter::log_gaussian;
use crate::geometry::{circle_intersections, multilaterate, sphere_intersections};
use crate::model::{StateMatrix, StateVector};
use crate::scene::Scene;

/// Settings of the initial state search.
#[derive(Debug, Clone, PartialEq)]
pub struct InitialState {
    /// Perimeter threshold D_th for 2D triangles, metres.
    pub perimeter_threshold_m: f64,
    /// Largest range residual a kept position may have at any antenna, metres.
    pub residual_threshold_m: f64,
    /// Extra 1-sigma range error from interpolation, metres (adds to R₀).
    pub interpolation_sigma_m: f64,
    /// How far outside the region a position may lie, metres.
    pub region_margin_m: f64,
    /// Positions closer than this are merged (the better one kept), metres.
    pub merge_distance_m: f64,
    /// At most this many hypotheses (best likelihood first). Mod-π readers
    /// double the candidates per antenna, about 8× the initial set in 3D
    /// (5,300 measured on a 3D arm against 190 mod 2π): a cap of 2,000 cut
    /// the true one in a tenth of such runs (6,000: the search and its
    /// replay stay within a few hundred ms on the first reads).
    pub max_hypotheses: usize,
    /// Fastest plausible range rate, m/s: unwrapping two reads of one
    /// antenna also tries the branches one ambiguity step away when the
    /// tag could have moved that far between them.
    pub max_speed_m_s: f64,
    /// An antenna whose two reads around t_x are further apart than this
    /// (s) is left out: too many unwrapping branches.
    pub max_pair_gap_s: f64,
}

impl Default for InitialState {
    fn default() -> Self {
        Self {
            perimeter_threshold_m: 0.06,
            residual_threshold_m: 0.015,
            interpolation_sigma_m: 0.004,
            region_margin_m: 0.05,
            merge_distance_m: 0.01,
            max_hypotheses: 6_000,
            max_speed_m_s: 0.6,
            max_pair_gap_s: 0.3,
        }
    }
}

/// One initial candidate trajectory.
#[derive(Debug, Clone)]
pub struct InitialHypothesis {
    /// [p, v] at the reference time (m, m/s).
    pub state: StateVector,
    /// log L₀ (eq. 10), unnormalised.
    pub log_likelihood: f64,
    /// Worst range residual at any antenna, metres.
    pub max_residual_m: f64,
}

/// One antenna's synchronised candidate: distance and range rate at t_x.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    distance: f64,
    range_rate: f64,
}

struct AntennaCandidates {
    /// Sorted by distance.
    candidates: Vec<Candidate>,
    /// Time between the two reads that were unwrapped, seconds.
    gap_s: f64,
}

impl AntennaCandidates {
    fn nearest(&self, d: f64) -> Candidate {
        let i = self.candidates.partition_point(|c| c.distance < d);
        let mut best = self.candidates[i.min(self.candidates.len() - 1)];
        if i > 0 && (self.candidates[i - 1].distance - d).abs() < (best.distance - d).abs() {
            best = self.candidates[i - 1];
        }
        best
    }

    /// Every candidate within `tolerance` (m) of `d`, nearest first.
    fn within(&self, d: f64, tolerance: f64) -> Vec<Candidate> {
        let mut near: Vec<Candidate> =
            self.candidates.iter().copied().filter(|c| (c.distance - d).abs() <= tolerance).collect();
        near.sort_by(|a, b| (a.distance - d).abs().total_cmp(&(b.distance - d).abs()));
        if near.is_empty() {
            near.push(self.nearest(d));
        }
        near
    }
}

/// The reference time t_x and the initial hypotheses there, or `None`
/// when the reads do not yet allow it (fewer than three antennas with two
/// reads each, or no position survives).
///
/// `reads` must be time-ordered. `range_sigma_m` is the 1-sigma range noise
/// implied by the phase noise (σ_φ λ / 4π). `with_velocity == false` gives
/// zero velocities (the no-velocity variant). The whole search at once:
/// [`InitialSearch`] runs it a budget at a time.
pub fn initial_hypotheses(
    scene: &Scene,
    reads: &[PhaseRead],
    settings: &InitialState,
    range_sigma_m: f64,
    with_velocity: bool,
) -> Option<(f64, Vec<InitialHypothesis>)> {
    let mut search = InitialSearch::new(scene, reads, settings, range_sigma_m, with_velocity)?;
    search.advance(scene, &mut Budget::unlimited()).expect("an unlimited budget completes the search")
}

/// Work units (see [`Budget`]) of one trilateration of a candidate triple
/// (a sphere or circle intersection with its region test: half a hypothesis
/// step, measured).
const INTERSECTIONS_PER_UNIT: u64 = 2;
/// Largest work of refining one intersection point: two least-squares
/// fixes, the likelihood, and up to 64 velocity combinations.
const REFINE_MAX_UNITS: u64 = 112;
/// Work of taking one hypothesis off the heap and checking it against the
/// kept ones (a grid lookup of the 27 neighbouring cells; ~0.25 µs per
/// unit measured in this stage at 4 units, so 8).
const MERGE_UNITS: u64 = 8;

/// Where a search stands.
#[derive(Debug, Clone)]
enum Stage {
    /// Trilaterating candidate triples: the next (first, second) antenna
    /// candidate indices of the best triple.
    Intersect { first: usize, second: usize },
    /// Refining the intersection points, the next one.
    Refine { next: usize },
    /// Taking hypotheses best first and merging near-duplicates.
    Merge,
}

/// Initial state pruning run a budget at a time ([`InitialSearch::advance`]):
/// the same steps and the same result as [`initial_hypotheses`], spread
/// over as many calls as the budgets need.
pub struct InitialSearch {
    t_x: f64,
    axes: usize,
    settings: InitialState,
    with_velocity: bool,
    anchors: Vec<Vector3<f64>>,
    lists: Vec<AntennaCandidates>,
    triple: [usize; 3],
    r0: f64,
    stage: Stage,
    points: Chunked<Vector3<f64>>,
    /// Refined hypotheses, best (then earliest) first off the heap.
    ranked: std::collections::BinaryHeap<Ranked>,
    hypotheses: Chunked<Option<InitialHypothesis>>,
    kept: Vec<InitialHypothesis>,
    /// Kept positions by merge-distance cell (the merge test looks at the
    /// 27 cells around a position instead of every kept one).
    grid: super::key_hash::CellMap<Vec<usize>>,
}

/// A growing list in fixed-size blocks: the search's points and refined
/// hypotheses run to megabytes in mod-π 3D, and one `Vec` doubling there
/// copies them all (and faults in fresh pages) within a single read.
struct Chunked<T> {
    blocks: Vec<Vec<T>>,
    len: usize,
}

/// Elements per block of [`Chunked`].
const BLOCK: usize = 4096;

impl<T> Default for Chunked<T> {
    fn default() -> Self {
        Self { blocks: Vec::new(), len: 0 }
    }
}

impl<T> Chunked<T> {
    fn push(&mut self, value: T) {
        // The first block grows as a Vec (a small search, the common case,
        // holds only what it found: 10,000 tags may search at once); full
        // blocks after it are allocated whole.
        if self.blocks.is_empty() {
            self.blocks.push(Vec::new());
        } else if self.len % BLOCK == 0 {
            self.blocks.push(Vec::with_capacity(BLOCK));
        }
        self.blocks.last_mut().expect("a block was pushed").push(value);
        self.len += 1;
    }

    fn len(&self) -> usize {
        self.len
    }

    fn get(&self, i: usize) -> &T {
        &self.blocks[i / BLOCK][i % BLOCK]
    }

    fn get_mut(&mut self, i: usize) -> &mut T {
        &mut self.blocks[i / BLOCK][i % BLOCK]
    }
}

/// A refined hypothesis' place in the best-first order: higher likelihood
/// first, ties by discovery order (what a stable sort gives).
#[derive(Debug, Clone, Copy)]
struct Ranked {
    log_likelihood: f64,
    index: usize,
}

impl PartialEq for Ranked {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}
impl Eq for Ranked {}
impl PartialOrd for Ranked {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Ranked {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.log_likelihood.total_cmp(&other.log_likelihood).then(other.index.cmp(&self.index))
    }
}

impl InitialSearch {
    /// Synchronises the reads (cheap: a few candidates per antenna) and
    /// sets the search up; `None` when the reads do not allow one.
    pub fn new(
        scene: &Scene,
        reads: &[PhaseRead],
        settings: &InitialState,
        range_sigma_m: f64,
        with_velocity: bool,
    ) -> Option<Self> {
        let n_antennas = scene.antennas.len();
        let mut per_antenna: Vec<Vec<&PhaseRead>> = vec![Vec::new(); n_antennas];
        for m in reads {
            per_antenna[m.antenna].push(m);
        }
        let usable: Vec<usize> = (0..n_antennas).filter(|&a| per_antenna[a].len() >= 2).collect();
        if usable.len() < 3 {
            return None;
        }
        // t_x: the latest time at which every usable antenna has been read, so
        // the hypotheses start as late (as close to "now") as possible and one
        // antenna's value at t_x is a reading, not an interpolation.
        let t_x = usable.iter().map(|&a| per_antenna[a].last().unwrap().time_s).fold(f64::INFINITY, f64::min);

        let axes = scene.dimensions;
        let (usable, lists): (Vec<usize>, Vec<AntennaCandidates>) = usable
            .iter()
            .filter_map(|&a| synchronise(scene, a, &per_antenna[a], t_x, settings).map(|l| (a, l)))
            .unzip();
        if usable.len() < 3 || lists.iter().any(|l| l.candidates.is_empty()) {
            return None;
        }
        let anchors: Vec<Vector3<f64>> = usable.iter().map(|&a| scene.antennas[a].position).collect();
        let triple = best_triple(&anchors, axes)?;
        let r0 = range_sigma_m * range_sigma_m + settings.interpolation_sigma_m.powi(2);
        Some(Self {
            t_x,
            axes,
            settings: settings.clone(),
            with_velocity,
            anchors,
            lists,
            triple,
            r0,
            stage: Stage::Intersect { first: 0, second: 0 },
            points: Chunked::default(),
            ranked: std::collections::BinaryHeap::new(),
            hypotheses: Chunked::default(),
            kept: Vec::new(),
            grid: Default::default(),
        })
    }

    /// Runs the search on within `budget`: `None` while work is left (call
    /// again with the next read's budget), then the result of
    /// [`initial_hypotheses`].
    pub fn advance(&mut self, scene: &Scene, budget: &mut Budget) -> Option<Option<(f64, Vec<InitialHypothesis>)>> {
        let axes = self.axes;
        let settings = &self.settings;
        let in_region = |p: &Vector3<f64>| {
            scene.region.as_ref().is_none_or(|r| r.contains(p, settings.region_margin_m, axes))
        };
        if let Stage::Intersect { mut first, mut second } = self.stage {
            let tolerance = settings.residual_threshold_m;
            let [t0, t1, t2] = self.triple;
            let (l0, l1, l2) = (&self.lists[t0], &self.lists[t1], &self.lists[t2]);
            let (a0, a1, a2) = (self.anchors[t0], self.anchors[t1], self.anchors[t2]);
            let row_units = (l2.candidates.len() as u64).div_ceil(INTERSECTIONS_PER_UNIT);
            while first < l0.candidates.len() {
                let c0 = l0.candidates[first];
                while second < l1.candidates.len() {
                    let c1 = l1.candidates[second];
                    if (c0.distance - c1.distance).abs() > (a0 - a1).norm() + tolerance {
                        second += 1;
                        continue; // spheres cannot meet: skip the inner loop early
                    }
                    if !budget.try_spend(row_units) {
                        self.stage = Stage::Intersect { first, second };
                        return None;
                    }
                    for c2 in &l2.candidates {
                        if axes == 3 {
                            if let Some(pair) =
                                sphere_intersections(&a0, c0.distance, &a1, c1.distance, &a2, c2.distance, tolerance)
                            {
                                for p in pair.into_iter().filter(in_region) {
                                    self.points.push(p);
                                }
                            }
                        } else if let Some(p) = perimeter_centroid(
                            [a0, a1, a2],
                            [c0.distance, c1.distance, c2.distance],
                            scene.plane_z,
                            settings.perimeter_threshold_m,
                            tolerance,
                        ) {
                            if in_region(&p) {
                                self.points.push(p);
                            }
                        }
                    }
                    second += 1;
                }
                second = 0;
                first += 1;
            }
            self.stage = Stage::Refine { next: 0 };
        }
        if let Stage::Refine { mut next } = self.stage {
            let mut distances = vec![0.0; self.lists.len()];
            let mut rates = vec![0.0; self.lists.len()];
            while next < self.points.len() {
                if !budget.affords(REFINE_MAX_UNITS) {
                    self.stage = Stage::Refine { next };
                    return None;
                }
                let (hypothesis, units) = self.refine(*self.points.get(next), &in_region, &mut distances, &mut rates);
                budget.spend(units);
                if let Some(h) = hypothesis {
                    self.ranked.push(Ranked { log_likelihood: h.log_likelihood, index: self.hypotheses.len() });
                    self.hypotheses.push(Some(h));
                }
                next += 1;
            }
            self.points = Chunked::default();
            self.stage = Stage::Merge;
        }
        // Best first, then merge near-duplicates (the same fix reached from
        // several intersection points).
        let md = settings.merge_distance_m;
        let cell = |p: &Vector3<f64>| {
            if md > 0.0 {
                [(p.x / md).floor() as i64, (p.y / md).floor() as i64, (p.z / md).floor() as i64]
            } else {
                [0; 3]
            }
        };
        while self.kept.len() < settings.max_hypotheses {
            if !budget.try_spend(MERGE_UNITS) {
                return None;
            }
            let Some(top) = self.ranked.pop() else { break };
            let h = self.hypotheses.get_mut(top.index).take().expect("each hypothesis leaves the heap once");
            let p: Vector3<f64> = h.state.fixed_rows::<3>(0).into();
            let c = cell(&p);
            let kept = &self.kept;
            let near = (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dz| {
                        self.grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).is_some_and(|ids| {
                            ids.iter().any(|&k| (kept[k].state.fixed_rows::<3>(0) - p).norm() <= md)
                        })
                    })
                })
            });
            if !near {
                self.grid.entry(c).or_default().push(self.kept.len());
                self.kept.push(h);
            }
        }
        let kept = std::mem::take(&mut self.kept);
        Some(if kept.is_empty() { None } else { Some((self.t_x, kept)) })
    }

    /// Refines one intersection point (two rounds of "pick nearest
    /// candidates, then least squares": the first pick at the rough
    /// intersection, the second at the refined position), scores it and
    /// finds its velocity: the hypothesis, if it passes, and the work done.
    fn refine(
        &self,
        start: Vector3<f64>,
        in_region: &impl Fn(&Vector3<f64>) -> bool,
        distances: &mut [f64],
        rates: &mut [f64],
    ) -> (Option<InitialHypothesis>, u64) {
        let (axes, lists, anchors, settings) = (self.axes, &self.lists, &self.anchors, &self.settings);
        let mut p = start;
        for _ in 0..2 {
            for (k, list) in lists.iter().enumerate() {
                let c = list.nearest((p - anchors[k]).norm());
                distances[k] = c.distance;
                rates[k] = c.range_rate;
            }
            match multilaterate(anchors, distances, p, axes, 6) {
                Some(fix) => p = fix.position,
                None => return (None, 8),
            }
        }
        if !in_region(&p) {
            return (None, 8);
        }
        let mut log_likelihood = 0.0;
        let mut max_residual: f64 = 0.0;
        for (k, list) in lists.iter().enumerate() {
            let d = (p - anchors[k]).norm();
            let c = list.nearest(d);
            distances[k] = c.distance;
            rates[k] = c.range_rate;
            max_residual = max_residual.max((d - c.distance).abs());
            log_likelihood += log_gaussian(d - c.distance, self.r0);
        }
        if max_residual > settings.residual_threshold_m {
            return (None, 8);
        }
        let (velocity, combinations) = if self.with_velocity {
            best_velocity(&p, anchors, lists, rates, axes, self.r0, settings)
        } else {
            (Vector3::zeros(), 0)
        };
        let mut state = StateVector::zeros();
        state.fixed_rows_mut::<3>(0).copy_from(&p);
        state.fixed_rows_mut::<3>(3).copy_from(&velocity);
        let units = (16 + 3 * combinations as u64 / 2).min(REFINE_MAX_UNITS);
        (Some(InitialHypothesis { state, log_likelihood, max_residual_m: max_residual }), units)
    }
}

/// Initial covariance: position σ_p and velocity σ_v on the moving axes,
/// zero on the fixed ones (z in 2D; velocity without a velocity model).
pub fn initial_covariance(axes: usize, position_sigma: f64, velocity_sigma: f64) -> StateMatrix {
    let mut p = StateMatrix::zeros();
    for i in 0..axes {
        p[(i, i)] = position_sigma * position_sigma;
        p[(i + 3, i + 3)] = velocity_sigma * velocity_sigma;
    }
    p
}

/// Candidate (distance, range rate) pairs of one antenna at t_x, or
/// `None` when its reads around t_x are too far apart to unwrap.
///
/// The two reads nearest t_x that bracket it (or the last two, when t_x
/// is this antenna's last read) are unwrapped candidate by candidate: for
/// each candidate of the first read, the second read's nearest candidate
/// (the tag usually moves far less than half an ambiguity step between two
/// reads of one antenna), plus the next branches when `max_speed_m_s`
/// allows the tag to have moved that far (long gaps, mod-π readers).
/// Linear interpolation to t_x gives the distance, and the slope gives the
/// projected velocity Δd/Δt = Δφ λ / (4π Δt).
fn synchronise(
    scene: &Scene,
    antenna: usize,
    reads: &[&PhaseRead],
    t_x: f64,
    settings: &InitialState,
) -> Option<AntennaCandidates> {
    let after = reads.iter().position(|m| m.time_s > t_x).unwrap_or(reads.len());
    let (ia, ib) = if after == 0 {
        (0, 1)
    } else if after >= reads.len() {
        (reads.len() - 2, reads.len() - 1)
    } else {
        (after - 1, after)
    };
    let (ra, rb) = (reads[ia], reads[ib]);
    let dt = (rb.time_s - ra.time_s).max(1e-6);
    if dt > settings.max_pair_gap_s {
        return None;
    }
    let (res_a, s_a) = (scene.distance_residue(antenna, ra.frequency_hz, ra.phase_rad), scene.candidate_spacing(ra.frequency_hz));
    let (res_b, s_b) = (scene.distance_residue(antenna, rb.frequency_hz, rb.phase_rad), scene.candidate_spacing(rb.frequency_hz));
    let (lo, hi) = scene.distance_bounds(antenna);
    let (lo, hi) = ((lo - settings.region_margin_m).max(0.0), hi + settings.region_margin_m);
    let alpha = (t_x - ra.time_s) / dt;
    let reach = (settings.max_speed_m_s * dt).max(0.5 * s_b);
    let n_lo = ((lo - res_a) / s_a).floor().max(0.0) as i64;
    let n_hi = ((hi - res_a) / s_a).ceil() as i64 + 1;
    let mut candidates = Vec::with_capacity((n_hi - n_lo + 1).max(0) as usize);
    for n in n_lo..=n_hi {
        let d_a = res_a + n as f64 * s_a;
        let nearest = nearest_candidate(res_b, s_b, d_a);
        for branch in -2i32..=2 {
            let d_b = nearest + branch as f64 * s_b;
            if branch != 0 && (d_b < 0.0 || (d_b - d_a).abs() > reach) {
                continue;
            }
            let distance = d_a + alpha * (d_b - d_a);
            if distance >= lo && distance <= hi {
                candidates.push(Candidate { distance, range_rate: (d_b - d_a) / dt });
            }
        }
    }
    candidates.sort_by(|a, b| a.distance.total_cmp(&b.distance));
    Some(AntennaCandidates { candidates, gap_s: dt })
}

/// The antenna triple with the best geometry: the largest triangle (3D:
/// sphere intersections are well defined; collinear triples only give a
/// circle). In 2D any triple works (circles meet in points), but a large
/// triangle still conditions the fix best.
fn best_triple(anchors: &[Vector3<f64>], axes: usize) -> Option<[usize; 3]> {
    let mut best: Option<([usize; 3], f64)> = None;
    let n = anchors.len();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let area = 0.5 * (anchors[j] - anchors[i]).cross(&(anchors[k] - anchors[i])).norm();
                if best.is_none_or(|(_, a)| area > a) {
                    best = Some(([i, j, k], area));
                }
            }
        }
    }
    match best {
        Some((t, area)) if area > 1e-6 || axes == 2 => Some(t),
        _ => None,
    }
}

/// 2D trilateration of the paper (Fig. 4a): the three circle pairs give up
/// to six points; the triangle with one point from each pair and the
/// smallest perimeter is kept if its perimeter is below `threshold` (D_th),
/// and its centroid is the estimate. Circles live in the plane z = plane_z:
/// a sphere of radius d about an antenna at height h cuts it in a circle of
/// radius √(d² − (plane_z − h)²).
fn perimeter_centroid(
    anchors: [Vector3<f64>; 3],
    distances: [f64; 3],
    plane_z: f64,
    threshold: f64,
    tolerance: f64,
) -> Option<Vector3<f64>> {
    let mut centres = [Vector2::zeros(); 3];
    let mut radii = [0.0; 3];
    for k in 0..3 {
        let dz = plane_z - anchors[k].z;
        let r2 = distances[k] * distances[k] - dz * dz;
        if r2 < 0.0 {
            return None;
        }
        centres[k] = Vector2::new(anchors[k].x, anchors[k].y);
        radii[k] = r2.sqrt();
    }
    let pair = |i: usize, j: usize| circle_intersections(&centres[i], radii[i], &centres[j], radii[j], tolerance);
    let (p01, p12, p02) = (pair(0, 1)?, pair(1, 2)?, pair(0, 2)?);
    let mut best: Option<(f64, Vector2<f64>)> = None;
    for a in &p01 {
        for b in &p12 {
            for c in &p02 {
                let perimeter = (a - b).norm() + (b - c).norm() + (c - a).norm();
                if best.is_none_or(|(p, _)| perimeter < p) {
                    best = Some((perimeter, (a + b + c) / 3.0));
                }
            }
        }
    }
    let (perimeter, centroid) = best?;
    (perimeter <= threshold).then(|| Vector3::new(centroid.x, centroid.y, plane_z))
}

/// The velocity of a fixed position when unwrapping branches leave an
/// antenna with several candidates of nearly the same interpolated distance
/// but different range rates (a branch one step away moves the
/// interpolated distance by only (1 − α)·s when t_x is near the second
/// read): every combination of the candidates within the residual
/// threshold is tried (at most 64), and the one whose least-squares
/// velocity explains the range rates best wins, with a weak prior towards
/// slow motion (σ = max_speed / 2) that decides when there is no
/// redundancy (three antennas). Writes the chosen rates into `rates`;
/// returns the velocity and the combinations tried.
fn best_velocity(
    p: &Vector3<f64>,
    anchors: &[Vector3<f64>],
    lists: &[AntennaCandidates],
    rates: &mut [f64],
    axes: usize,
    range_variance: f64,
    settings: &InitialState,
) -> (Vector3<f64>, usize) {
    let options: Vec<Vec<Candidate>> = lists
        .iter()
        .zip(anchors)
        .map(|(l, a)| l.within((p - a).norm(), settings.residual_threshold_m))
        .collect();
    let combinations: usize = options.iter().map(|o| o.len()).product();
    if combinations == 1 {
        return (projected_velocity(p, anchors, rates, axes), 1);
    }
    let prior = 1.0 / (0.5 * settings.max_speed_m_s).powi(2);
    let mut trial = rates.to_vec();
    let (mut best_score, mut best_velocity) = (f64::INFINITY, Vector3::zeros());
    for index in 0..combinations.min(64) {
        let mut rest = index;
        for (k, o) in options.iter().enumerate() {
            trial[k] = o[rest % o.len()].range_rate;
            rest /= o.len();
        }
        let v = projected_velocity(p, anchors, &trial, axes);
        let mut score = prior * v.norm_squared();
        for (k, list) in lists.iter().enumerate() {
            let mut e = (p - anchors[k]).normalize();
            if axes == 2 {
                e.z = 0.0;
            }
            // A slope from two reads Δt apart has variance 2R/Δt².
            let variance = 2.0 * range_variance / (list.gap_s * list.gap_s);
            score += (trial[k] - e.dot(&v)).powi(2) / variance;
        }
        if score < best_score {
            best_score = score;
            best_velocity = v;
            rates.copy_from_slice(&trial);
        }
    }
    (best_velocity, combinations.min(64))
}

/// Least-squares velocity from projected velocities: eᵢ · V = ṙᵢ with eᵢ
/// the unit vector from antenna i to the tag (Fig. 4b). 2D solves for
/// (vx, vy) only. Returns zero when the geometry is singular.
fn projected_velocity(p: &Vector3<f64>, anchors: &[Vector3<f64>], rates: &[f64], axes: usize) -> Vector3<f64> {
    let mut ata = Matrix3::<f64>::zeros();
    let mut atb = Vector3::<f64>::zeros();
    for (a, &rate) in anchors.iter().zip(rates) {
        let mut e = (p - a).normalize();
        if axes == 2 {
            e.z = 0.0;
        }
        ata += e * e.transpose();
        atb += e * rate;
    }
    if axes == 2 {
        ata[(2, 2)] = 1.0;
    }
    ata.try_inverse().map_or(Vector3::zeros(), |inv| inv * atb)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Antenna, Region};

    fn scene(dimensions: usize) -> Scene {
        let pos = [[0.0, 0.0], [0.0, 0.3], [0.0, 0.8], [0.8, 0.8]];
        let antennas = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: 0.7 * i as f64, role: Default::default() })
            .collect();
        let region = if dimensions == 3 {
            Region { min: Vector3::new(-0.5, -0.5, 0.05), max: Vector3::new(1.5, 1.5, 1.5) }
        } else {
            Region { min: Vector3::new(0.1, -0.5, 0.0), max: Vector3::new(1.6, 1.5, 0.0) }
        };
        Scene::new(dimensions, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, Some(region), vec![]).unwrap()
    }

    fn reads_for(scene: &Scene, p0: Vector3<f64>, v: Vector3<f64>, n: usize) -> Vec<PhaseRead> {
        (0..n)
            .map(|k| {
                let t = 0.033 * k as f64;
                let a = k % scene.antennas.len();
                let d = (p0 + v * t - scene.antennas[a].position).norm();
                let f = 915.25e6;
                PhaseRead { time_s: t, antenna: a, frequency_hz: f, phase_rad: scene.ideal_phase(a, f, d) }
            })
            .collect()
    }

    #[test]
    fn noiseless_reads_contain_the_truth_3d_and_2d() {
        for (dims, p0, v) in [
            (3, Vector3::new(0.36, 0.5, 0.71), Vector3::new(0.1, -0.05, 0.08)),
            (2, Vector3::new(0.6, 0.3, 0.0), Vector3::new(0.3, 0.2, 0.0)),
        ] {
            let scene = scene(dims);
            let reads = reads_for(&scene, p0, v, 12);
            let (t_x, hyps) = initial_hypotheses(&scene, &reads, &InitialState::default(), 0.0026, true).unwrap();
            let truth = p0 + v * t_x;
            let best = hyps
                .iter()
                .map(|h| ((h.state.fixed_rows::<3>(0) - truth).norm(), h))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            assert!(best.0 < 0.01, "{dims}D: nearest initial position {} m off ({} hypotheses)", best.0, hyps.len());
            let dv = (best.1.state.fixed_rows::<3>(3) - v).norm();
            assert!(dv < 0.05, "{dims}D: velocity {dv} m/s off");
        }
    }

    #[test]
    fn waits_for_three_antennas() {
        let scene = scene(3);
        let reads = reads_for(&scene, Vector3::new(0.4, 0.4, 0.6), Vector3::zeros(), 12);
        let two: Vec<PhaseRead> = reads.into_iter().filter(|m| m.antenna < 2).collect();
        assert!(initial_hypotheses(&scene, &two, &InitialState::default(), 0.0026, true).is_none());
    }
}
