//! TurboTrack: Bayesian space-time super-resolution over wideband frames
//! (thesis ch. 5, Algorithm 1).
//!
//! Each frame gives, per receive antenna, path-length candidates one
//! wavelength apart with weights (eq. 5.1, `model::wideband`). The state
//! is the tag position `x_t` with the random-walk prior of eq. 5.3,
//! `x_t = x_{t−1} + v_t, v_t ~ N(0, Σ_v)`, here with a motion mode per
//! particle (moving: the thesis's Σ_v; static: a small step), switching
//! as a Markov chain so that the weights can put a resting tag at rest
//! (docs/turbotrack.md, "Where we depart", 13); the likelihood is the product
//! over receivers of mixtures of Gaussians (eq. 5.2). Inference is a
//! sequential importance sampler:
//!
//! - **Initial sampling** (§5.3.1): candidate tuples are intersected
//!   (ellipses / ellipsoids), linearised (eq. 5.4), fused by their centroid
//!   (eq. 5.5), refitted on every receiver, ranked by the likelihood at
//!   that fit and weighted by `w(s) = Π w(s_j)` (eq. 5.6); particles are
//!   drawn from that mixture and weighted `p(y₀|x) / q₀(x)` (a uniform
//!   prior over the region). The thesis's perimeter rule `r(s) ≤ T` (an
//!   absolute threshold) is replaced by a χ² consistency test in units of
//!   each frame's own σ_w (see `initial_components`).
//! - **Sequential sampling** (§5.3.2): each particle's proposal is the
//!   product of the prior and the mixture component nearest to it — the
//!   tuple whose comb teeth are nearest its path lengths — computed once
//!   per tuple ("cluster") and shared by its particles; weights
//!   `w_t = w_{t−1} p(y_t|x_t) p(x_t|x_{t−1}) / π(x_t|x_{t−1}, y_t)`.
//! - **Resampling** when `N̂_eff < threshold · N`; **outliers** (all
//!   particles improbable, or the fix jumping) leave the particles as
//!   they were and extrapolate; **MAP** output is the highest-weight
//!   particle's mode, and its backtracked ancestry is the MAP trajectory.
//! - **Lobe test** (`lobes.rs`): every accepted frame the
//!   filter's lobe is compared with its neighbouring lobes (other comb
//!   teeth) by their profile likelihood, accumulated over frames; the
//!   particles move to a lobe whose evidence passes `lobe_switch_nats`, and
//!   unresolved lobes widen the reported covariance.
//! - **Far lobes** (`far_lobes.rs`): the initial search's fits, repeated
//!   every `far_lobe_search_s`, are kept as alternatives with the same
//!   accumulated evidence, for lobes beyond the lattice's reach.
//! - **Rest** (`resting_average.rs`): while the static particles hold the
//!   weight, the estimate is the fit of the frames' coherent average, and
//!   the lobe is decided on that averaged frame (`search_resting_lobes`).
//!
//! The comparison variants of §7.2 are parameter settings of the same
//! filter (see [`make`](super::make)): a single broad Gaussian likelihood
//! with the prior as proposal ("gaussian-pf"), and uniform initial
//! sampling with the prior as proposal ("uniform-pf").

use std::collections::VecDeque;

use nalgebra::{Matrix3, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use crate::error::{Error, Result};
use crate::filter::particle::{effective_sample_size, normalise_log_weights, systematic_resample};
use crate::model::wideband::CandidateParams;
use crate::scene::Scene;

use super::bistatic::{
    calibration_covariance, frame_receivers, log_normal, mixture_log_likelihood_with, tuple_gaussian, tuple_gaussian_lenient, usable_subsets, Decline, HelperGeometry,
    MixtureLogs, PositionGaussian, Receiver,
};
use super::key_hash::KeyMap;
use super::far_lobes::{FarLobes, SLOTS as FAR_LOBE_SLOTS};
use super::resting_average::{averaged_receivers, frame_covariance, ChannelAverage};
use super::lobes::{mixture_spread, multipath_frame, refine_on_teeth, LobeDecision, LobeEvidence, LobeFrame, LobeLevels};
use super::{Estimate, Measurement, Params, Tracker, TrackerStats, WidebandFrame};

/// Whether the lobe test runs: the mixture likelihood (the broad
/// single-Gaussian baseline has no lobes) and a finite switch level.
fn lobe_test(params: &TurboTrackParams) -> bool {
    matches!(params.likelihood, WidebandLikelihood::Mixture) && params.lobe_switch_nats.is_finite()
}

/// The registry's constructor of `turbotrack`: Algorithm 1 with the
/// parameters as given (the §7.2 baselines: [`super::variants`]).
pub fn build(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    Ok(Box::new(TurboTrack::new(scene.clone(), params.turbotrack.clone())?))
}

/// The observation model used to weight particles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WidebandLikelihood {
    /// Eqs. 5.1–5.2: a mixture of narrow Gaussians, one per candidate.
    Mixture,
    /// §7.2(a) baseline: one Gaussian per receiver, centred on its
    /// highest-weight candidate, with this 1-sigma, m.
    SingleGaussian { sigma_m: f64 },
}

/// How the first particles are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitialSampling {
    /// §5.3.1: from the pruned, linearised intersection tuples.
    Intersections,
    /// §7.2(b) baseline: uniformly over the region (needs `[region]`).
    Uniform,
}

/// Where each new particle is drawn from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Proposal {
    /// §5.3.2: prior × nearest mixture component (near-optimal).
    NearOptimal,
    /// The transition prior alone (bootstrap filter).
    Prior,
}

/// TurboTrack's tunables. Defaults follow the thesis where it gives a
/// value (Σ_v = 5 mm, 100 particles suffice per Fig. 7-5).
#[derive(Debug, Clone, PartialEq)]
pub struct TurboTrackParams {
    /// Number of particles N.
    pub particles: usize,
    /// 1-sigma per axis of the random-walk step Σ_v over one
    /// `reference_interval_s`, m (thesis ch. 6: 5 mm).
    pub transition_sigma_m: f64,
    /// Frame interval the step sigma refers to, s (300 frames/s); the
    /// variance scales with the actual interval (a random walk).
    pub reference_interval_s: f64,
    /// 1-sigma per axis of the random-walk step of a particle in the
    /// *static* motion mode over one `reference_interval_s`, m. Every
    /// particle carries a mode (moving: `transition_sigma_m`; static:
    /// this), switching as a Markov chain (`static_entry_probability`,
    /// `static_exit_probability`): a jump-Markov prior whose weights
    /// choose the mode, so a tag at rest is averaged over many frames
    /// instead of following each frame's noise, and a tag that starts
    /// moving is followed by the moving particles that the switching keeps
    /// alive.
    pub static_sigma_m: f64,
    /// Probability that a moving particle turns static over one
    /// `reference_interval_s` (scaled to the actual interval). 0 keeps
    /// every particle moving (the thesis's single random walk).
    pub static_entry_probability: f64,
    /// Probability that a static particle turns moving over one
    /// `reference_interval_s`. Large against the entry: a static particle
    /// lives a few frames and its lineage lasts only while the weights keep
    /// choosing it, so few static particles linger (and lag) once the tag
    /// moves; a symmetric chain (half the cloud static) lagged a slow tag
    /// in the poorly observed directions (docs/notes/turbotrack-experiments.md).
    pub static_exit_probability: f64,
    /// 1-sigma residual of each receiver's calibration on its path sum, m:
    /// a bias no frame reveals, added to the reported covariance as
    /// `σ² (JᵀJ)⁻¹` ([`calibration_covariance`]). 0: none.
    pub calibration_sigma_m: f64,
    /// Resample when `N̂_eff < resample_threshold · N`.
    pub resample_threshold: f64,
    /// Perimeter threshold T of the thesis's initial pruning, m (doubled up
    /// to 3 times when no tuple survives): the gaussian-pf baseline only;
    /// turbotrack and uniform-pf test each tuple's χ² instead.
    pub perimeter_threshold_m: f64,
    /// Largest number of initial mixture components kept (by weight).
    pub max_initial_components: usize,
    /// Tangency tolerance of the intersection routine, m.
    pub intersection_tolerance_m: f64,
    /// Candidate extraction from each receiver's channel.
    pub candidates: CandidateParams,
    /// Fixed 1-sigma path-length error σ_w, m; None: each frame's estimate.
    pub distance_sigma_m: Option<f64>,
    /// Mixture weight of comb teeth outside the kept candidates.
    pub weight_floor: f64,
    pub likelihood: WidebandLikelihood,
    pub initial_sampling: InitialSampling,
    pub proposal: Proposal,
    /// A frame is an outlier when even the best particle's χ² over the
    /// receivers exceeds this (every particle improbable).
    pub outlier_chi2: f64,
    /// ... or when the fix jumps farther than this plus `max_speed_m_s · dt`, m.
    pub outlier_jump_m: f64,
    /// Largest plausible tag speed, m/s (only for the jump test).
    pub max_speed_m_s: f64,
    /// Start over after this many consecutive outlier frames.
    pub max_consecutive_outliers: u32,
    /// Start over after a gap between frames longer than this, s.
    pub reinit_gap_s: f64,
    /// Particles farther than this outside the region are impossible, m.
    pub region_margin_m: f64,
    /// Frames of particle ancestry kept for the backtracked MAP trajectory.
    pub history_frames: usize,
    /// Velocity is the slope of the estimates over this window, s.
    pub velocity_window_s: f64,
    /// Seed of the sampler's random numbers.
    pub seed: u64,
    /// Acquisition window of the RFind baseline (a static tag is assumed
    /// over it), s; the thesis reports ~3 s of hopping.
    pub rfind_window_s: f64,
    /// Lobe test (`lobes.rs`): move to another lobe when its accumulated
    /// evidence against the filter's exceeds this, nats (10: posterior odds
    /// 22 000 : 1). Infinite: never.
    pub lobe_switch_nats: f64,
    /// Lobe test: an alternative's evidence never sinks below minus this,
    /// nats (200: how much history protects a lobe the filter has been
    /// confirmed on; with the cap, 100 frames of contrary evidence, 0.33 s
    /// at 300 frames/s, before a confirmed lobe can be left. At 20 the
    /// simulated 4 dB multipath arm switched to a wrong lobe in 19 of 20
    /// starts when a reflection favoured it for a few tens of frames).
    pub lobe_floor_nats: f64,
    /// Lobe test: one frame changes an evidence by at most this, nats (2:
    /// a switch needs at least switch / cap = 5 agreeing frames from an
    /// even start, so no single corrupt frame can cause one).
    pub lobe_frame_cap_nats: f64,
    /// Far lobes (`far_lobes.rs`): the initial tuple search is repeated on
    /// the current frame this often, its fits tested as alternatives, s.
    /// Infinite: only the first frame's fits.
    pub far_lobe_search_s: f64,
    /// Resting average (`resting_average.rs`): while the static particles
    /// carry the weight, the estimate is the fit of the frames' coherent
    /// average, forgotten with this time constant, s. 0: the particles' mode.
    pub static_average_s: f64,
}

impl Default for TurboTrackParams {
    fn default() -> Self {
        Self {
            particles: 100,
            transition_sigma_m: 0.005,
            reference_interval_s: 1.0 / 300.0,
            static_sigma_m: 0.001,
            static_entry_probability: 0.01,
            static_exit_probability: 0.2,
            calibration_sigma_m: 0.004,
            resample_threshold: 0.5,
            perimeter_threshold_m: 0.03,
            max_initial_components: 64,
            intersection_tolerance_m: 0.02,
            candidates: CandidateParams::default(),
            distance_sigma_m: None,
            weight_floor: 1e-3,
            likelihood: WidebandLikelihood::Mixture,
            initial_sampling: InitialSampling::Intersections,
            proposal: Proposal::NearOptimal,
            outlier_chi2: 100.0,
            outlier_jump_m: 0.05,
            max_speed_m_s: 2.0,
            max_consecutive_outliers: 30,
            reinit_gap_s: 1.0,
            region_margin_m: 0.05,
            history_frames: 3000,
            velocity_window_s: 0.1,
            seed: 0,
            rfind_window_s: 3.0,
            lobe_switch_nats: 10.0,
            lobe_floor_nats: 200.0,
            lobe_frame_cap_nats: 2.0,
            far_lobe_search_s: 0.5,
            static_average_s: 1.0,
        }
    }
}

impl TurboTrackParams {
    fn validate(&self, scene: &Scene) -> Result<()> {
        let bad = |name: &str, reason: &str| Err(Error::Parameter { name: name.into(), reason: reason.into() });
        if self.particles == 0 {
            return bad("particles", "must be at least 1");
        }
        if !(self.transition_sigma_m > 0.0) || !(self.reference_interval_s > 0.0) {
            return bad("transition_sigma_m", "must be positive");
        }
        if !(self.calibration_sigma_m >= 0.0 && self.calibration_sigma_m.is_finite()) {
            return bad("calibration_sigma_m", "must be finite and at least 0");
        }
        if !(self.static_sigma_m > 0.0) {
            return bad("static_sigma_m", "must be positive");
        }
        if !(self.static_entry_probability >= 0.0 && self.static_entry_probability < 1.0) {
            return bad("static_entry_probability", "must be in [0, 1)");
        }
        if !(self.static_exit_probability > 0.0 && self.static_exit_probability <= 1.0) {
            return bad("static_exit_probability", "must be in (0, 1]");
        }
        if !(self.resample_threshold >= 0.0 && self.resample_threshold <= 1.0) {
            return bad("resample_threshold", "must be in [0, 1]");
        }
        if let Some(s) = self.distance_sigma_m {
            if !(s > 0.0) {
                return bad("distance_sigma_m", "must be positive");
            }
        }
        if self.initial_sampling == InitialSampling::Uniform && scene.region.is_none() {
            return bad("initial_sampling", "uniform sampling needs a [region] in the scene");
        }
        if HelperGeometry::new(scene).is_none() {
            return Err(Error::Scene(
                "a wideband tracker needs one antenna with role \"tx\" and at least 3 (2 for dimensions = 2) with role \"rx\"".into(),
            ));
        }
        Ok(())
    }
}

/// One mixture component's proposal, shared by the particles of a cluster:
/// `π(x | x_prev) = N(A x_prev + b, P)` with `P = (Σ_v⁻¹ + Σ_s⁻¹)⁻¹`,
/// `A = P Σ_v⁻¹`, `b = P Σ_s⁻¹ μ_s` (product of two Gaussians).
struct ClusterProposal {
    a: Matrix3<f64>,
    b: Vector3<f64>,
    /// Cholesky factor of P.
    l: Matrix3<f64>,
    p_inv: Matrix3<f64>,
    log_det_p: f64,
    /// The tuple's fused position μ_s (eq. 5.5), m.
    centroid: Vector3<f64>,
}

/// The TurboTrack particle filter (and its §7.2 variants).
pub struct TurboTrack {
    scene: Scene,
    geometry: HelperGeometry,
    params: TurboTrackParams,
    rng: StdRng,
    /// Particle positions, m (flat: one `Vector3` each).
    positions: Vec<Vector3<f64>>,
    /// Normalised log-weights.
    log_weights: Vec<f64>,
    /// Per particle: its motion mode (true: static, see `static_sigma_m`).
    modes: Vec<bool>,
    /// Positions of the scene's receive antennas, m (the calibration term's
    /// geometry; fixed for the tracker's life).
    receive_positions: Vec<Vector3<f64>>,
    /// Ancestry per frame (after resampling): positions and the parent
    /// index into the previous frame's arrays, for backtracking.
    history: VecDeque<(f64, Vec<Vector3<f64>>, Vec<usize>)>,
    /// Recent estimates (time s, position m) for the velocity slope.
    recent: VecDeque<(f64, Vector3<f64>)>,
    last_time_s: f64,
    last_estimate: Option<Estimate>,
    consecutive_outliers: u32,
    initialised: bool,
    stats: TrackerStats,
    /// Accumulated evidence of the neighbouring lobes (`lobes.rs`).
    lobes: LobeEvidence,
    /// Far alternatives from the global tuple search (`far_lobes.rs`), and
    /// when that search last ran, s.
    far: FarLobes,
    last_far_search_s: f64,
    /// The resting tag's coherent average and, on the frames it decides,
    /// its fit: position m and covariance m² (`resting_average.rs`).
    average: ChannelAverage,
    resting: Option<(Vector3<f64>, Matrix3<f64>)>,
    /// At rest, the lobes are decided on the average: the last search's
    /// other lobes (position m, log-likelihood ratio on the averaged frame
    /// against the resting fit, nats), when it last ran (s), and the
    /// displacement to a lobe that won, to apply in `estimate`.
    resting_lobes: Option<Vec<(Vector3<f64>, f64)>>,
    last_resting_search_s: f64,
    /// The averaged frames at that search (a doubling since searches again).
    resting_search_frames: f64,
    resting_switch: Option<Vector3<f64>>,
    // Scratch buffers reused every frame.
    scratch_positions: Vec<Vector3<f64>>,
    scratch_keys: Vec<u64>,
    scratch_ancestors: Vec<usize>,
}

/// The cluster proposal of Gaussian `g` (its inverse covariance `s_inv`)
/// under a random-walk step of inverse covariance `sigma_v_inv`: the
/// product of the two Gaussians (planar scenes keep z out of it).
fn cluster_proposal(g: &PositionGaussian, s_inv: &Matrix3<f64>, sigma_v_inv: &Matrix3<f64>, dims: usize) -> Option<ClusterProposal> {
    let mut p_inv = sigma_v_inv + s_inv;
    if dims == 2 {
        p_inv[(2, 2)] = 1.0;
        p_inv[(0, 2)] = 0.0;
        p_inv[(1, 2)] = 0.0;
        p_inv[(2, 0)] = 0.0;
        p_inv[(2, 1)] = 0.0;
    }
    let pm = p_inv.try_inverse()?;
    let l = pm.cholesky()?.l();
    let log_det_p = if dims == 3 { pm.determinant().ln() } else { (pm[(0, 0)] * pm[(1, 1)] - pm[(0, 1)] * pm[(1, 0)]).ln() };
    Some(ClusterProposal { a: pm * sigma_v_inv, b: pm * (s_inv * g.mean), l, p_inv, log_det_p, centroid: g.mean })
}

/// Packs a candidate-index tuple into a hash key (8 bits per receiver,
/// offset so small negative indices fit; up to 8 receivers).
fn pack(indices: &[i64]) -> u64 {
    indices.iter().fold(0u64, |key, &n| (key << 8) | ((n + 128).clamp(0, 255) as u64))
}

fn log_gaussian3(r: &Vector3<f64>, inverse: &Matrix3<f64>, log_det: f64, dims: usize) -> f64 {
    -0.5 * (r.dot(&(inverse * r)) + log_det + dims as f64 * (2.0 * std::f64::consts::PI).ln())
}

impl TurboTrack {
    pub fn new(scene: Scene, mut params: TurboTrackParams) -> Result<Self> {
        params.validate(&scene)?;
        // The residual coherence only serves the lobe tests (a multipath
        // frame is kept out of them): about a microsecond a receiver saved
        // on every frame when they are off.
        params.candidates.measure_coherence &= lobe_test(&params);
        let geometry = HelperGeometry::new(&scene).expect("validated");
        let rng = StdRng::seed_from_u64(params.seed);
        Ok(Self {
            geometry,
            rng,
            positions: Vec::new(),
            log_weights: Vec::new(),
            modes: Vec::new(),
            receive_positions: scene.antennas.iter().filter(|a| a.role == crate::scene::Role::Rx).map(|a| a.position).collect(),
            history: VecDeque::new(),
            recent: VecDeque::new(),
            last_time_s: f64::NEG_INFINITY,
            last_estimate: None,
            consecutive_outliers: 0,
            initialised: false,
            stats: TrackerStats::default(),
            lobes: LobeEvidence::default(),
            far: FarLobes::default(),
            last_far_search_s: f64::NEG_INFINITY,
            average: ChannelAverage::new(params.static_average_s),
            resting: None,
            resting_lobes: None,
            last_resting_search_s: f64::NEG_INFINITY,
            resting_search_frames: 0.0,
            resting_switch: None,
            scratch_positions: Vec::new(),
            scratch_keys: Vec::new(),
            scratch_ancestors: Vec::new(),
            scene,
            params,
        })
    }

    /// The backtracked MAP trajectory (Algorithm 1's output): the ancestry
    /// of the current highest-weight particle over the kept history, as
    /// (time s, position m), oldest first.
    pub fn map_trajectory(&self) -> Vec<(f64, [f64; 3])> {
        let Some(mut index) = self.best_particle() else { return Vec::new() };
        let mut out = Vec::with_capacity(self.history.len());
        for (t, positions, parents) in self.history.iter().rev() {
            let p = positions[index];
            out.push((*t, [p.x, p.y, p.z]));
            index = parents[index];
        }
        out.reverse();
        out
    }

    fn best_particle(&self) -> Option<usize> {
        self.log_weights.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i)
    }

    /// The motion-mode chain's stationary share of static particles,
    /// entry / (entry + exit) (0 when particles never turn static).
    fn static_share(&self) -> f64 {
        let (entry, exit) = (self.params.static_entry_probability, self.params.static_exit_probability);
        if entry > 0.0 {
            entry / (entry + exit)
        } else {
            0.0
        }
    }

    fn in_region(&self, p: &Vector3<f64>) -> bool {
        self.scene.region.as_ref().is_none_or(|r| r.contains(p, self.params.region_margin_m, self.scene.dimensions))
    }

    /// Applies the fixed σ_w if configured.
    fn receivers(&self, frame: &WidebandFrame) -> std::result::Result<Vec<Receiver>, Decline> {
        let mut receivers = frame_receivers(&self.scene, &self.geometry, frame, &self.params.candidates)?;
        if let Some(s) = self.params.distance_sigma_m {
            receivers.iter_mut().for_each(|r| r.candidates.sigma_m = s);
        }
        Ok(receivers)
    }

    /// Log-likelihood of a position under the configured observation model,
    /// and the χ² of the nearest candidates.
    /// `logs`: this frame's [`MixtureLogs`] (the mixture's logarithms, tabulated once).
    fn log_likelihood(&self, receivers: &[Receiver], logs: &MixtureLogs, p: &Vector3<f64>) -> (f64, f64) {
        if !self.in_region(p) {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        match self.params.likelihood {
            WidebandLikelihood::Mixture => mixture_log_likelihood_with(&self.geometry, receivers, logs, p),
            WidebandLikelihood::SingleGaussian { sigma_m } => {
                let mut log_l = 0.0;
                let mut chi2 = 0.0;
                for rx in receivers {
                    let d = crate::geometry::bistatic_distance(p, &self.geometry.tx_position, &rx.position).0;
                    let centre = rx.candidates.distances_m[rx.candidates.best];
                    log_l += log_normal(d, centre, sigma_m);
                    chi2 += ((d - centre) / sigma_m).powi(2);
                }
                (log_l, chi2)
            }
        }
    }

    fn subset_list(&self, receivers: &[Receiver]) -> Vec<Vec<usize>> {
        usable_subsets(&self.geometry, receivers)
    }

    /// Standard-normal draw in the tracked dimensions (z stays 0 in a plane).
    fn normal3(&mut self) -> Vector3<f64> {
        let z = if self.scene.dimensions == 3 { self.rng.sample(StandardNormal) } else { 0.0 };
        Vector3::new(self.rng.sample(StandardNormal), self.rng.sample(StandardNormal), z)
    }

    /// Transition covariance Σ_v for a step of `dt` seconds (random walk:
    /// variance grows linearly with time; at least a quarter step so
    /// bursts of nearly simultaneous frames still move). Planar scenes get
    /// a unit z variance that is never sampled.
    fn transition(&self, dt: f64, resting: bool) -> Matrix3<f64> {
        let scale = (dt / self.params.reference_interval_s).clamp(0.25, 1e4);
        let sigma = if resting { self.params.static_sigma_m } else { self.params.transition_sigma_m };
        let v = sigma.powi(2) * scale;
        let vz = if self.scene.dimensions == 3 { v } else { 1.0 };
        Matrix3::from_diagonal(&Vector3::new(v, v, vz))
    }

    /// Algorithm 1, initialisation: the mixture q₀ of §5.3.1 and N particles from it.
    fn initialise(&mut self, time_s: f64, receivers: &[Receiver]) -> bool {
        let n = self.params.particles;
        let logs = MixtureLogs::new(receivers, self.params.weight_floor);
        self.positions.clear();
        self.log_weights.clear();
        self.history.clear();
        self.recent.clear();
        self.last_estimate = None;
        self.consecutive_outliers = 0;
        self.lobes.reset();
        if self.params.initial_sampling == InitialSampling::Uniform {
            let region = self.scene.region.clone().expect("validated");
            for _ in 0..n {
                let mut p = Vector3::zeros();
                for k in 0..3 {
                    p[k] = region.min[k] + self.rng.random::<f64>() * (region.max[k] - region.min[k]);
                }
                if self.scene.dimensions == 2 {
                    p.z = self.scene.plane_z;
                }
                self.positions.push(p);
                let (log_l, _) = self.log_likelihood(receivers, &logs, &p);
                self.log_weights.push(log_l);
            }
        } else {
            let components = self.initial_components(receivers);
            if components.is_empty() {
                return false;
            }
            self.far.reset();
            self.last_far_search_s = time_s;
            if self.lobe_test() {
                // The filter's own lobe is among them: the first update merges it.
                self.far.offer(components.iter().take(FAR_LOBE_SLOTS + 1).map(|c| c.0.mean), 0.0, None);
            }
            // q₀ = Σ w̄_s N(μ_s, Σ_s); precompute inverses for q₀(x).
            let total: f64 = components.iter().map(|c| c.1).sum();
            let dims = self.scene.dimensions;
            let prepared: Vec<(Vector3<f64>, Matrix3<f64>, Matrix3<f64>, f64, f64)> = components
                .iter()
                .filter_map(|(g, w)| {
                    let chol = g.covariance.cholesky()?;
                    let inv = chol.inverse();
                    let log_det = if dims == 3 { g.covariance.determinant().ln() } else { g.covariance.fixed_view::<2, 2>(0, 0).determinant().ln() };
                    Some((g.mean, chol.l(), inv, log_det, (w / total).ln()))
                })
                .collect();
            if prepared.is_empty() {
                return false;
            }
            let mut log_component: Vec<f64> = prepared.iter().map(|c| c.4).collect();
            normalise_log_weights(&mut log_component);
            // Systematic draw of N component labels from the weights.
            let u = self.rng.random::<f64>();
            let mut chosen = Vec::with_capacity(n);
            let cumulative: Vec<f64> = log_component
                .iter()
                .scan(0.0, |s, w| {
                    *s += w.exp();
                    Some(*s)
                })
                .collect();
            for i in 0..n {
                let target = (i as f64 + u) / n as f64;
                chosen.push(cumulative.iter().position(|&c| c >= target).unwrap_or(cumulative.len() - 1));
            }
            for &c in &chosen {
                let (mean, l, ..) = prepared[c];
                let z = self.normal3();
                let mut p = mean + l * z;
                if dims == 2 {
                    p.z = self.scene.plane_z;
                }
                let log_q = {
                    let terms: Vec<f64> = prepared
                        .iter()
                        .zip(&log_component)
                        .map(|((m, _, inv, log_det, _), lw)| lw + log_gaussian3(&(p - m), inv, *log_det, dims))
                        .collect();
                    let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
                };
                let (log_l, _) = self.log_likelihood(receivers, &logs, &p);
                self.positions.push(p);
                self.log_weights.push(log_l - log_q);
            }
        }
        // The Markov chain's stationary share of the particles starts at
        // rest, spread evenly over the draw; the first frames' weights choose.
        let share = self.static_share();
        let count = self.positions.len();
        self.modes = (0..count).map(|i| ((i as f64 + 0.5) / count as f64) < share).collect();
        if normalise_log_weights(&mut self.log_weights) == f64::NEG_INFINITY {
            self.positions.clear();
            self.log_weights.clear();
            self.modes.clear();
            return false;
        }
        self.history.push_back((time_s, self.positions.clone(), (0..n).collect()));
        self.initialised = true;
        true
    }

    /// §5.3.1 steps 1–4: the consistent tuples' Gaussians and weights
    /// `w(s) = Π_j w_j(s_j)`. Tuples are seeded from the first `needed`
    /// receivers' candidate combinations (each intersected); the other
    /// receivers' indices are the comb teeth nearest the seed point; then
    /// every subset is intersected, the centroid refitted and tested.
    fn initial_components(&self, receivers: &[Receiver]) -> Vec<(PositionGaussian, f64)> {
        let subset_list = self.subset_list(receivers);
        let logs = MixtureLogs::new(receivers, self.params.weight_floor);
        let Some(base_set) = subset_list.first().cloned() else { return Vec::new() };
        let single = matches!(self.params.likelihood, WidebandLikelihood::SingleGaussian { .. });
        let base: Vec<Vec<i64>> = base_set
            .iter()
            .map(|&j| {
                let c = &receivers[j].candidates;
                if single {
                    vec![c.best as i64]
                } else {
                    (0..c.distances_m.len() as i64).collect()
                }
            })
            .collect();
        // Cartesian product of the base receivers' candidate indices.
        let mut combos: Vec<Vec<i64>> = vec![Vec::new()];
        for options in &base {
            combos = combos.into_iter().flat_map(|c| options.iter().map(move |&o| [c.clone(), vec![o]].concat())).collect();
        }
        let positions: Vec<Vector3<f64>> = base_set.iter().map(|&j| receivers[j].position).collect();
        let mut tuples: KeyMap<(Vec<i64>, Vector3<f64>)> = KeyMap::default();
        for combo in combos {
            let distances: Vec<f64> = combo.iter().zip(&base_set).map(|(&n, &j)| receivers[j].candidates.distance(n)).collect();
            for p in crate::geometry::bistatic_intersections(
                &self.geometry.tx_position,
                &positions,
                &distances,
                self.geometry.plane(),
                self.params.intersection_tolerance_m,
            ) {
                if !self.in_region(&p) {
                    continue;
                }
                let mut indices: Vec<i64> = receivers
                    .iter()
                    .map(|rx| {
                        let d = crate::geometry::bistatic_distance(&p, &self.geometry.tx_position, &rx.position).0;
                        if single {
                            rx.candidates.best as i64
                        } else {
                            rx.candidates.nearest_index(d)
                        }
                    })
                    .collect();
                for (&n, &j) in combo.iter().zip(&base_set) {
                    indices[j] = n;
                }
                tuples.entry(pack(&indices)).or_insert((indices, p));
            }
        }
        // turbotrack / uniform-pf: no absolute pruning threshold (the
        // thesis's perimeter rule T). At 8 dB the true tuple's subset
        // intersections spread by centimetres along the poorly conditioned
        // directions and an absolute T removed it more often than a wrong
        // one. Each tuple's centroid is instead refitted on every receiver
        // (weighted least squares in units of this frame's σ_w, which
        // carries the noise and, through the Jacobian, the geometry) and kept
        // if that fit is consistent: its χ² over the receivers within
        // `outlier_chi2`, the level at which the filter would call the whole
        // frame an outlier. The survivors are ranked by the likelihood at
        // their fit. The single-Gaussian baseline (gaussian-pf) keeps the
        // thesis's rule, `perimeter_threshold_m` doubled up to 3 times when
        // no tuple survives: it is the §7.2(a) comparison as published.
        let component = |indices: &[i64], seed: &Vector3<f64>, threshold: f64| -> Option<(f64, (PositionGaussian, f64))> {
            let tolerance = self.params.intersection_tolerance_m;
            let mut g = if single {
                let g = tuple_gaussian(&self.geometry, receivers, indices, &subset_list, seed, tolerance)?;
                (g.perimeter_m <= threshold).then_some(g)?
            } else {
                let mut g = tuple_gaussian_lenient(&self.geometry, receivers, indices, &subset_list, seed, tolerance)?;
                let (fit, chi2) = refine_on_teeth(&self.geometry, receivers, indices, &g.mean, 3)?;
                (chi2 <= self.params.outlier_chi2).then_some(())?;
                g.mean = fit;
                g
            };
            if !self.in_region(&g.mean) {
                return None;
            }
            let w: f64 = indices.iter().zip(receivers).map(|(&n, r)| r.candidates.weight(n, self.params.weight_floor)).product();
            if let WidebandLikelihood::SingleGaussian { sigma_m } = self.params.likelihood {
                // The broad baseline starts as broad as its likelihood.
                g.covariance += Matrix3::identity() * sigma_m * sigma_m;
            }
            // The likelihood at the (fitted) mean weighs both the candidate
            // weights and the consistency across *all* receivers (w(s) alone
            // is nearly flat over a 100 MHz envelope).
            Some((self.log_likelihood(receivers, &logs, &g.mean).0, (g, w)))
        };
        let mut threshold = if single { self.params.perimeter_threshold_m } else { f64::INFINITY };
        let mut scored: Vec<(f64, (PositionGaussian, f64))> = Vec::new();
        for _ in 0..4 {
            scored = tuples.values().filter_map(|(indices, seed)| component(indices, seed, threshold)).collect();
            if !scored.is_empty() || !single {
                break;
            }
            threshold *= 2.0;
        }
        scored.sort_by(|a, b| b.0.total_cmp(&a.0));
        scored.truncate(self.params.max_initial_components);
        scored.into_iter().map(|(_, c)| c).collect()
    }

    /// Algorithm 1, one iteration. Returns false when the frame is an outlier.
    fn sequential_step(&mut self, time_s: f64, receivers: &[Receiver]) -> bool {
        let dt = (time_s - self.last_time_s).max(0.0);
        let dims = self.scene.dimensions;
        // Per motion mode (0: moving, 1: static): Σ_v's inverse, Cholesky
        // factor and log-determinant.
        let motion: [(Matrix3<f64>, Matrix3<f64>, f64); 2] = [false, true].map(|resting| {
            let sigma_v = self.transition(dt, resting);
            let inverse = sigma_v.try_inverse().expect("diagonal, positive");
            let chol = sigma_v.cholesky().expect("diagonal, positive").l();
            let log_det = if dims == 3 { sigma_v.determinant().ln() } else { (sigma_v[(0, 0)] * sigma_v[(1, 1)]).ln() };
            (inverse, chol, log_det)
        });
        let subset_list = self.subset_list(receivers);
        let logs = MixtureLogs::new(receivers, self.params.weight_floor);
        let n = self.positions.len();

        // Modes first (the Markov chain's switch over dt), so that the
        // proposals below use each particle's new mode: sampled from its
        // prior, the mode's probability cancels in the weight.
        let steps = (dt / self.params.reference_interval_s).max(0.0);
        let over_dt = |p: f64| 1.0 - (1.0 - p).powf(steps);
        let (entry, exit) = (over_dt(self.params.static_entry_probability), over_dt(self.params.static_exit_probability));
        let mut new_modes = self.modes.clone();
        if entry > 0.0 {
            for mode in new_modes.iter_mut() {
                if self.rng.random::<f64>() < if *mode { exit } else { entry } {
                    *mode = !*mode;
                }
            }
        }

        // Cluster keys: the nearest comb tooth of every receiver. A
        // cluster's proposal is computed once per motion mode.
        self.scratch_keys.clear();
        let mut tuples: KeyMap<Option<[ClusterProposal; 2]>> = KeyMap::default();
        let mut indices = vec![0i64; receivers.len()];
        for i in 0..n {
            let p = self.positions[i];
            for (j, rx) in receivers.iter().enumerate() {
                let d = crate::geometry::bistatic_distance(&p, &self.geometry.tx_position, &rx.position).0;
                indices[j] = rx.candidates.nearest_index(d);
            }
            let key = pack(&indices);
            self.scratch_keys.push(key);
            if self.params.proposal == Proposal::NearOptimal && !tuples.contains_key(&key) {
                let proposal =
                    tuple_gaussian(&self.geometry, receivers, &indices, &subset_list, &p, self.params.intersection_tolerance_m)
                        .and_then(|g| {
                            let s_inv = g.covariance.try_inverse()?;
                            let moving = cluster_proposal(&g, &s_inv, &motion[0].0, dims)?;
                            let resting = cluster_proposal(&g, &s_inv, &motion[1].0, dims)?;
                            Some([moving, resting])
                        });
                tuples.insert(key, proposal);
            }
        }

        // Sample and weight (into scratch; committed only if not an outlier).
        let mut new_positions = std::mem::take(&mut self.scratch_positions);
        new_positions.clear();
        let mut new_log_weights = self.log_weights.clone();
        let mut best_chi2 = f64::INFINITY;
        for i in 0..n {
            let prev = self.positions[i];
            let mode = usize::from(new_modes[i]);
            let (sigma_v_inv, sigma_v_chol, log_det_v) = &motion[mode];
            let z = self.normal3();
            let (mut x, log_correction) = match tuples.get(&self.scratch_keys[i]).and_then(|c| c.as_ref()) {
                Some(proposals) => {
                    let c = &proposals[mode];
                    let mean = c.a * prev + c.b;
                    let x = mean + c.l * z;
                    let mut r_prior = x - prev;
                    let mut r_prop = x - mean;
                    if dims == 2 {
                        r_prior.z = 0.0;
                        r_prop.z = 0.0;
                    }
                    let log_prior = log_gaussian3(&r_prior, sigma_v_inv, *log_det_v, dims);
                    let log_prop = log_gaussian3(&r_prop, &c.p_inv, c.log_det_p, dims);
                    (x, log_prior - log_prop)
                }
                // Bootstrap: sampled from the prior, which cancels.
                None => (prev + sigma_v_chol * z, 0.0),
            };
            if dims == 2 {
                x.z = self.scene.plane_z;
            }
            let (log_l, chi2) = self.log_likelihood(receivers, &logs, &x);
            best_chi2 = best_chi2.min(chi2);
            new_log_weights[i] += log_l + log_correction;
            new_positions.push(x);
        }
        let evidence = normalise_log_weights(&mut new_log_weights);
        let outlier = evidence == f64::NEG_INFINITY || best_chi2 > self.params.outlier_chi2;
        // §5.3.2 outlier rule 1, on the measurement side: the centroid
        // (eq. 5.5) that this frame gives the most probable particle jumped
        // from where that particle was. (Testing the particle estimate
        // instead would also reject the legitimate switch to another mode.)
        let jumped = !outlier
            && self.best_particle().is_some_and(|best| {
                let key = self.scratch_keys[best];
                match tuples.get(&key) {
                    Some(Some(c)) => {
                        (c[0].centroid - self.positions[best]).norm() > self.params.outlier_jump_m + self.params.max_speed_m_s * dt
                    }
                    _ => false,
                }
            });
        if outlier || jumped {
            self.scratch_positions = new_positions;
            return false;
        }
        self.scratch_positions = std::mem::replace(&mut self.positions, new_positions);
        self.log_weights = new_log_weights;
        self.modes = new_modes;

        // Resample on low effective sample size.
        let mut parents: Vec<usize> = (0..n).collect();
        if effective_sample_size(&self.log_weights) < self.params.resample_threshold * n as f64 {
            let u = self.rng.random::<f64>();
            systematic_resample(&self.log_weights, u, &mut self.scratch_ancestors);
            let old = self.positions.clone();
            let old_modes = self.modes.clone();
            for (i, &a) in self.scratch_ancestors.iter().enumerate() {
                self.positions[i] = old[a];
                self.modes[i] = old_modes[a];
                parents[i] = a;
            }
            let uniform = -(n as f64).ln();
            self.log_weights.iter_mut().for_each(|w| *w = uniform);
        }
        self.history.push_back((time_s, self.positions.clone(), parents));
        while self.history.len() > self.params.history_frames.max(1) {
            self.history.pop_front();
        }
        true
    }

    /// The resting average (`resting_average.rs`) on a frame: the frame
    /// joins the average; while the static particles carry
    /// `RESTING_STATIC_WEIGHT` of the weight and `RESTING_MIN_FRAMES` frames
    /// are averaged, the averaged frame is fitted on the static mean's
    /// teeth. The average starts over when its
    /// fit leaves the particles' mode (`estimate`), not when the static
    /// weight dips: in a weakly observed direction the moving particles
    /// follow each frame's noise and win many frames of a resting tag.
    fn update_resting(&mut self, frame: &WidebandFrame) {
        self.resting = None;
        if !(self.params.static_average_s > 0.0) {
            return;
        }
        let (mut static_weight, mut mean) = (0.0, Vector3::zeros());
        for ((p, lw), &resting) in self.positions.iter().zip(&self.log_weights).zip(&self.modes) {
            if resting {
                let w = lw.exp();
                static_weight += w;
                mean += p * w;
            }
        }
        self.average.add(frame);
        if static_weight < RESTING_STATIC_WEIGHT || self.average.frames() < RESTING_MIN_FRAMES {
            return;
        }
        mean /= static_weight;
        // The fit does not read the residual's coherence (the lobe search does).
        let fit_candidates = CandidateParams { measure_coherence: false, ..self.params.candidates.clone() };
        let receivers = averaged_receivers(&self.scene, &self.geometry, &self.average, &fit_candidates, self.params.distance_sigma_m, &mean);
        if receivers.len() < self.geometry.needed() {
            return;
        }
        let teeth: Vec<i64> = receivers
            .iter()
            .map(|rx| rx.candidates.nearest_index(crate::geometry::bistatic_distance(&mean, &self.geometry.tx_position, &rx.position).0))
            .collect();
        let Some((fit, _)) = refine_on_teeth(&self.geometry, &receivers, &teeth, &mean, 3) else { return };
        if (fit - mean).norm() > self.mode_radius() || !self.in_region(&fit) {
            return;
        }
        let Some(covariance) = frame_covariance(&self.geometry, &receivers, &fit) else { return };
        self.resting = Some((fit, covariance));
        // Every `far_lobe_search_s`, and whenever the average has doubled
        // since the last search (early in a rest each search is worth twice
        // the frames of the one before).
        let frames = self.average.frames();
        let due = frame.time_s - self.last_resting_search_s >= self.params.far_lobe_search_s || frames >= 2.0 * self.resting_search_frames;
        if self.lobe_test() && frames >= RESTING_LOBE_FRAMES && due {
            self.last_resting_search_s = frame.time_s;
            self.resting_search_frames = frames;
            self.search_resting_lobes(&fit);
        }
    }

    /// The lobe decision at rest: the initial tuple search (§5.3.1) on the
    /// averaged frame, its fits' log-likelihood ratios against the resting
    /// fit `fit` on that frame (K frames' evidence at once), and a switch
    /// when one passes `lobe_switch_nats`. A distant tag beside an in-line
    /// row has lobes that one frame barely tells apart (a rotation about the
    /// row, seen through one receiver's tooth and the envelope), and the
    /// per-frame tests of `lobes.rs` and `far_lobes.rs` drift between them;
    /// at rest they pause and this decides. On the averaged frame the
    /// envelope is K times sharper, so its receivers keep every tooth down
    /// to `RESTING_LOBE_RELATIVE_WEIGHT` of the peak with its own weight,
    /// and the mixture's floor (one frame's chance of a corrupt envelope)
    /// is divided by K: with one frame's floor, a lobe one tooth off on one
    /// receiver could never lose by more than ln(1/floor) = 6.9 nats
    /// (docs/notes/turbotrack-experiments.md).
    fn search_resting_lobes(&mut self, fit: &Vector3<f64>) {
        let frames = self.average.frames();
        let mut candidates = self.params.candidates.clone();
        candidates.min_relative_weight = candidates.min_relative_weight.min(RESTING_LOBE_RELATIVE_WEIGHT);
        let mut receivers = averaged_receivers(&self.scene, &self.geometry, &self.average, &candidates, self.params.distance_sigma_m, fit);
        if receivers.len() < self.geometry.needed() || multipath_frame(&receivers) {
            // A reflection biases the averaged envelope as it does each
            // frame's (`lobes::MULTIPATH_COHERENCE`): no lobe decision.
            return;
        }
        // The calibration residual (a bias per receiver, departure 14) does
        // not average away: lobes are compared with it in each receiver's σ.
        let calibration = self.params.calibration_sigma_m;
        receivers.iter_mut().for_each(|r| r.candidates.sigma_m = r.candidates.sigma_m.hypot(calibration));
        let floor = self.params.weight_floor / frames;
        let ll = |x: &Vector3<f64>| crate::track::bistatic::mixture_log_likelihood(&self.geometry, &receivers, x, floor).0;
        let at_fit = ll(fit);
        let mut others: Vec<(Vector3<f64>, f64)> = Vec::new();
        for (g, _) in self.initial_components(&receivers).iter().take(FAR_LOBE_SLOTS + 1) {
            if (g.mean - fit).norm() > self.mode_radius() && others.iter().all(|o| (o.0 - g.mean).norm() > self.mode_radius()) {
                others.push((g.mean, ll(&g.mean) - at_fit));
            }
        }
        let best = others.iter().enumerate().max_by(|a, b| a.1 .1.total_cmp(&b.1 .1)).map(|(i, o)| (i, *o));
        if let Some((i, (position, llr))) = best.filter(|b| b.1 .1 > self.params.lobe_switch_nats) {
            // Re-based on the new lobe; the lobe left joins the others.
            others.remove(i);
            others.iter_mut().for_each(|o| o.1 -= llr);
            others.push((*fit, -llr));
            self.resting_switch = Some(position - fit);
        }
        self.resting_lobes = Some(others);
    }

    /// Forgets the resting average and its lobes (the tag moved, a restart).
    fn clear_resting(&mut self) {
        self.average.clear();
        self.resting = None;
        self.resting_lobes = None;
        self.resting_switch = None;
        self.resting_search_frames = 0.0;
    }

    /// Particles within this distance of the best one form its mode
    /// (half the smallest candidate spacing: another comb tooth is another mode), m.
    fn mode_radius(&self) -> f64 {
        0.08
    }

    /// Whether the lobe test runs ([`lobe_test`]).
    fn lobe_test(&self) -> bool {
        lobe_test(&self.params)
    }

    /// The lobe test on an accepted frame (`lobes.rs`): the displacement
    /// to another lobe when one won.
    fn test_lobes(&mut self, receivers: &[Receiver], mean: &Vector3<f64>) -> Option<Vector3<f64>> {
        let levels = self.lobe_levels();
        let (scene, margin) = (&self.scene, self.params.region_margin_m);
        let in_region = |p: &Vector3<f64>| scene.region.as_ref().is_none_or(|r| r.contains(p, margin, scene.dimensions));
        match self.lobes.update(&LobeFrame { geometry: &self.geometry, receivers, weight_floor: self.params.weight_floor, levels: &levels }, mean, in_region) {
            LobeDecision::Stay => None,
            LobeDecision::Switch(d) => Some(d),
        }
    }

    fn lobe_levels(&self) -> LobeLevels {
        LobeLevels {
            switch_nats: self.params.lobe_switch_nats,
            floor_nats: self.params.lobe_floor_nats,
            frame_cap_nats: self.params.lobe_frame_cap_nats,
        }
    }

    /// The far-lobe test (`far_lobes.rs`) on any frame with receivers,
    /// outliers included (a filter on a wrong lobe sees mostly outliers):
    /// first the periodic global search, then the alternatives' evidence.
    /// The displacement to an alternative that won.
    fn test_far_lobes(&mut self, time_s: f64, receivers: &[Receiver], mean: &Vector3<f64>) -> Option<Vector3<f64>> {
        let levels = self.lobe_levels();
        if time_s - self.last_far_search_s >= self.params.far_lobe_search_s {
            self.last_far_search_s = time_s;
            let found: Vec<Vector3<f64>> = self.initial_components(receivers).iter().take(FAR_LOBE_SLOTS + 1).map(|c| c.0.mean).collect();
            self.far.offer(found, levels.frame_cap_nats - levels.floor_nats, Some(mean));
        }
        let (scene, margin) = (&self.scene, self.params.region_margin_m);
        let into_region = |p: &Vector3<f64>| scene.region.as_ref().map_or(*p, |r| r.clamp(p, margin, scene.dimensions));
        match self.far.update(&LobeFrame { geometry: &self.geometry, receivers, weight_floor: self.params.weight_floor, levels: &levels }, mean, into_region) {
            LobeDecision::Stay => None,
            LobeDecision::Switch(d) => Some(d),
        }
    }

    /// Moves the whole cloud by `d`, m (its shape kept; the next frames'
    /// cluster proposals reshape it), and the ancestry's newest entry with
    /// it; counted as a lobe switch.
    fn shift_cloud(&mut self, d: &Vector3<f64>) {
        self.positions.iter_mut().for_each(|p| *p += d);
        if let Some(last) = self.history.back_mut() {
            last.1.clone_from(&self.positions);
        }
        self.recent.clear();
        self.stats.lobe_switches += 1;
    }

    /// A per-frame lobe switch: the cloud moves. The resting average stays
    /// (it is the frames' data, whatever lobe it is fitted on; a switch is
    /// not motion); this frame's fit, made on the old lobe, goes.
    fn move_cloud(&mut self, d: &Vector3<f64>) {
        self.shift_cloud(d);
        self.resting = None;
    }

    fn estimate(&mut self, time_s: f64, receivers: Option<&[Receiver]>) -> Option<Estimate> {
        let best = self.best_particle()?;
        let (mut mean, mut covariance, mut weight) = mode_mean(&self.positions, &self.log_weights, best, self.mode_radius());
        if self.resting_lobes.is_some() {
            // At rest the average decides the lobe (`search_resting_lobes`);
            // the per-frame tests pause and start afresh when the tag moves.
            self.lobes.reset();
            self.far.reset();
            if let Some(d) = self.resting_switch.take() {
                // The average holds whatever the lobe: it stays.
                self.shift_cloud(&d);
                if let Some(r) = self.resting.as_mut() {
                    r.0 += d;
                }
                (mean, covariance, weight) = mode_mean(&self.positions, &self.log_weights, best, self.mode_radius());
            }
        } else if let Some(receivers) = receivers.filter(|r| self.lobe_test() && !multipath_frame(r)) {
            // Another lobe won: the whole cloud moves there.
            if let Some(d) = self.test_lobes(receivers, &mean) {
                self.move_cloud(&d);
                (mean, covariance, weight) = mode_mean(&self.positions, &self.log_weights, best, self.mode_radius());
            }
            if let Some(d) = self.test_far_lobes(time_s, receivers, &mean) {
                self.move_cloud(&d);
                (mean, covariance, weight) = mode_mean(&self.positions, &self.log_weights, best, self.mode_radius());
            }
        }
        if let Some((fit, fit_covariance)) = self.resting.take() {
            // The average assumes rest. A fit that the particles' mode does
            // not contain (squared Mahalanobis distance beyond
            // `RESTING_CONSISTENCY_CHI2`) means the tag has been moving, slowly
            // enough for the static mode to keep the weight: the average
            // lags it and starts over.
            let d = fit - mean;
            let consistent = (covariance + fit_covariance).try_inverse().is_some_and(|inverse| d.dot(&(inverse * d)) <= RESTING_CONSISTENCY_CHI2);
            if consistent {
                // The tag rests: every frame since, through their average.
                mean = fit;
                covariance = fit_covariance;
            } else {
                self.clear_resting();
            }
        }
        if self.lobe_test() {
            // Unresolved lobes widen the reported covariance (a mixture about the reported mean).
            covariance += self.lobes.spread(&mean) + self.far.spread(&mean);
            if let Some(others) = &self.resting_lobes {
                // Untempered, unlike the far lobes' per-frame evidence: the
                // averaged frame's ratio is one comparison with the error
                // that frames share (the calibration residual) already in
                // its σ, not a sum over correlated frames.
                covariance += mixture_spread(others.iter().copied(), &mean);
            }
        }
        if self.params.calibration_sigma_m > 0.0 {
            if let Some(c) = calibration_covariance(&self.geometry, &self.receive_positions, &mean, self.params.calibration_sigma_m) {
                covariance += c;
            }
        }
        self.recent.push_back((time_s, mean));
        while self.recent.front().is_some_and(|(t, _)| time_s - t > self.params.velocity_window_s) {
            self.recent.pop_front();
        }
        let velocity = slope(&self.recent);
        let e = Estimate::from_position(time_s, &mean, &covariance, [velocity.x, velocity.y, velocity.z], self.positions.len(), weight);
        self.last_estimate = Some(e.clone());
        Some(e)
    }

    /// The previous estimate carried forward to `time_s` (outlier recovery:
    /// "extrapolates the previous estimates").
    fn extrapolate(&mut self, time_s: f64) -> Option<Estimate> {
        let mut e = self.last_estimate.clone()?;
        let dt = time_s - e.time_s;
        if e.velocity.iter().all(|v| v.is_finite()) {
            for k in 0..3 {
                e.position[k] += e.velocity[k] * dt;
            }
        }
        e.time_s = time_s;
        Some(e)
    }

    /// The state before a restart, kept as a far-lobe alternative at even
    /// odds: a run of outliers (a reflection, a burst, the weak direction
    /// drifting) can restart the filter on a wrong lobe, and the evidence
    /// then brings it back (`far_lobes.rs`).
    fn keep_as_alternative(&mut self, before: Option<Vector3<f64>>) {
        if let Some(position) = before.filter(|_| self.lobe_test()) {
            self.far.prefer(position, 0.0);
        }
    }

    /// Forgets the particles and lobes; returns the last estimate's position, m.
    fn restart(&mut self) -> Option<Vector3<f64>> {
        let before = self.last_estimate.as_ref().map(|e| Vector3::from(e.position));
        self.initialised = false;
        self.positions.clear();
        self.log_weights.clear();
        self.modes.clear();
        self.history.clear();
        self.recent.clear();
        self.last_estimate = None;
        self.consecutive_outliers = 0;
        self.lobes.reset();
        self.far.reset();
        self.clear_resting();
        self.stats.reinitialisations += 1;
        before
    }

    fn step_frame(&mut self, frame: &WidebandFrame) -> Option<Estimate> {
        self.stats.measurements += 1;
        if !frame.time_s.is_finite() {
            self.stats.invalid += 1;
            return None;
        }
        if frame.time_s < self.last_time_s {
            self.stats.out_of_order += 1;
            return None;
        }
        let receivers = match self.receivers(frame) {
            Ok(r) => r,
            Err(_) => {
                self.stats.invalid += 1;
                return None;
            }
        };
        let mut before = None;
        if self.initialised && frame.time_s - self.last_time_s > self.params.reinit_gap_s {
            before = self.restart();
        }
        if !self.initialised {
            self.stats.initialising += 1;
            self.last_time_s = frame.time_s;
            if !self.initialise(frame.time_s, &receivers) {
                return None;
            }
            self.keep_as_alternative(before);
            self.stats.max_hypotheses = self.stats.max_hypotheses.max(self.positions.len() as u64);
            return self.estimate(frame.time_s, Some(&receivers));
        }
        self.stats.filter_updates += self.positions.len() as u64;
        let accepted = self.sequential_step(frame.time_s, &receivers);
        self.last_time_s = frame.time_s;
        if accepted {
            self.consecutive_outliers = 0;
            self.update_resting(frame);
            return self.estimate(frame.time_s, Some(&receivers));
        }
        self.stats.outliers += 1;
        if self.lobe_test() && self.resting_lobes.is_none() {
            // A filter on a wrong far lobe sees mostly outliers: the far
            // alternatives are tested on them too.
            if let Some(position) = self.last_estimate.as_ref().map(|e| Vector3::from(e.position)) {
                if let Some(d) = self.test_far_lobes(frame.time_s, &receivers, &position) {
                    self.move_cloud(&d);
                    self.consecutive_outliers = 0;
                    return self.estimate(frame.time_s, None);
                }
            }
        }
        self.consecutive_outliers += 1;
        if self.consecutive_outliers > self.params.max_consecutive_outliers {
            let before = self.restart();
            self.stats.initialising += 1;
            if self.initialise(frame.time_s, &receivers) {
                self.keep_as_alternative(before);
                return self.estimate(frame.time_s, Some(&receivers));
            }
            return None;
        }
        // At rest the frame still counts: in the weakly observed directions
        // most frames of a distant tag fail the jump test (their fix moves
        // centimetres along the weak direction), and the average is what
        // the rest of them are for.
        self.update_resting(frame);
        if self.resting.is_some() {
            return self.estimate(frame.time_s, None);
        }
        self.extrapolate(frame.time_s)
    }
}

/// The static particles' share of the weight from which the resting fit is
/// computed (and, if the particles' mode contains it, reported).
const RESTING_STATIC_WEIGHT: f64 = 0.2;

/// The resting fit's largest squared Mahalanobis distance from the
/// particles' mode (χ² with 3 degrees of freedom, p = 0.001).
const RESTING_CONSISTENCY_CHI2: f64 = 16.3;

/// Frames (effective, after forgetting) averaged before the lobes are
/// decided on the average (0.1 s at 300 frames/s: 15 dB above one frame).
const RESTING_LOBE_FRAMES: f64 = 30.0;

/// The averaged frame's teeth kept for the resting lobe search, relative
/// to the envelope's peak (one frame keeps those above half of it).
const RESTING_LOBE_RELATIVE_WEIGHT: f64 = 0.05;

/// Frames (effective, after forgetting) the resting average needs before
/// its fit is the estimate: 10 frames lift a frame's SNR by 10 dB.
const RESTING_MIN_FRAMES: f64 = 10.0;

/// Weighted mean and covariance (m, m²) of the particles within `radius`
/// of particle `best`, and their total weight.
fn mode_mean(positions: &[Vector3<f64>], log_weights: &[f64], best: usize, radius: f64) -> (Vector3<f64>, Matrix3<f64>, f64) {
    let centre = positions[best];
    let mut total = 0.0;
    let mut mean = Vector3::zeros();
    for (p, lw) in positions.iter().zip(log_weights) {
        if (p - centre).norm() <= radius {
            let w = lw.exp();
            total += w;
            mean += p * w;
        }
    }
    if !(total > 0.0) {
        return (centre, Matrix3::identity() * radius * radius, 0.0);
    }
    mean /= total;
    let mut cov = Matrix3::zeros();
    for (p, lw) in positions.iter().zip(log_weights) {
        if (p - centre).norm() <= radius {
            let r = p - mean;
            cov += r * r.transpose() * (lw.exp() / total);
        }
    }
    (mean, cov, total)
}

/// Least-squares slope of positions over time (m/s); zero with fewer than
/// two samples or no time spread.
fn slope(samples: &VecDeque<(f64, Vector3<f64>)>) -> Vector3<f64> {
    let n = samples.len() as f64;
    if samples.len() < 2 {
        return Vector3::zeros();
    }
    let t_mean = samples.iter().map(|s| s.0).sum::<f64>() / n;
    let p_mean = samples.iter().map(|s| s.1).sum::<Vector3<f64>>() / n;
    let stt: f64 = samples.iter().map(|s| (s.0 - t_mean).powi(2)).sum();
    if stt <= 0.0 {
        return Vector3::zeros();
    }
    samples.iter().map(|s| (s.1 - p_mean) * (s.0 - t_mean)).sum::<Vector3<f64>>() / stt
}

impl Tracker for TurboTrack {
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate> {
        match measurement {
            Measurement::Wideband(frame) => self.step_frame(frame),
            Measurement::Phase(_) => self.stats.decline_invalid(),
        }
    }

    fn stats(&self) -> TrackerStats {
        self.stats
    }

    fn reset(&mut self) {
        let stats = self.stats;
        self.restart();
        self.stats = stats;
        self.last_time_s = f64::NEG_INFINITY;
        self.rng = StdRng::seed_from_u64(self.params.seed);
    }

    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        self.positions.iter().zip(&self.log_weights).map(|(p, w)| ([p.x, p.y, p.z], *w)).collect()
    }

    fn trajectory(&self) -> Vec<(f64, [f64; 3])> {
        self.map_trajectory()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Role, SPEED_OF_LIGHT};
    use nalgebra::Complex;
    use rand_distr::Distribution;

    /// A helper on the floor: tx in the middle, four rx 40 cm around it.
    fn scene() -> Scene {
        Scene::plus_helper(3, 0.0)
    }

    /// Frames at 300 /s of a tag on `path` (docs/formats.md §5 convention:
    /// `exp(−j 2π f d / c)`), 20 subcarriers over 100 MHz, complex noise of
    /// rms 0.1 relative to the channel.
    fn frames(scene: &Scene, path: impl Fn(f64) -> Vector3<f64>, duration_s: f64, seed: u64) -> Vec<(WidebandFrame, Vector3<f64>)> {
        noisy_frames(scene, path, duration_s, seed, 0.1)
    }

    /// [`frames`] with complex noise of rms `noise` relative to the channel.
    fn noisy_frames(
        scene: &Scene,
        path: impl Fn(f64) -> Vector3<f64>,
        duration_s: f64,
        seed: u64,
        noise_rms: f64,
    ) -> Vec<(WidebandFrame, Vector3<f64>)> {
        let mut rng = StdRng::seed_from_u64(seed);
        let frequencies: Vec<f64> = (0..20).map(|k| 867.5e6 + 5e6 * k as f64).collect();
        let tx = scene.antennas[0].position;
        let rx: Vec<usize> = (1..5).collect();
        let n = (duration_s * 300.0) as usize;
        (0..n)
            .map(|i| {
                let t = i as f64 / 300.0;
                let p = path(t);
                let mut h = Vec::new();
                for &r in &rx {
                    let d = (p - tx).norm() + (p - scene.antennas[r].position).norm();
                    for &f in &frequencies {
                        let noise: (f64, f64) = (StandardNormal.sample(&mut rng), StandardNormal.sample(&mut rng));
                        let clean = Complex::from_polar(1.0, -std::f64::consts::TAU * f * d / SPEED_OF_LIGHT);
                        h.push(clean + Complex::new(noise.0, noise.1) * (noise_rms / 2f64.sqrt()));
                    }
                }
                (WidebandFrame { time_s: t, tx: 0, rx: rx.clone(), frequencies_hz: frequencies.clone(), h }, p)
            })
            .collect()
    }

    fn tracker() -> TurboTrack {
        TurboTrack::new(scene(), TurboTrackParams { particles: 2_000, ..TurboTrackParams::default() }).unwrap()
    }

    #[test]
    fn a_static_tag_converges_within_millimetres() {
        let truth = Vector3::new(0.5, 1.2, 0.8);
        let mut tracker = tracker();
        let mut errors = Vec::new();
        for (frame, p) in frames(&scene(), |_| truth, 2.0, 1) {
            let t = frame.time_s;
            if let Some(e) = tracker.step(&Measurement::Wideband(frame)) {
                if t >= 1.0 {
                    errors.push((Vector3::from(e.position) - p).norm());
                    assert!(e.position_sigma().iter().all(|s| s.is_finite() && *s > 0.0), "{e:?}");
                }
            }
        }
        assert!(errors.len() > 250, "{} estimates after 1 s", errors.len());
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 3e-3, "median error {median} m");
        assert!(errors[errors.len() * 9 / 10] < 6e-3, "p90 {} m", errors[errors.len() * 9 / 10]);
    }

    /// The smoothed (MAP) trajectory is causal bookkeeping of the frames
    /// seen: ascending times, ending near the moving tag.
    #[test]
    fn a_moving_tag_is_followed_and_its_map_trajectory_kept() {
        let path = |t: f64| Vector3::new(0.4 + 0.1 * t, 1.1 + 0.05 * t, 0.8);
        let mut tracker = tracker();
        let mut last = None;
        for (frame, p) in frames(&scene(), path, 2.0, 2) {
            if let Some(e) = tracker.step(&Measurement::Wideband(frame)) {
                last = Some((Vector3::from(e.position) - p).norm());
            }
        }
        assert!(last.unwrap() < 0.01, "final error {last:?} m");
        let trajectory = tracker.trajectory();
        assert!(trajectory.len() > 100);
        assert!(trajectory.windows(2).all(|w| w[0].0 < w[1].0));
        let mut smoothed: Vec<f64> =
            trajectory.iter().filter(|(t, _)| *t >= 1.0).map(|(t, p)| (Vector3::from(*p) - path(*t)).norm()).collect();
        smoothed.sort_by(f64::total_cmp);
        assert!(!smoothed.is_empty() && smoothed[smoothed.len() / 2] < 0.01, "smoothed median error {:?} m", smoothed.get(smoothed.len() / 2));
    }

    #[test]
    fn declines_what_it_cannot_use_and_resets() {
        let mut tracker = tracker();
        let frames = frames(&scene(), |_| Vector3::new(0.5, 1.2, 0.8), 0.5, 3);
        for (f, _) in &frames[..60] {
            tracker.step(&Measurement::Wideband(f.clone()));
        }
        let late = WidebandFrame { time_s: 0.0, ..frames[60].0.clone() };
        assert!(tracker.step(&Measurement::Wideband(late)).is_none());
        let read = super::super::PhaseRead { time_s: 1.0, antenna: 1, frequency_hz: 915e6, phase_rad: 0.1 };
        assert!(tracker.step(&Measurement::Phase(read)).is_none());
        let s = tracker.stats();
        assert_eq!((s.measurements, s.out_of_order, s.invalid), (62, 1, 1));
        tracker.reset();
        assert_eq!(tracker.stats().measurements, 62, "reset keeps the counters");
        assert!(tracker.trajectory().is_empty(), "reset forgets the trajectory");
    }

    /// Median 3D error (m) of the estimates from `from_s` on.
    fn median_error(tracker: &mut TurboTrack, frames: Vec<(WidebandFrame, Vector3<f64>)>, from_s: f64) -> f64 {
        let mut errors = Vec::new();
        for (frame, p) in frames {
            let t = frame.time_s;
            if let Some(e) = tracker.step(&Measurement::Wideband(frame)) {
                if t >= from_s {
                    errors.push((Vector3::from(e.position) - p).norm());
                }
            }
        }
        errors.sort_by(f64::total_cmp);
        errors[errors.len() / 2]
    }

    /// At low SNR a tag at rest is averaged over many frames by the static
    /// mode's particles; with every particle moving (the thesis's single
    /// random walk) the estimate follows each frame's noise.
    #[test]
    fn the_static_mode_averages_a_tag_at_rest() {
        let truth = Vector3::new(0.5, 1.2, 0.8);
        let run = |entry: f64| {
            let params = TurboTrackParams { particles: 300, static_entry_probability: entry, ..TurboTrackParams::default() };
            let mut tracker = TurboTrack::new(scene(), params).unwrap();
            let error = median_error(&mut tracker, noisy_frames(&scene(), |_| truth, 3.0, 11, 1.0), 1.0);
            let static_weight: f64 =
                tracker.modes.iter().zip(&tracker.log_weights).filter(|(m, _)| **m).map(|(_, w)| w.exp()).sum();
            (error, static_weight)
        };
        let ((with_mode, static_weight), (single, none)) = (run(0.01), run(0.0));
        assert!(with_mode < 0.75 * single, "static mode {with_mode} m against the single random walk {single} m");
        // The prior share of static particles is 0.01 / 0.21 ≈ 5 %: the
        // weights, not the prior, put the tag at rest.
        assert!(static_weight > 0.2, "weight on static particles {static_weight}");
        assert_eq!(none, 0.0);
    }

    /// A tag that rests and then moves is followed by the moving particles
    /// that the mode switching keeps alive.
    #[test]
    fn a_tag_that_starts_moving_is_followed() {
        let path = |t: f64| Vector3::new(0.4 + 0.2 * (t - 1.0).max(0.0), 1.1, 0.8);
        let mut tracker = tracker();
        let mut worst: f64 = 0.0;
        for (frame, p) in noisy_frames(&scene(), path, 2.5, 12, 0.3) {
            let t = frame.time_s;
            if let Some(e) = tracker.step(&Measurement::Wideband(frame)) {
                if t >= 1.5 {
                    worst = worst.max((Vector3::from(e.position) - p).norm());
                }
            }
        }
        assert!(worst < 0.02, "worst error after the start {worst} m");
    }

    /// σ² (JᵀJ)⁻¹ with J from finite differences of the path sums: the
    /// analytic gradients agree, a planar scene has no z, and the spread
    /// grows as the tag nears the receivers' plane (z poorly fixed there).
    #[test]
    fn calibration_covariance_matches_finite_differences() {
        let s = scene();
        let geometry = HelperGeometry::new(&s).unwrap();
        let rx: Vec<Vector3<f64>> = s.antennas.iter().filter(|a| a.role == Role::Rx).map(|a| a.position).collect();
        let sigma = 0.004;
        let p = Vector3::new(0.7, 1.1, 0.6);
        let path = |q: &Vector3<f64>, r: &Vector3<f64>| (q - geometry.tx_position).norm() + (q - r).norm();
        let mut information = Matrix3::zeros();
        for r in &rx {
            let h = 1e-6;
            let g = Vector3::from_fn(|k, _| {
                let mut dq = Vector3::zeros();
                dq[k] = h;
                (path(&(p + dq), r) - path(&(p - dq), r)) / (2.0 * h)
            });
            information += g * g.transpose();
        }
        let expected = information.try_inverse().unwrap() * sigma * sigma;
        let c = calibration_covariance(&geometry, &rx, &p, sigma).unwrap();
        assert!((c - expected).norm() < 1e-6 * expected.norm(), "{c} against {expected}");
        let low = calibration_covariance(&geometry, &rx, &Vector3::new(0.7, 1.1, 0.15), sigma).unwrap();
        assert!(low[(2, 2)] > 4.0 * c[(2, 2)], "z variance {} near the plane against {}", low[(2, 2)], c[(2, 2)]);
        let planar = HelperGeometry::new(&Scene::plus_helper(2, 0.0)).unwrap();
        let c2 = calibration_covariance(&planar, &rx, &Vector3::new(0.7, 1.1, 0.0), sigma).unwrap();
        assert_eq!([c2[(2, 2)], c2[(0, 2)], c2[(2, 1)]], [0.0; 3]);
        assert!(c2[(0, 0)] > 0.0 && c2[(1, 1)] > 0.0);
    }

    #[test]
    fn rejects_invalid_mode_parameters() {
        for params in [
            TurboTrackParams { static_sigma_m: 0.0, ..TurboTrackParams::default() },
            TurboTrackParams { static_entry_probability: 1.0, ..TurboTrackParams::default() },
            TurboTrackParams { static_exit_probability: 0.0, ..TurboTrackParams::default() },
            TurboTrackParams { calibration_sigma_m: -1e-3, ..TurboTrackParams::default() },
        ] {
            assert!(matches!(TurboTrack::new(scene(), params), Err(Error::Parameter { .. })));
        }
    }

    #[test]
    fn a_scene_without_a_transmitter_is_rejected() {
        let mut s = scene();
        s.antennas.iter_mut().for_each(|a| a.role = Role::TxRx);
        assert!(matches!(TurboTrack::new(s, TurboTrackParams::default()), Err(Error::Scene(_))));
    }
}
