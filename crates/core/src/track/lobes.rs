//! Lobe-level evidence for the wideband particle filters.
//!
//! Every receiver's candidates form a comb one wavelength λ apart
//! (eq. 5.1), so the likelihood has *lobes*: positions whose path lengths
//! sit on other teeth, `n + k` instead of `n` for an integer shift vector
//! `k`. With receivers in line with the transmitter some shifts are
//! (nearly) consistent with every receiver's phase, and only the wideband
//! weights `w_j(n)` — the time-of-flight envelope — tell the lobes apart. A
//! particle filter whose particles all sit in one lobe never compares it with
//! another: within a lobe every particle gets the same `w_j(n_j)`. This
//! file makes that comparison explicit, per frame, and accumulates it.
//!
//! **Per-frame evidence of shift `k` against the filter's lobe** (a profile
//! log-likelihood ratio): with `x₀*` the weighted least-squares fit of the
//! filter's teeth `n` (started at the filter's estimate) and `x_k*` the fit
//! of the teeth `n + k`,
//!
//! `λ_k = ℓ(x_k*) − ℓ(x₀*)`,  `ℓ(x) = Σ_j log w_j(n_j(x)) + log N(d_j(x); D_j(n_j), σ_j²)`
//!
//! (eq. 5.2 at the lobes' best points, nats). For every shift of the
//! lattice it is first approximated at linear order — the weights' change
//! `Σ_j log w_j(n_j + k_j) − log w_j(n_j)` minus half the whitened
//! least-squares misfit `χ²_lin(k) = zᵀ(I − A(AᵀA)⁻¹Aᵀ)z`, `z_j = k_j λ / σ_j`,
//! `A` the whitened path-length Jacobian — and the few best shifts are then
//! evaluated exactly (Gauss–Newton on their teeth, in the region).
//!
//! **Accumulation and switch** (a CUSUM-type test): `L_k ← clamp(L_k +
//! clamp(λ_k, −c, c), −B, ∞)`. `e^{L_k}` is then the posterior odds of lobe
//! `k` against the filter's (equal prior odds) over the recent frames; the
//! filter moves its particles to lobe `k` when `L_k > h`. Levels (defaults,
//! chosen on our simulator — `bench/turbotrack_lobes.py`, the in-line
//! layout at 2 dB and the multipath arm at 4 dB — see docs/turbotrack.md):
//!
//! - `h = lobe_switch_nats = 10`: posterior odds of 22 000 : 1 for the other
//!   lobe.
//! - `c = lobe_frame_cap_nats = 2`: one frame moves any `L_k` by at most 2
//!   nats, so one corrupted frame (a burst, a reflection) cannot switch; from
//!   an even start a switch needs `h / c = 5` agreeing frames at least.
//! - `B = lobe_floor_nats = 200`: how far below the filter's lobe an
//!   alternative's evidence may sink, i.e. how much history protects a lobe
//!   the filter has been confirmed on: `(B + h) / c = 105` frames (0.35 s at
//!   300 frames/s) of contrary evidence before it is left. Multipath makes
//!   the per-frame evidence correlated: on the simulated multipath arm at
//!   4 dB a reflection favoured a wrong lobe for a few tens of frames, and
//!   with `B = 20, c = 5` the filter left the right lobe in 19 of 20 starts
//!   (0 with these levels). A lobe at the floor keeps `e^{−200}` of
//!   posterior mass: nothing in the reported covariance.
//!
//! The evidence starts over when the filter's own lobe jumps (`JUMP_M`),
//! and a frame that lacks a receiver is skipped (`ADOPT_AFTER`).
//!
//! **Reported covariance**: the exactly evaluated lobes enter the reported
//! covariance as a mixture about the reported state,
//! `Σ = Σ_mode + Σ_k p_k (x_k* − x̂)(x_k* − x̂)ᵀ`, `p_k = e^{L_k} / (1 + Σ_i e^{L_i})`:
//! while the lobes are unresolved the sigma covers them.

use nalgebra::{Matrix3, Vector3};

use crate::geometry::bistatic_distance;

use super::bistatic::{mixture_log_likelihood, HelperGeometry, Receiver};

/// The levels of the lobe test, nats (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeLevels {
    /// `h`: switch when an alternative's accumulated evidence exceeds this.
    pub switch_nats: f64,
    /// `B`: evidence is never below −B.
    pub floor_nats: f64,
    /// `c`: one frame changes an evidence by at most ±c.
    pub frame_cap_nats: f64,
}

/// Frames in a row with another receiver set before the evidence starts
/// over on that set (0.1 s at 300 frames/s, as long as the filter's own
/// outlier run before it starts over).
const ADOPT_AFTER: usize = 30;

/// A jump of the filter's fitted lobe between frames larger than this, m,
/// is a change of lobe (neighbouring lobes are 10-60 cm apart; the tag
/// moves about 1 mm a frame at 30 cm/s and 300 frames/s).
const JUMP_M: f64 = 0.08;

/// A frame whose receiver leaves a single-path residual at least this
/// coherent ([`crate::model::wideband::residual_coherence`]) carries a
/// reflection that its envelope reads as the direct path's: its lobe
/// evidence is biased the same way frame after frame while the tag moves
/// slowly past the reflector, and it is skipped (per-frame and far-lobe
/// tests, and the lobe search on the averaged frame at rest). On the
/// simulated 3D multipath arm (a wall, a cabinet and the floor at 23 dB)
/// the lobe tests otherwise moved the cloud 0.5–0.7 m onto the
/// reflections' lobes, 20 times in 20 s on one seed. A white residual of
/// 20 subcarriers exceeds 0.3 on about 4 % of receivers (a Monte Carlo of
/// the statistic), so about one 4-receiver frame in six is skipped at low
/// SNR too: the lobe tests then need a fifth more frames.
pub const MULTIPATH_COHERENCE: f64 = 0.3;

/// Whether any receiver of the frame shows a reflection ([`MULTIPATH_COHERENCE`]).
pub fn multipath_frame(receivers: &[Receiver]) -> bool {
    receivers.iter().any(|r| r.candidates.residual_coherence > MULTIPATH_COHERENCE)
}

/// Shifts evaluated exactly per frame (the best by accumulated + approximate evidence).
const EXACT_PER_FRAME: usize = 2;

/// The shift lattice for `receivers` receivers: every `k ∈ {−1, 0, 1}^R \ {0}`
/// up to 6 receivers (728 shifts), beyond that the shifts with at most 3
/// non-zero entries (the count grows as R³, not 3^R). Flat, `R` per shift.
pub fn shift_lattice(receivers: usize) -> Vec<i8> {
    let mut out = Vec::new();
    let total = 3usize.pow(receivers.min(12) as u32);
    for code in 0..total {
        let mut c = code;
        let mut shift = Vec::with_capacity(receivers);
        for _ in 0..receivers {
            shift.push((c % 3) as i8 - 1);
            c /= 3;
        }
        if shift.iter().all(|&s| s == 0) {
            continue;
        }
        if receivers > 6 && shift.iter().filter(|&&s| s != 0).count() > 3 {
            continue;
        }
        out.extend(shift);
    }
    out
}

/// Damping added to the normal equations of the lobe fits, m⁻²: a prior
/// of 1 m on each step. It keeps them invertible where the height is
/// unobserved (every antenna at one height and the fit on that plane, as
/// at the region's floor); next to a receiver's 1/σ² ≈ 10⁵ m⁻² it changes
/// nothing else.
pub const NORMAL_DAMPING: f64 = 1.0;

/// One damped Gauss–Newton step at `x` (m) of the weighted least-squares
/// fit `Σ_j ((d_j(x) − t_j) / σ_j)²` of every receiver's bistatic path
/// length `d_j` to its target `t_j = target(j, receiver, d_j)` (a receiver
/// whose target is None is left out); planar scenes step in x and y only.
/// The lobe fits differ only in their targets: fixed teeth
/// (`refine_on_teeth`), teeth moving towards a shift (`follow_to_teeth`),
/// the nearest teeth (`far_lobes::fit_nearest_lobe`). None when the normal
/// equations are singular.
pub fn path_length_step(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    x: &Vector3<f64>,
    target: impl Fn(usize, &Receiver, f64) -> Option<f64>,
) -> Option<Vector3<f64>> {
    let planar = geometry.dimensions == 2;
    let mut normal = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for (j, rx) in receivers.iter().enumerate() {
        let (d, mut g) = bistatic_distance(x, &geometry.tx_position, &rx.position);
        let Some(t) = target(j, rx, d) else { continue };
        if planar {
            g.z = 0.0;
        }
        let w = 1.0 / (rx.candidates.sigma_m * rx.candidates.sigma_m);
        normal += g * g.transpose() * w;
        rhs += g * ((t - d) * w);
    }
    if planar {
        normal[(2, 2)] = 1.0;
    }
    normal += Matrix3::identity() * NORMAL_DAMPING;
    Some(normal.try_inverse()? * rhs)
}

/// Weighted least-squares fit of the teeth `teeth` (one index per
/// receiver): Gauss–Newton on `Σ_j ((d_j(x) − D_j(n_j)) / σ_j)²` from
/// `start`, at most `iterations` steps (planar scenes: x and y only).
/// Returns the point and its χ², or None when the normal equations are
/// singular, a step leaves 5 m, or the fit's nearest teeth are not `teeth`
/// (the lobe does not exist there).
pub fn refine_on_teeth(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    teeth: &[i64],
    start: &Vector3<f64>,
    iterations: usize,
) -> Option<(Vector3<f64>, f64)> {
    let planar = geometry.dimensions == 2;
    let mut x = *start;
    if planar {
        x.z = geometry.plane_z;
    }
    for _ in 0..iterations {
        let step = path_length_step(geometry, receivers, &x, |j, rx, _| teeth.get(j).map(|&n| rx.candidates.distance(n)))?;
        if !(step.norm() < 5.0) {
            return None;
        }
        x += step;
        if step.norm() < 1e-6 {
            break;
        }
    }
    let mut chi2 = 0.0;
    for (rx, &n) in receivers.iter().zip(teeth) {
        let d = bistatic_distance(&x, &geometry.tx_position, &rx.position).0;
        if rx.candidates.nearest_index(d) != n {
            return None;
        }
        chi2 += ((d - rx.candidates.distance(n)) / rx.candidates.sigma_m).powi(2);
    }
    Some((x, chi2))
}

/// Lobe `teeth + shift` reached from the fit `x0` of `teeth` by following
/// the lobe continuously: the target path lengths move from `D_j(n_j)` to
/// `D_j(n_j + k_j)` in `FOLLOW_SUBSTEPS` equal parts, each with two
/// Gauss–Newton steps of at most `FOLLOW_STEP_M`, then `refine_on_teeth`
/// on the shifted teeth. Why not one jump from the linear prediction: where
/// a direction is poorly observed (a rotation about an in-line row of
/// receivers, the height of a tag low over the antennas' plane) a shift of
/// one tooth moves the lobe along an arc, up to metres; the straight
/// prediction leaves the arc and Gauss–Newton from there fails or lands on
/// other teeth, so the lobe was never evaluated (dev seeds 1005 and 1124 of
/// docs/notes/turbotrack-experiments.md: shifts (0, 0, 0, −1) and
/// (+1, 0, −1, 0), 1.4 m away). None as for `refine_on_teeth`.
pub fn follow_to_teeth(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    teeth: &[i64],
    shift: &[i8],
    x0: &Vector3<f64>,
) -> Option<(Vector3<f64>, f64)> {
    let mut x = *x0;
    for part in 1..=FOLLOW_SUBSTEPS {
        let alpha = part as f64 / FOLLOW_SUBSTEPS as f64;
        let target = |j: usize, rx: &Receiver, _| {
            let (&n, &k) = (teeth.get(j)?, shift.get(j)?);
            Some(rx.candidates.distance(n) + alpha * k as f64 * rx.candidates.spacing_m)
        };
        for _ in 0..2 {
            let mut step = path_length_step(geometry, receivers, &x, target)?;
            if !step.iter().all(|v| v.is_finite()) {
                return None;
            }
            if step.norm() > FOLLOW_STEP_M {
                step *= FOLLOW_STEP_M / step.norm();
            }
            x += step;
        }
    }
    let shifted: Vec<i64> = teeth.iter().zip(shift).map(|(&n, &k)| n + k as i64).collect();
    refine_on_teeth(geometry, receivers, &shifted, &x, 3)
}

/// Parts of a shift followed by `follow_to_teeth` (a tooth in 8 parts: 4 cm of path each).
const FOLLOW_SUBSTEPS: usize = 8;

/// Longest step of `follow_to_teeth`, m.
const FOLLOW_STEP_M: f64 = 0.15;

/// The linear-order evidence of every shift of `lattice` (flat, `R` per
/// shift) against the teeth `teeth` fitted at `x0`: `Σ_j Δ log w_j −
/// ½ χ²_lin(k)` (module doc), and the predicted displacement of each lobe.
/// Flat arrays, no allocation once `out` has grown: this runs every frame.
fn approximate_evidence(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    teeth: &[i64],
    x0: &Vector3<f64>,
    lattice: &[i8],
    weight_floor: f64,
    out: &mut Vec<(f64, Vector3<f64>)>,
) {
    const MAX_RX: usize = 16;
    let r = receivers.len().min(MAX_RX);
    let planar = geometry.dimensions == 2;
    out.clear();
    // Whitened Jacobian rows a_j = ∇d_j / σ_j and the normal matrix AᵀA.
    let mut a = [Vector3::zeros(); MAX_RX];
    let mut normal = Matrix3::zeros();
    for (j, rx) in receivers.iter().take(r).enumerate() {
        let (_, mut g) = bistatic_distance(x0, &geometry.tx_position, &rx.position);
        if planar {
            g.z = 0.0;
        }
        a[j] = g / rx.candidates.sigma_m;
        normal += a[j] * a[j].transpose();
    }
    if planar {
        normal[(2, 2)] = 1.0;
    }
    let Some(inverse) = normal.try_inverse() else {
        out.resize(lattice.len() / r.max(1), (f64::NEG_INFINITY, Vector3::zeros()));
        return;
    };
    // δx = (AᵀA)⁻¹ Aᵀ z = Σ_j p_j z_j with p_j = (AᵀA)⁻¹ a_j; the misfit is
    // χ²_lin = |z|² − zᵀA(AᵀA)⁻¹Aᵀz = |z|² − δx·(Aᵀz).
    // The lattice's shifts are −1, 0, 1 per receiver: their log-weight
    // changes are tabulated once (three logarithms per receiver, not one per
    // shift and receiver).
    let mut p = [Vector3::zeros(); MAX_RX];
    let mut lambda = [0.0; MAX_RX];
    let mut tof_of = [[0.0; 3]; MAX_RX];
    for j in 0..r {
        p[j] = inverse * a[j];
        let c = &receivers[j].candidates;
        lambda[j] = c.spacing_m / c.sigma_m;
        let base = c.weight(teeth[j], weight_floor).ln();
        tof_of[j] = [c.weight(teeth[j] - 1, weight_floor).ln() - base, 0.0, c.weight(teeth[j] + 1, weight_floor).ln() - base];
    }
    for shift in lattice.chunks_exact(receivers.len()) {
        let (mut tof, mut zz) = (0.0, 0.0);
        let (mut delta, mut atz) = (Vector3::zeros(), Vector3::zeros());
        for j in 0..r {
            let k = shift[j] as i64;
            if k == 0 {
                continue;
            }
            let z = k as f64 * lambda[j];
            zz += z * z;
            delta += p[j] * z;
            atz += a[j] * z;
            tof += tof_of[j][(k + 1) as usize];
        }
        let chi2 = (zz - delta.dot(&atz)).max(0.0);
        out.push((tof - 0.5 * chi2, delta));
    }
}

/// The spread about `about` (m²) of other lobes at positions `x_k` (m)
/// with log-odds `λ_k` (nats) against the reported one:
/// `Σ_k p_k (x_k − about)(x_k − about)ᵀ`, `p_k = e^{λ_k} / (1 + Σ_i e^{λ_i})`
/// (the reported lobe has odds 1). Every lobe test widens the reported
/// covariance by it (departure 12 of docs/turbotrack.md).
pub fn mixture_spread<I>(lobes: I, about: &Vector3<f64>) -> Matrix3<f64>
where
    I: Iterator<Item = (Vector3<f64>, f64)> + Clone,
{
    let total: f64 = 1.0 + lobes.clone().map(|(_, llr)| llr.exp()).sum::<f64>();
    lobes.fold(Matrix3::zeros(), |acc, (x, llr)| {
        let d = x - about;
        acc + d * d.transpose() * (llr.exp() / total)
    })
}

/// One frame as the lobe tests see it: the scene's helper geometry, the
/// frame's receivers, the mixture's weight floor and the test's levels.
#[derive(Debug, Clone, Copy)]
pub struct LobeFrame<'a> {
    pub geometry: &'a HelperGeometry,
    pub receivers: &'a [Receiver],
    pub weight_floor: f64,
    pub levels: &'a LobeLevels,
}

/// What one frame's lobe test concluded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LobeDecision {
    /// The filter's lobe stays.
    Stay,
    /// Move the particles by this displacement (m): another lobe's
    /// evidence passed the switch level.
    Switch(Vector3<f64>),
}

/// Accumulated evidence of every lattice shift against the filter's lobe.
#[derive(Debug, Clone, Default)]
pub struct LobeEvidence {
    /// The receivers (antenna indices) the shifts refer to; another set resets.
    antennas: Vec<usize>,
    lattice: Vec<i8>,
    /// `L_k`, nats, one per shift.
    evidence: Vec<f64>,
    /// This frame's exactly evaluated shifts: (index, fitted lobe position m).
    exact: Vec<(usize, Vector3<f64>)>,
    /// Whether `evidence` holds anything yet (the first frame sets, later ones add).
    started: bool,
    /// The previous frame's fit of the filter's lobe and its exact lobes
    /// (index, position): warm starts, so a lobe kept across frames needs
    /// one Gauss–Newton step, not four.
    previous_x0: Option<Vector3<f64>>,
    previous: Vec<(usize, Vector3<f64>)>,
    /// Consecutive frames with another receiver set than `antennas`.
    other_set: usize,
    scratch: Vec<(f64, Vector3<f64>)>,
}

impl LobeEvidence {
    /// Forgets every lobe's evidence (a new start of the filter).
    pub fn reset(&mut self) {
        self.started = false;
        self.exact.clear();
        self.previous.clear();
        self.previous_x0 = None;
    }

    /// Whether this frame's receivers are the ones the evidence refers to.
    /// A frame that lacks one (a missed reply on one antenna) is skipped,
    /// not allowed to reset the evidence: a reset would forget how far the
    /// alternatives had fallen behind, and with one receiver fewer the
    /// lobes are told apart by the envelope alone. After `ADOPT_AFTER`
    /// frames in a row with another set the evidence starts over on it.
    fn same_receivers(&mut self, receivers: &[Receiver]) -> bool {
        let same = self.antennas.len() == receivers.len() && self.antennas.iter().zip(receivers).all(|(a, r)| *a == r.antenna);
        if same && !self.lattice.is_empty() {
            self.other_set = 0;
            return true;
        }
        self.other_set += 1;
        if self.lattice.is_empty() || self.other_set > ADOPT_AFTER {
            self.antennas = receivers.iter().map(|r| r.antenna).collect();
            self.lattice = shift_lattice(receivers.len());
            self.evidence = vec![0.0; self.lattice.len() / receivers.len().max(1)];
            self.reset();
            self.other_set = 0;
            return true;
        }
        false
    }

    /// One frame: the evidence of every shift against the lobe of the
    /// filter's estimate `estimate` (m), accumulated, and the decision.
    /// `in_region` rules lobes out. After a switch the evidence is re-based
    /// on the new lobe (shifts the lattice cannot express start at 0).
    pub fn update(&mut self, frame: &LobeFrame<'_>, estimate: &Vector3<f64>, in_region: impl Fn(&Vector3<f64>) -> bool) -> LobeDecision {
        let LobeFrame { geometry, receivers, weight_floor, levels } = *frame;
        if !self.same_receivers(receivers) {
            // Skipped: the last frame's lobes (and their spread) stand.
            return LobeDecision::Stay;
        }
        std::mem::swap(&mut self.previous, &mut self.exact);
        self.exact.clear();
        let r = receivers.len();
        if r == 0 || self.evidence.is_empty() {
            return LobeDecision::Stay;
        }
        let teeth: Vec<i64> = receivers
            .iter()
            .map(|rx| rx.candidates.nearest_index(bistatic_distance(estimate, &geometry.tx_position, &rx.position).0))
            .collect();
        // One step: the estimate is a likelihood-weighted particle mean, already near its lobe's fit.
        let x0 = refine_on_teeth(geometry, receivers, &teeth, estimate, 1).map_or(*estimate, |f| f.0);
        let moved = self.previous_x0.map_or(Vector3::zeros(), |p| x0 - p);
        self.previous_x0 = Some(x0);
        if moved.norm() > JUMP_M {
            // The filter's lobe moved by itself (resampling into another
            // lobe, an outlier run): the evidence was against the old one.
            self.started = false;
            self.previous.clear();
        }
        let l0 = mixture_log_likelihood(geometry, receivers, &x0, weight_floor).0;
        let mut approx = std::mem::take(&mut self.scratch);
        approximate_evidence(geometry, receivers, &teeth, &x0, &self.lattice, weight_floor, &mut approx);

        // The shifts worth an exact fit: highest accumulated + this frame's approximation.
        if !self.started {
            self.evidence.iter_mut().for_each(|e| *e = 0.0);
        }
        let mut best: Vec<(f64, usize)> = Vec::with_capacity(EXACT_PER_FRAME + 1);
        for (i, (a, _)) in approx.iter().enumerate() {
            let score = self.evidence[i] + a;
            if best.len() < EXACT_PER_FRAME || score > best[best.len() - 1].0 {
                let at = best.iter().position(|b| b.0 < score).unwrap_or(best.len());
                best.insert(at, (score, i));
                best.truncate(EXACT_PER_FRAME);
            }
        }
        let mut shifted = teeth.clone();
        for &(_, i) in &best {
            let shift = &self.lattice[i * r..(i + 1) * r];
            for j in 0..r {
                shifted[j] = teeth[j] + shift[j] as i64;
            }
            // Warm start where this lobe was fitted last frame (moved with the filter's lobe).
            let fit = match self.previous.iter().find(|p| p.0 == i) {
                Some(&(_, x)) => refine_on_teeth(geometry, receivers, &shifted, &(x + moved), 2),
                None => refine_on_teeth(geometry, receivers, &shifted, &(x0 + approx[i].1), 4)
                    .or_else(|| follow_to_teeth(geometry, receivers, &teeth, &self.lattice[i * r..(i + 1) * r], &x0)),
            };
            let exact = fit
                .filter(|(x, _)| in_region(x))
                .map(|(x, _)| (mixture_log_likelihood(geometry, receivers, &x, weight_floor).0 - l0, x));
            match exact {
                Some((llr, x)) => {
                    approx[i].0 = llr;
                    self.exact.push((i, x));
                }
                None => approx[i].0 = f64::NEG_INFINITY,
            }
        }

        let (cap, floor) = (levels.frame_cap_nats, levels.floor_nats);
        for (i, (a, _)) in approx.iter().enumerate() {
            self.evidence[i] = (self.evidence[i] + a.clamp(-cap, cap)).max(-floor);
        }
        self.started = true;
        self.scratch = approx;

        let winner = self
            .exact
            .iter()
            .map(|&(i, x)| (self.evidence[i], i, x))
            .filter(|e| e.0 > levels.switch_nats)
            .max_by(|a, b| a.0.total_cmp(&b.0));
        let Some((won, i, x)) = winner else { return LobeDecision::Stay };
        self.rebase(i, won);
        self.previous_x0 = None;
        LobeDecision::Switch(x - x0)
    }

    /// After switching to shift `i` (evidence `won`): every shift's evidence
    /// relative to the new lobe, `L'_m = L_{m+k} − L_k`, 0 where `m + k`
    /// is outside the lattice, and `−L_k` for the lobe left.
    fn rebase(&mut self, i: usize, won: f64) {
        let r = self.antennas.len();
        let k: Vec<i8> = self.lattice[i * r..(i + 1) * r].to_vec();
        // Only on a switch: a linear search is fine.
        let index = |shift: &[i8]| -> Option<usize> { self.lattice.chunks_exact(r).position(|c| c == shift) };
        let old = self.evidence.clone();
        let mut sum = vec![0i8; r];
        for (m, shift) in self.lattice.chunks_exact(r).enumerate() {
            for j in 0..r {
                sum[j] = shift[j] + k[j];
            }
            self.evidence[m] = if sum.iter().all(|&s| s == 0) {
                -won
            } else {
                index(&sum).map_or(0.0, |n| old[n] - won)
            };
        }
        self.exact.clear();
    }

    /// The lobes' spread about `about` (m², `mixture_spread`) over this
    /// frame's exactly evaluated lobes, at log-odds `L_k`.
    pub fn spread(&self, about: &Vector3<f64>) -> Matrix3<f64> {
        if !self.started {
            return Matrix3::zeros();
        }
        mixture_spread(self.exact.iter().map(|&(i, x)| (x, self.evidence[i])), about)
    }

    /// The largest accumulated evidence of any exactly evaluated lobe (nats; −∞ with none).
    pub fn strongest(&self) -> f64 {
        self.exact.iter().map(|&(i, _)| self.evidence[i]).fold(f64::NEG_INFINITY, f64::max)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::model::wideband::Candidates;

    pub(crate) fn geometry() -> HelperGeometry {
        HelperGeometry { tx: 0, tx_position: Vector3::new(0.6, 0.0, 0.0), bounds: vec![], dimensions: 3, plane_z: 0.0 }
    }

    const SPACING: f64 = 0.3276;

    /// Receivers of the outside layout (three in line with tx) whose combs
    /// put a tooth exactly on the path lengths of `tag`, with the envelope's
    /// best tooth `favour[j]` teeth off the truth on receiver j.
    pub(crate) fn receivers(tag: &Vector3<f64>, sigma: f64, favour: [i64; 4], sharpness: f64) -> Vec<Receiver> {
        let g = geometry();
        [[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.8, 0.0, 0.0], [0.6, 0.4, 0.0]]
            .iter()
            .enumerate()
            .map(|(j, p)| {
                let position = Vector3::new(p[0], p[1], p[2]);
                let d = bistatic_distance(tag, &g.tx_position, &position).0;
                // Teeth d − 5λ … d + 5λ: the truth is index 5.
                let distances_m: Vec<f64> = (-5..=5).map(|n| d + n as f64 * SPACING).collect();
                let mut weights: Vec<f64> = (0..11).map(|n| (-(sharpness) * ((n - 5 - favour[j]) as f64).powi(2)).exp()).collect();
                let total: f64 = weights.iter().sum();
                weights.iter_mut().for_each(|w| *w /= total);
                let best = (5 + favour[j]) as usize;
                Receiver { antenna: j + 1, position, candidates: Candidates { distances_m, weights, spacing_m: SPACING, sigma_m: sigma, best, residual_coherence: 0.0 } }
            })
            .collect()
    }

    #[test]
    fn lattice_has_every_nonzero_shift_once() {
        let l = shift_lattice(4);
        assert_eq!(l.len(), 80 * 4);
        let mut seen: Vec<&[i8]> = l.chunks_exact(4).collect();
        seen.sort();
        seen.dedup();
        assert_eq!(seen.len(), 80);
        assert!(!seen.contains(&&[0i8, 0, 0, 0][..]));
        // Beyond 6 receivers at most 3 non-zero entries.
        let big = shift_lattice(8);
        assert!(big.chunks_exact(8).all(|s| s.iter().filter(|&&v| v != 0).count() <= 3));
    }

    #[test]
    fn refinement_lands_on_the_tag_and_rejects_other_teeth() {
        let tag = Vector3::new(0.8, 1.6, 0.8);
        let rx = receivers(&tag, 0.003, [0; 4], 1.0);
        let teeth = vec![5i64; 4];
        let (x, chi2) = refine_on_teeth(&geometry(), &rx, &teeth, &(tag + Vector3::new(0.02, -0.03, 0.01)), 6).unwrap();
        assert!((x - tag).norm() < 1e-6, "{x}");
        assert!(chi2 < 1e-6);
    }

    #[test]
    fn a_far_lobe_on_an_arc_is_reached_by_following_it() {
        // Dev seed 1005: the tag low beside the in-line row; its lobe one
        // tooth over on the fourth receiver is a rotation of 1.4 m about the
        // row. A straight jump to the linear prediction does not reach it;
        // following the lobe does, and lands on its teeth.
        let tag = Vector3::new(-0.268, 1.696, 0.416);
        let rx = receivers(&tag, 0.003, [0; 4], 1.0);
        let g = geometry();
        let truth_teeth = vec![5i64; 4];
        let far_teeth = vec![5i64, 5, 5, 6];
        let (far, chi2) = refine_on_teeth(&g, &rx, &far_teeth, &Vector3::new(-0.32, 0.342, 1.70), 8).expect("the far lobe exists");
        assert!(chi2 < 1.0 && (far - tag).norm() > 1.0, "{far} {chi2}");
        let (back, _) = follow_to_teeth(&g, &rx, &far_teeth, &[0, 0, 0, -1], &far).expect("followed");
        assert!((back - tag).norm() < 1e-3, "{back}");
        // And from the truth out to the far lobe.
        let (out, _) = follow_to_teeth(&g, &rx, &truth_teeth, &[0, 0, 0, 1], &tag).expect("followed");
        assert!((out - far).norm() < 1e-3, "{out}");
    }

    #[test]
    fn the_favoured_lobe_wins_and_the_filter_switches_to_it() {
        // The envelope favours the fourth receiver's next tooth: with three
        // receivers in line with tx that lobe (a rotation about their line)
        // fits every phase exactly, so only the envelope tells. Starting on
        // the other lobe the filter must move there within a bounded number
        // of frames.
        let tag = Vector3::new(0.8, 1.6, 0.8);
        let rx = receivers(&tag, 0.003, [0, 0, 0, 1], 2.0);
        let g = geometry();
        let levels = LobeLevels { switch_nats: 10.0, floor_nats: 20.0, frame_cap_nats: 5.0 };
        let mut lobes = LobeEvidence::default();
        let mut switched = None;
        for frame in 0..20 {
            if let LobeDecision::Switch(d) = lobes.update(&LobeFrame { geometry: &g, receivers: &rx, weight_floor: 1e-3, levels: &levels }, &tag, |_| true) {
                switched = Some((frame, d));
                break;
            }
        }
        let (frame, d) = switched.expect("switches");
        // Not before (B is not involved at the start) h / c = 2 frames, then 3.
        assert!(frame >= 2, "{frame}");
        let moved = tag + d;
        let teeth: Vec<i64> = rx.iter().map(|r| r.candidates.nearest_index(bistatic_distance(&moved, &g.tx_position, &r.position).0)).collect();
        assert_ne!(teeth, vec![5; 4]);
        // The envelope's favourite is better than the old lobe.
        let l = |p: &Vector3<f64>| mixture_log_likelihood(&g, &rx, p, 1e-3).0;
        assert!(l(&moved) > l(&tag));
    }

    #[test]
    fn the_right_lobe_stays_and_its_spread_vanishes() {
        let tag = Vector3::new(0.45, 1.2, 0.6);
        let rx = receivers(&tag, 0.003, [0; 4], 1.0);
        let g = geometry();
        let levels = LobeLevels { switch_nats: 10.0, floor_nats: 20.0, frame_cap_nats: 5.0 };
        let mut lobes = LobeEvidence::default();
        assert_eq!(lobes.update(&LobeFrame { geometry: &g, receivers: &rx, weight_floor: 1e-3, levels: &levels }, &tag, |_| true), LobeDecision::Stay);
        let first = lobes.spread(&tag).trace();
        // The weakest preference here is 1 nat per frame: 20 frames to the floor.
        for _ in 0..25 {
            assert_eq!(lobes.update(&LobeFrame { geometry: &g, receivers: &rx, weight_floor: 1e-3, levels: &levels }, &tag, |_| true), LobeDecision::Stay);
        }
        let last = lobes.spread(&tag).trace();
        assert!(last < first && last < 1e-8, "{first} -> {last}");
        assert!(lobes.strongest() <= -levels.floor_nats + 1e-9);
    }

    #[test]
    fn an_unresolved_lobe_inflates_the_spread() {
        // Flat envelope: the lobes are told apart by the phases only, and a
        // consistent shift keeps its posterior mass.
        let tag = Vector3::new(0.45, 1.2, 0.6);
        let rx = receivers(&tag, 0.003, [0; 4], 0.0);
        let g = geometry();
        let levels = LobeLevels { switch_nats: 10.0, floor_nats: 20.0, frame_cap_nats: 5.0 };
        let mut lobes = LobeEvidence::default();
        for _ in 0..5 {
            lobes.update(&LobeFrame { geometry: &g, receivers: &rx, weight_floor: 1e-3, levels: &levels }, &tag, |_| true);
        }
        let sigma = lobes.spread(&tag).trace().sqrt();
        assert!(sigma > 0.05, "{sigma}");
    }

    #[test]
    fn a_frame_without_one_receiver_neither_resets_nor_switches() {
        let tag = Vector3::new(0.8, 1.6, 0.8);
        let g = geometry();
        let levels = LobeLevels { switch_nats: 10.0, floor_nats: 20.0, frame_cap_nats: 5.0 };
        let mut lobes = LobeEvidence::default();
        let right = receivers(&tag, 0.003, [0; 4], 2.0);
        for _ in 0..10 {
            lobes.update(&LobeFrame { geometry: &g, receivers: &right, weight_floor: 1e-3, levels: &levels }, &tag, |_| true);
        }
        let before = lobes.strongest();
        // Three receivers that favour another lobe, for a few frames.
        let three: Vec<Receiver> = receivers(&tag, 0.003, [1, 1, 1, 1], 50.0).into_iter().take(3).collect();
        for _ in 0..5 {
            assert_eq!(lobes.update(&LobeFrame { geometry: &g, receivers: &three, weight_floor: 1e-3, levels: &levels }, &tag, |_| true), LobeDecision::Stay);
        }
        assert_eq!(lobes.strongest(), before);
        // A receiver set that persists is adopted.
        for _ in 0..ADOPT_AFTER + 2 {
            lobes.update(&LobeFrame { geometry: &g, receivers: &three, weight_floor: 1e-3, levels: &levels }, &tag, |_| true);
        }
        assert_eq!(lobes.antennas.len(), 3);
    }

    #[test]
    fn one_frame_cannot_switch() {
        let tag = Vector3::new(0.8, 1.6, 0.8);
        let g = geometry();
        let levels = LobeLevels { switch_nats: 10.0, floor_nats: 20.0, frame_cap_nats: 5.0 };
        let mut lobes = LobeEvidence::default();
        let right = receivers(&tag, 0.003, [0; 4], 2.0);
        let wrong = receivers(&tag, 0.003, [0, 0, 0, 1], 50.0);
        for _ in 0..10 {
            lobes.update(&LobeFrame { geometry: &g, receivers: &right, weight_floor: 1e-3, levels: &levels }, &tag, |_| true);
        }
        // One frame with an overwhelming (corrupt) preference elsewhere.
        assert_eq!(lobes.update(&LobeFrame { geometry: &g, receivers: &wrong, weight_floor: 1e-3, levels: &levels }, &tag, |_| true), LobeDecision::Stay);
    }
}
