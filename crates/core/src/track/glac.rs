//! GLAC: HMM over candidate trajectories, one EKF each, updated by a single
//! phase reading (Wang, Chen, Gong, "Mobility Improves Accuracy", sec. 3).
//!
//! * Each hypothesis (candidate trajectory) carries an EKF on
//!   x = [p, v] (eq. 3, constant velocity) and a log-likelihood.
//! * A reading φ from antenna a on carrier f constrains the range to
//!   d₀ + n·s (s = λ/2, λ/4 mod π). Nearest-neighbour pruning (eq. 9): each
//!   hypothesis takes the candidate nearest its predicted range, so the
//!   number of hypotheses never grows.
//! * The initial hypotheses come from initial state pruning (sec. 3.2.2,
//!   [`super::initial`]) with likelihood L₀ (eq. 10).
//! * Likelihoods propagate per reading (eqs. 11–13) and are normalised over
//!   hypotheses after every reading; the best one is reported.
//! * Quick stop: hypotheses whose normalised likelihood falls below l_th
//!   are removed. Recovery: a reading that would change the velocity by
//!   more than 3σ_v is replaced by the prediction. The velocity change is
//!   Δv = K_v ν, linear in the innovation ν, so its 3σ test is the 3σ test
//!   of ν against √S; that is how it is computed.
//! * Region constraint: hypotheses that leave the region are removed (this
//!   is what rejects mirror solutions of coplanar antennas).
//! * Re-initialisation when every hypothesis has lost lock (too many
//!   consecutive gated readings) or the tag goes unread for `reinit_gap_s`.
//!
//! Beyond the paper (docs/glac.md says why): each hypothesis runs two
//! motion models as an IMM (`manoeuvre_q`), the initial search tries
//! unwrapping branches when two reads of an antenna are far apart, and a
//! hypothesis whose predicted range is too uncertain for nearest-neighbour
//! pruning also follows the second-nearest candidate (ambiguity branching).
//!
//! Variants (sec. 5.2.2–5.2.3): no velocity model ([`MotionModel::RandomWalk`]),
//! synchronous 4-read handling ([`Inference::Synchronous`]) and naive,
//! unpruned inference ([`Inference::Naive`]).

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};

use super::candidates::nearest_candidate;
use super::bias::{BiasClock, BiasPrediction, BiasStep};
use super::initial::{initial_covariance, InitialSearch, InitialState};
use super::read_budget::Budget;
use super::line_twins::{line_layout, line_twins, LineLayout};
use super::{Estimate, Measurement, PhaseRead, Tracker, TrackerStats};
use crate::error::{Error, Result};
use crate::filter::{apply_scalar, imm, innovation, log_gaussian, pack_pair, predict, unpack_pair, update_position, PackedCovariance};
use crate::geometry::multilaterate;
use crate::model::{apparent_range, range, reflected_paths, MotionModel, ReflectedPath, StateMatrix, StateVector, Transition};
use crate::scene::{Scene, SPEED_OF_LIGHT};

/// How hypotheses are expanded per reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Inference {
    /// Nearest-neighbour pruning + quick stop (GLAC's fast inference).
    Fast,
    /// Every hypothesis branches on every candidate distance in range:
    /// exponential growth, capped at `max_hypotheses` (sec. 5.2.3).
    Naive,
    /// Every group of reads covering all antennas is trilaterated into a
    /// position and used as one synchronous measurement (sec. 5.2.2).
    Synchronous,
}

/// The per-reading likelihood factor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Likelihood {
    /// p(z | z_{1:k−1}) = N(ν; 0, S): the EKF's marginal likelihood of the
    /// reading under the predicted state (the exact HMM forward factor under
    /// linearisation).
    Innovation,
    /// The paper's eqs. 12–13 literally: F(d_{k+1}; z*, R) at the updated
    /// state times F(θ_{k+1}; Aθ_k, Q).
    Paper,
}

/// Parameters of GLAC and its variants. Units are SI.
#[derive(Debug, Clone, PartialEq)]
pub struct GlacParams {
    pub inference: Inference,
    pub likelihood: Likelihood,
    /// Motion model (eq. 3) and its process noise.
    pub motion: MotionModel,
    /// 1-sigma phase noise, radians; `None` takes the scene's prior.
    pub phase_noise_rad: Option<f64>,
    /// 1-sigma of the phase error that is correlated in time on each
    /// antenna (wander, calibration error, multipath), radians; 0 treats
    /// all error as white. See [`correlated_variance_factor`].
    pub phase_wander_rad: f64,
    /// Correlation time τ of that error, seconds.
    pub phase_wander_s: f64,
    /// 1-sigma of a slowly varying phase bias per antenna (wander,
    /// residual calibration, multipath; real readers show 0.05–0.1 rad over
    /// ~0.5 s beyond their read-to-read noise), radians. With `bias_state`
    /// (fast inference) each hypothesis estimates it; otherwise its effect
    /// on the position, σ_b² (λ/4π)² (Jᵀ J)⁻¹ with J the unit vectors from
    /// the antennas to the tag, is added to the reported covariance (a
    /// "consider" covariance) without changing the estimate. Either way a
    /// scene that states only the white noise gets sigmas that cover the
    /// truth. 0 disables both.
    pub bias_sigma_rad: f64,
    /// Estimate that bias per antenna in each hypothesis as an AR(1)
    /// state (stationary 1-sigma `bias_sigma_rad`, correlation time
    /// `bias_time_s`) instead of only counting it in the reported sigma
    /// (fast inference). The innovation then separates a slow bias from
    /// the motion, so that a true trajectory is not charged for it.
    pub bias_state: bool,
    /// Correlation time τ_b of the bias, seconds.
    pub bias_time_s: f64,
    /// 1-sigma of the bias share that changes with the carrier (per-channel
    /// calibration residual, multipath), radians: when an antenna's read is
    /// on another channel than its previous one, this variance is added to
    /// its bias states. 0: the bias ignores hops.
    pub hop_bias_sigma_rad: f64,
    /// A second bias level σ_b (rad) run beside `bias_sigma_rad` as a
    /// bank of two trackers ([`super::glac_bank`]; `glac`, fast inference
    /// with `bias_state`): the one whose accumulated evidence of the reads
    /// is larger is reported. `None`: one tracker.
    pub bank_sigma_rad: Option<f64>,
    /// The bias correlation time of that second tracker, seconds; `None`:
    /// `bias_time_s`.
    pub bank_time_s: Option<f64>,
    /// The bank switches the reported tracker when another's log evidence
    /// is ahead by this many nats.
    pub bank_switch_nats: f64,
    /// ... and drops a tracker behind the best by this many nats.
    pub bank_drop_nats: f64,
    /// Collect at least this long before initialising, seconds.
    pub init_window_s: f64,
    /// Give up waiting for every antenna after this long, seconds.
    pub init_max_window_s: f64,
    pub initial: InitialState,
    /// Initial 1-sigma position uncertainty of a hypothesis, metres.
    pub init_position_sigma_m: f64,
    /// Initial 1-sigma velocity uncertainty, m/s.
    pub init_velocity_sigma_m_s: f64,
    /// Quick-stop threshold l_th on normalised likelihood.
    pub quick_stop: f64,
    /// Temperature T ≥ 1 of the hypothesis weights in the reported
    /// covariance (see [`mixture_covariance`]): the competitors count as if
    /// the evidence against them were T times weaker. Selection and
    /// pruning use the plain likelihoods.
    pub weight_temperature: f64,
    /// Recovery gate, in sigmas. The paper's 3σ_v lets about one
    /// uniform outlier in seven through on a λ/4 candidate step, and an
    /// accepted outlier displaces the state by centimetres; 2.5σ lets a
    /// sixth fewer through and charges a clean read only 1.2 % of the time
    /// (docs/glac.md, "3σ_v recovery as an innovation gate").
    pub gate_sigmas: f64,
    /// A hypothesis that gates this many readings in a row has lost lock.
    pub max_consecutive_outliers: u32,
    /// Start over when a tag has not been read for this long, seconds.
    pub reinit_gap_s: f64,
    /// Re-seeding, seconds between searches (0 disables): while the track
    /// is unresolved (competing hypotheses leave a sigma above 4 cm, see
    /// [`Glac::unresolved`]) or the
    /// reported hypothesis gated reads since the last search, the initial
    /// search runs again on the last `init_max_window_s` of reads and its
    /// candidates that no hypothesis already follows join at a small
    /// weight ([`RESEED_WEIGHT`]). A true trajectory that the first search
    /// missed, or that was pruned, can so come back.
    pub reseed_interval_s: f64,
    /// Longest interval between re-seeding searches while the track stays
    /// unresolved, seconds: each search started only because competing
    /// hypotheses remain doubles the interval up to this, and gated reads
    /// or a resolved track bring it back to `reseed_interval_s`. A tag
    /// whose reads cannot decide (a near-twin geometry) keeps its
    /// candidates alive, and searching again every second costs ~200 times
    /// tracking them; but under multipath the searches' newcomers are what
    /// keeps the sigmas honest (docs/glac.md, "Re-seeding"), so the default
    /// equals `reseed_interval_s`: no back-off.
    pub reseed_max_interval_s: f64,
    /// Fastest the tag can move, m/s: after a restart (a read gap, or lost
    /// lock) the new search keeps only candidates within
    /// `max_speed_m_s · gap + 3σ` of the last estimate, and until it
    /// commits the tracker reports that last estimate with the reachable
    /// ball as its uncertainty (re-acquisition from the last good state).
    pub max_speed_m_s: f64,
    /// Hypotheses further than this outside the region are removed, metres.
    pub region_margin_m: f64,
    /// Hypotheses closer than this (position) are merged, metres.
    pub merge_distance_m: f64,
    /// Cap on live hypotheses (bounds naive inference's memory).
    pub max_hypotheses: usize,
    /// Process noise q (m²/s³) of a second, manoeuvring constant-velocity
    /// model run as an IMM beside `motion` (fast inference only); `None`
    /// keeps the paper's single model. A robot-carried tag alternates
    /// between near-constant velocity (small q: accurate velocity) and
    /// sharp turns (large q: no loss of lock), which one q cannot serve.
    pub manoeuvre_q: Option<f64>,
    /// IMM Markov switch probability per reading.
    pub model_switch_probability: f64,
    /// Ambiguity branching (fast inference) only while fewer hypotheses
    /// than this are live; 0 disables it (the paper's pure nearest
    /// neighbour).
    pub max_branching_hypotheses: usize,
    /// Most work one read does, in [`Budget`] units (one unit: about one
    /// hypothesis through one read, ~0.2 µs). The initial search, the
    /// replay of buffered reads through thousands of mod-π hypotheses and
    /// re-seeding carry what is left to the tag's next reads (queued, and
    /// taken in order, so the result is the same); meanwhile the tag
    /// reports nothing, or the re-acquisition estimate after a restart.
    /// 2,000 units keep a read near 0.5 ms. Fast inference only: the
    /// naive and synchronous variants run unbudgeted.
    pub read_budget: usize,
}

impl Default for GlacParams {
    fn default() -> Self {
        Self {
            inference: Inference::Fast,
            likelihood: Likelihood::Innovation,
            motion: MotionModel::ConstantVelocity { q: 0.02 },
            phase_noise_rad: None,
            phase_wander_rad: 0.0,
            phase_wander_s: 0.5,
            bias_sigma_rad: 0.07,
            bias_state: true,
            bias_time_s: 0.5,
            hop_bias_sigma_rad: 0.1,
            bank_sigma_rad: None,
            bank_time_s: None,
            bank_switch_nats: 3.0,
            bank_drop_nats: 20.0,
            init_window_s: 0.3,
            init_max_window_s: 1.0,
            initial: InitialState::default(),
            init_position_sigma_m: 0.01,
            init_velocity_sigma_m_s: 0.1,
            quick_stop: 1e-6,
            weight_temperature: 3.0,
            gate_sigmas: 2.5,
            max_consecutive_outliers: 8,
            reinit_gap_s: 1.0,
            max_speed_m_s: 1.0,
            reseed_interval_s: 1.0,
            reseed_max_interval_s: 1.0,
            region_margin_m: 0.05,
            merge_distance_m: 0.002,
            max_hypotheses: 200_000,
            manoeuvre_q: Some(1.0),
            model_switch_probability: 0.05,
            max_branching_hypotheses: 16,
            read_budget: 2_000,
        }
    }
}

impl GlacParams {
    /// Switches to the no-velocity variant (sec. 5.2.2, scheme 2): position
    /// random walk whose diffusion matches what the constant-velocity model
    /// would allow over a typical speed (q_rw = v² · τ with v = 0.3 m/s,
    /// τ = 0.1 s) unless already a random walk.
    pub fn motion_model_no_velocity(&mut self) {
        if self.motion.has_velocity() {
            self.motion = MotionModel::RandomWalk { q: 0.3 * 0.3 * 0.1 };
        }
    }

    fn validate(&self) -> Result<()> {
        let positive = [
            ("init_window_s", self.init_window_s),
            ("init_max_window_s", self.init_max_window_s),
            ("init_position_sigma_m", self.init_position_sigma_m),
            ("init_velocity_sigma_m_s", self.init_velocity_sigma_m_s),
            ("gate_sigmas", self.gate_sigmas),
            ("reinit_gap_s", self.reinit_gap_s),
            ("max_speed_m_s", self.max_speed_m_s),
            ("reseed_max_interval_s", self.reseed_max_interval_s),
            ("phase_wander_s", self.phase_wander_s),
            ("bias_time_s", self.bias_time_s),
        ];
        for (name, v) in positive {
            if !(v > 0.0 && v.is_finite()) {
                return Err(Error::Parameter { name: name.into(), reason: format!("must be positive, got {v}") });
            }
        }
        if !(self.bias_sigma_rad >= 0.0 && self.bias_sigma_rad.is_finite()) {
            return Err(Error::Parameter { name: "bias_sigma_rad".into(), reason: "must be zero or positive".into() });
        }
        if !(self.hop_bias_sigma_rad >= 0.0 && self.hop_bias_sigma_rad.is_finite()) {
            return Err(Error::Parameter { name: "hop_bias_sigma_rad".into(), reason: "must be zero or positive".into() });
        }
        for (name, v) in [("bank_sigma_rad", self.bank_sigma_rad), ("bank_time_s", self.bank_time_s)] {
            if v.is_some_and(|v| !(v > 0.0 && v.is_finite())) {
                return Err(Error::Parameter { name: name.into(), reason: "must be positive".into() });
            }
        }
        if !(self.bank_switch_nats > 0.0 && self.bank_drop_nats >= self.bank_switch_nats) {
            return Err(Error::Parameter { name: "bank_drop_nats".into(), reason: "must be at least bank_switch_nats (both positive)".into() });
        }
        if !(self.phase_wander_rad >= 0.0 && self.phase_wander_rad.is_finite()) {
            return Err(Error::Parameter { name: "phase_wander_rad".into(), reason: "must be zero or positive".into() });
        }
        if !(self.reseed_interval_s >= 0.0 && self.reseed_interval_s.is_finite()) {
            return Err(Error::Parameter { name: "reseed_interval_s".into(), reason: "must be zero or positive".into() });
        }
        if !(self.weight_temperature >= 1.0 && self.weight_temperature.is_finite()) {
            return Err(Error::Parameter { name: "weight_temperature".into(), reason: "must be at least 1".into() });
        }
        if !(0.0..1.0).contains(&self.quick_stop) {
            return Err(Error::Parameter { name: "quick_stop".into(), reason: "must be in [0, 1)".into() });
        }
        let q = match self.motion {
            MotionModel::ConstantVelocity { q } | MotionModel::RandomWalk { q } => q,
        };
        if !(q > 0.0 && q.is_finite()) {
            return Err(Error::Parameter { name: "q".into(), reason: format!("process noise must be positive, got {q}") });
        }
        if self.manoeuvre_q.is_some_and(|q| !(q > 0.0 && q.is_finite())) {
            return Err(Error::Parameter { name: "manoeuvre_q".into(), reason: "must be positive".into() });
        }
        if self.likelihood == Likelihood::Paper && self.manoeuvre_q.is_some() && self.inference == Inference::Fast {
            return Err(Error::Parameter {
                name: "likelihood".into(),
                reason: "'paper' (eqs. 12-13) is defined for one motion model: set manoeuvre_q = None".into(),
            });
        }
        if !(0.0..=0.5).contains(&self.model_switch_probability) {
            return Err(Error::Parameter { name: "model_switch_probability".into(), reason: "must be in [0, 0.5]".into() });
        }
        if self.read_budget == 0 {
            return Err(Error::Parameter { name: "read_budget".into(), reason: "must be at least 1".into() });
        }
        if self.max_hypotheses == 0 {
            return Err(Error::Parameter { name: "max_hypotheses".into(), reason: "must be at least 1".into() });
        }
        Ok(())
    }
}

/// One candidate trajectory: two model-conditioned filters for the IMM
/// (single-model trackers use slot 0 only, μ = [1, 0]), its log-likelihood
/// and its run of gated readings. A read steps every field of a
/// hypothesis together, so they are stored together: with thousands of
/// tags a converged tag's hypothesis is one run of memory that the
/// prefetcher streams in, not five arrays that each miss.
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    /// Model probabilities μ (IMM).
    mu: [f64; 2],
    x: [StateVector; 2],
    /// Covariances, packed between steps (unpacked around each filter step).
    p: [PackedCovariance; 2],
    log_likelihood: f64,
    /// Consecutive gated readings.
    outliers: u32,
}

/// Candidate trajectories as one flat array, and their bias states.
#[derive(Debug, Clone)]
struct Hypotheses {
    items: Vec<Hypothesis>,
    /// Per hypothesis and antenna (the first `biases`, at most
    /// [`MAX_BIASES`]): the estimated range bias (m) and its variance (m²)
    /// of the AR(1) phase-bias state, at `i * biases + antenna`.
    bias: Vec<[f64; 2]>,
    biases: usize,
}

/// Twins up to this many candidate spacings away count in the covariance.
const MAX_TWIN_SHIFT: i32 = 3;

/// Total weight of the candidates a re-seeding search adds (the live
/// hypotheses keep the rest): small, so that a wrong newcomer dies in a few
/// reads and a true one must earn its place.
pub const RESEED_WEIGHT: f64 = 1e-3;
/// At most this many candidates per re-seeding search (best first).
const RESEED_MAX_CANDIDATES: usize = 300;
/// A re-seeded candidate this close to a live hypothesis (m) is the same
/// trajectory and is not added.
const RESEED_DISTANCE_M: f64 = 0.01;
/// Re-seed while competing hypotheses leave a sigma above this (m): a
/// quarter of the λ/2 candidate spacing.
const RESEED_SIGMA_M: f64 = 0.04;
/// For this long after the reported trajectory last switched to another
/// candidate (s), a track is unresolved while its reported sigma exceeds
/// [`RESEED_SIGMA_M`]; afterwards while its hypotheses' plain-weight
/// spread does ([`plain_spread`]). See [`Glac::unresolved`].
const SWITCH_MEMORY_S: f64 = 5.0;
/// Once a track has been resolved, the reported trajectory moves to
/// another hypothesis only when that one explains the reads this much
/// better (log-likelihood, nats) than the one nearest the last report:
/// without it the report flips between two near-equal candidates a metre
/// apart read by read (after a gap, single-read jumps of 0.7 m between
/// rows 2 mm from the truth). 3 nats untempered is 1 nat at
/// `weight_temperature` 3, the evidence `bank_switch_nats` asks of a bank
/// switch. See [`Glac::reported`].
const REPORT_HOLD_NATS: f64 = 3.0;

/// Hypothesis arrays larger than this (and four times what is live) are
/// shrunk after pruning ([`Hypotheses::retain`]).
const SHRINK_CAPACITY: usize = 32;

/// Antennas (by index) that get a bias state; further ones count their
/// bias as white noise. A hypothesis holds one per antenna up to this.
pub const MAX_BIASES: usize = 8;

impl Hypotheses {
    /// Room for `n` hypotheses with bias states for `biases` antennas.
    fn with_capacity(n: usize, biases: usize) -> Self {
        Self { items: Vec::with_capacity(n), bias: Vec::with_capacity(n * biases), biases }
    }

    /// Hypothesis `i`'s bias states (mean m, variance m²), by antenna.
    fn biases_of(&self, i: usize) -> &[[f64; 2]] {
        &self.bias[i * self.biases..(i + 1) * self.biases]
    }

    fn len(&self) -> usize {
        self.items.len()
    }

    fn clear(&mut self) {
        self.items.clear();
        self.bias.clear();
    }

    /// The log-likelihoods, in order.
    fn log_likelihoods(&self) -> impl Iterator<Item = f64> + '_ {
        self.items.iter().map(|h| h.log_likelihood)
    }

    fn push(&mut self, x: StateVector, p: StateMatrix, log_likelihood: f64) {
        let packed = PackedCovariance::pack(&p);
        self.items.push(Hypothesis { mu: [1.0, 0.0], x: [x, x], p: [packed, packed], log_likelihood, outliers: 0 });
        // Unknown until the antenna is first read, when the AR(1)
        // prediction (ρ = 0) sets the stationary variance.
        self.bias.extend(std::iter::repeat_n([0.0; 2], self.biases));
    }

    /// Appends a copy of hypothesis `i` (for ambiguity branching).
    fn duplicate(&mut self, i: usize) {
        self.items.push(self.items[i]);
        self.bias.extend_from_within(i * self.biases..(i + 1) * self.biases);
    }

    /// Appends hypothesis `i` of `other` with log-likelihood `log_likelihood`.
    fn append_from(&mut self, other: &Hypotheses, i: usize, log_likelihood: f64) {
        self.items.push(Hypothesis { log_likelihood, ..other.items[i] });
        debug_assert_eq!(self.biases, other.biases);
        self.bias.extend_from_slice(other.biases_of(i));
    }

    /// The reported state of hypothesis `i`: the IMM combination (which
    /// is slot 0 itself for single-model trackers, where μ = [1, 0]).
    fn state(&self, i: usize) -> (StateVector, StateMatrix) {
        let h = &self.items[i];
        if h.mu[1] == 0.0 {
            (h.x[0], h.p[0].unpack())
        } else {
            imm::combine(&h.x, &unpack_pair(&h.p), &h.mu)
        }
    }

    /// Keeps the hypotheses for which `keep(i)` holds, in order.
    fn retain(&mut self, keep: impl Fn(usize) -> bool) {
        let mut w = 0;
        for r in 0..self.len() {
            if keep(r) {
                // Swapping a hypothesis with itself would copy it three
                // times for nothing.
                if w != r {
                    self.items.swap(w, r);
                    let b = self.biases;
                    let (low, high) = self.bias.split_at_mut(r * b);
                    low[w * b..(w + 1) * b].swap_with_slice(&mut high[..b]);
                }
                w += 1;
            }
        }
        self.items.truncate(w);
        self.bias.truncate(w * self.biases);
        // A tag that has narrowed to a few trajectories gives back the room
        // its search needed (about 0.5 kB a hypothesis; 100+ while it
        // initialises): 10,000 converged tags then hold kilobytes each,
        // not the initial search's peak. Regrowing on a later branching is
        // one allocation per array.
        if self.items.capacity() > SHRINK_CAPACITY && self.items.capacity() > 4 * w {
            let room = w.max(SHRINK_CAPACITY / 2);
            self.items.shrink_to(room);
            self.bias.shrink_to(room * self.biases);
        }
    }

    /// Index of the likeliest hypothesis (the one reported), if any.
    fn best(&self) -> Option<usize> {
        (0..self.len()).max_by(|&a, &b| self.items[a].log_likelihood.total_cmp(&self.items[b].log_likelihood))
    }

    /// Normalises log-likelihoods so that Σ exp = 1 (log-sum-exp).
    fn normalise(&mut self) {
        // A lone finite hypothesis normalises to exactly 0 (l − (l + ln e⁰)):
        // the converged tag's every read, without an exp and a log.
        if let [only] = self.items.as_mut_slice() {
            if only.log_likelihood.is_finite() {
                only.log_likelihood = 0.0;
                return;
            }
        }
        let max = self.log_likelihoods().fold(f64::NEG_INFINITY, f64::max);
        let sum: f64 = self.log_likelihoods().map(|l| (l - max).exp()).sum();
        let log_norm = max + sum.ln();
        for h in &mut self.items {
            h.log_likelihood -= log_norm;
        }
    }
}

/// What the tracker is doing.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Phase {
    /// Collecting reads for initial state pruning.
    Initialising,
    /// Hypotheses are live.
    Tracking,
}

/// The GLAC tracker for one tag.
///
/// Laid out in declaration order (`repr(C)`), what a converged tag's read
/// touches first: with 10,000 tags no tag's state is in cache when its
/// next read comes (each read misses on every cache line it touches, about
/// 40 of them before this layout), so the fields every read uses sit
/// together and the large, rarely used ones (searches under way, buffers)
/// are boxed or last.
#[repr(C)]
pub struct Glac {
    /// Shared by every tag's tracker of one engine ([`Tracker::fresh`]):
    /// read on every step, so one copy stays in cache for all of them.
    scene: Arc<Scene>,
    params: Arc<GlacParams>,
    /// Per antenna, the reflected paths of the scene's known reflectors
    /// (empty without them); a read's step shares its antenna's.
    reflected: Vec<Arc<[ReflectedPath]>>,
    hypotheses: Hypotheses,
    /// Time of the hypotheses' states, seconds.
    time_s: f64,
    /// Time of the last accepted measurement, seconds.
    last_time_s: f64,
    /// Time of the latest read accepted (out-of-order check), seconds.
    arrival_s: f64,
    /// Carrier of the latest read, Hz (NaN before any).
    last_frequency_hz: f64,
    /// Carrier of the first read, Hz, and whether any read was on another
    /// channel since (then twins of one channel no longer fit, provided
    /// the scene's channel offsets are calibrated).
    first_frequency_hz: f64,
    /// Time of the last (re-)seeding search, seconds.
    seeded_s: f64,
    /// When the reported trajectory last jumped to another candidate (or
    /// the track was committed), seconds.
    switched_s: f64,
    /// Moving axes: 2 (tag in the plane z = plane_z) or 3.
    axes: usize,
    /// Reads the reported hypothesis gated since then.
    gated_since_seed: u32,
    /// Consecutive re-seeding searches started only because the track was
    /// unresolved (the interval doubles with each; see
    /// `reseed_max_interval_s`).
    reseed_streak: u32,
    phase: Phase,
    hopped: bool,
    /// Per antenna: time of its latest read and the interval before it,
    /// seconds (∞ before its second read): how correlated its next error is.
    antenna_clock: Vec<AntennaClock>,
    /// Per antenna: time (s) and carrier (Hz) the hypotheses' bias states
    /// were last propagated to ([`BiasClock::UNSET`]: the next read starts
    /// them).
    bias_clock: Vec<BiasClock>,
    /// Reads of the last `init_max_window_s` while tracking (re-seeding).
    recent: std::collections::VecDeque<PhaseRead>,
    /// Reads accepted but not yet taken through the tracker (the read
    /// budget ran out), oldest first.
    pending: std::collections::VecDeque<Pending>,
    /// The fast step under way, when a read's hypotheses span reads.
    progress: Option<Box<StepProgress>>,
    /// The initial search under way, if any (reads wait for it).
    job: Option<Box<Job>>,
    /// The re-seeding under way, if any (on the budget the reads leave).
    reseeding: Option<Box<Reseed>>,
    /// When recorded (a bank of noise levels, [`super::glac_bank`]): per
    /// read tracked, its time and log p(z_k | z_1:k−1), oldest first.
    evidence: Option<std::collections::VecDeque<(f64, f64)>>,
    stats: TrackerStats,
    /// The latest estimate (time s, position m, its 3×3 covariance m²):
    /// where re-acquisition starts from.
    last_good: Option<(f64, Vector3<f64>, Matrix3<f64>)>,
    /// Whether a report of this tag has ever been resolved (largest sigma
    /// or the hypotheses' plain-weight spread below [`RESEED_SIGMA_M`]):
    /// from then on the report holds its trajectory ([`Glac::reported`]).
    resolved_once: bool,
    // Not read by a converged tag's step.
    /// The estimate after the latest read taken through the tracker, while
    /// reads wait for a later call ([`Glac::step_read`]).
    result: Option<Estimate>,
    /// Three or more antennas on a line and one off it (3D): the free
    /// antenna's integer cannot be fixed on one channel (`line_twins`).
    line_layout: Option<LineLayout>,
    buffer: Vec<PhaseRead>,
    /// Scratch for naive branching.
    scratch: Hypotheses,
    /// Synchronous variant: reads collected towards one group.
    group: Vec<PhaseRead>,
    /// Antennas a synchronous group must cover (those that read during init).
    group_antennas: Vec<bool>,
}

/// One antenna's read times, seconds.
#[derive(Debug, Clone, Copy)]
struct AntennaClock {
    /// Its latest read (−∞ before any).
    read_s: f64,
    /// The interval before that read (∞ before its second read).
    interval_s: f64,
}

impl AntennaClock {
    const UNREAD: AntennaClock = AntennaClock { read_s: f64::NEG_INFINITY, interval_s: f64::INFINITY };
}

/// A read waiting for the tracker.
#[derive(Debug, Clone, Copy)]
struct Pending {
    read: PhaseRead,
    /// A buffered read replayed through fresh initial hypotheses (no
    /// per-read bookkeeping: it was done when the read was buffered);
    /// the time the estimate after it is reported at.
    replay: Option<f64>,
}

/// Why a fast step runs.
#[derive(Debug, Clone, Copy)]
enum Purpose {
    Track(Pending),
    /// A re-seeding replay through the fresh candidates alone.
    Reseed,
}

/// A fast step (see [`Glac::begin_fast`]) that may span several reads'
/// budgets: hypotheses `next..n` are still to be stepped.
struct StepProgress {
    read: PhaseRead,
    purpose: Purpose,
    step: FastStep,
    bias: BiasStep,
    n: usize,
    next: usize,
    /// Ambiguity branches: (index, candidate, bias prediction, predicted
    /// reading, its variance).
    branches: Vec<(usize, f64, BiasPrediction, f64, f64)>,
    /// The hypotheses those branches copied (the evidence splits their
    /// prior weight between the two).
    origins: Vec<usize>,
}

/// A search spread over reads.
enum Job {
    /// Initial state pruning over the buffer, started by the read at `now_s`.
    Initial { search: InitialSearch, last_s: f64, counts: Vec<usize>, now_s: f64 },
    /// Its result, waiting for a budget that covers building the hypotheses.
    /// A thousand hypotheses' filters are megabytes to write: built
    /// [`BUILD_BLOCK`] at a time into `built`.
    Commit { t_x: f64, initial: Vec<super::initial::InitialHypothesis>, built: Hypotheses, last_s: f64, counts: Vec<usize>, now_s: f64 },
}

/// Re-seeding, in the background: it runs on what the reads leave of
/// their budgets, while the live hypotheses keep tracking.
enum Reseed {
    /// The search over the recent reads.
    Search { search: InitialSearch, reads: Vec<PhaseRead> },
    /// The replay of the reads after t_x (and of those tracked since, up
    /// to `replayed_s`) through the candidates alone, with their own clock
    /// and bias clocks.
    Replay {
        fresh: Hypotheses,
        time_s: f64,
        bias_clock: Vec<BiasClock>,
        reads: std::collections::VecDeque<PhaseRead>,
        replayed_s: f64,
        progress: Option<StepProgress>,
    },
}

/// Work units (see [`Budget`]) of building one hypothesis from an initial
/// candidate (writing ~1 kB of fresh memory: measured near 0.5 µs).
const BUILD_UNITS: u64 = 2;
/// Hypotheses built per item.
const BUILD_BLOCK: usize = 64;
/// Hypotheses per unit of a step's end: normalisation, pruning and the
/// estimate (the mixture covariance combines every hypothesis' IMM state)
/// cost about half the filter step per hypothesis (measured).
const FINISH_PER_UNIT: u64 = 2;
/// Work units of checking one re-seeded candidate against the live
/// hypotheses (a grid lookup), and of filing one live hypothesis in the grid.
const JOIN_UNITS: u64 = 2;

/// The registry's constructor of `glac`: the paper's tracker with the
/// parameters as given (variants: [`super::variants`]).
pub fn build(scene: &Scene, params: &super::Params) -> Result<Box<dyn Tracker>> {
    let p = &params.glac;
    match p.bank_sigma_rad {
        Some(level) if p.inference == Inference::Fast && p.bias_state => {
            p.validate()?;
            let base = GlacParams { bank_sigma_rad: None, ..p.clone() };
            let other = GlacParams { bias_sigma_rad: level, bias_time_s: p.bank_time_s.unwrap_or(p.bias_time_s), ..base.clone() };
            Ok(Box::new(super::glac_bank::GlacBank::of(scene.clone(), vec![base, other], p.bank_switch_nats, p.bank_drop_nats)?))
        }
        _ => Ok(Box::new(Glac::new(scene.clone(), p.clone())?)),
    }
}

impl Glac {
    pub fn new(scene: Scene, params: GlacParams) -> Result<Self> {
        params.validate()?;
        let positions: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| a.position).collect();
        let line_layout = if scene.dimensions == 3 { line_layout(&positions) } else { None };
        Ok(Self::with_shared(Arc::new(scene), Arc::new(params), line_layout))
    }

    /// A tracker in its initial state over `scene` and `params` as they
    /// are (validated by the caller).
    fn with_shared(scene: Arc<Scene>, params: Arc<GlacParams>, line_layout: Option<LineLayout>) -> Self {
        let axes = scene.dimensions;
        let n_antennas = scene.antennas.len();
        let biases = n_antennas.min(MAX_BIASES);
        let reflected = scene.antennas.iter().map(|a| Arc::from(reflected_paths(&a.position, &scene.reflectors))).collect();
        Self {
            scene,
            params,
            reflected,
            axes,
            phase: Phase::Initialising,
            buffer: Vec::new(),
            hypotheses: Hypotheses::with_capacity(0, biases),
            scratch: Hypotheses::with_capacity(0, biases),
            time_s: f64::NEG_INFINITY,
            last_time_s: f64::NEG_INFINITY,
            group: Vec::new(),
            group_antennas: Vec::new(),
            antenna_clock: vec![AntennaClock::UNREAD; n_antennas],
            last_frequency_hz: f64::NAN,
            first_frequency_hz: f64::NAN,
            hopped: false,
            line_layout,
            bias_clock: vec![BiasClock::UNSET; n_antennas],
            last_good: None,
            resolved_once: false,
            recent: std::collections::VecDeque::new(),
            seeded_s: f64::NEG_INFINITY,
            switched_s: f64::NEG_INFINITY,
            gated_since_seed: 0,
            reseed_streak: 0,
            stats: TrackerStats::default(),
            arrival_s: f64::NEG_INFINITY,
            pending: std::collections::VecDeque::new(),
            progress: None,
            job: None,
            reseeding: None,
            result: None,
            evidence: None,
        }
    }

    pub fn params(&self) -> &GlacParams {
        &self.params
    }

    /// Starts recording each tracked read's log evidence
    /// ([`Glac::take_evidence`]).
    pub(crate) fn record_evidence(&mut self) {
        self.evidence.get_or_insert_with(Default::default);
    }

    /// The (read time s, log evidence) of the reads tracked since the
    /// last call, oldest first.
    pub(crate) fn take_evidence(&mut self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.evidence.iter_mut().flat_map(|log| log.drain(..))
    }

    /// Live hypotheses.
    pub fn hypothesis_count(&self) -> usize {
        self.hypotheses.len()
    }

    fn phase_noise(&self) -> f64 {
        self.params.phase_noise_rad.unwrap_or(self.scene.phase_noise_rad)
    }

    /// Range noise variance R (m²) of a read on a carrier whose antenna
    /// was last read `interval_s` before: σ_d = σ_φ λ / 4π (round trip:
    /// the phase turns 4π per wavelength of range), with
    /// σ_φ² = σ_white² + σ_wander² · f(ρ) (see [`correlated_variance_factor`]).
    #[inline]
    fn range_variance_after(&self, frequency_hz: f64, interval_s: f64) -> f64 {
        let white = self.phase_noise();
        let wander = self.params.phase_wander_rad;
        let mut phase_variance = white * white;
        if wander > 0.0 {
            // Only then: the exp is a tenth of a converged step.
            let rho = (-interval_s / self.params.phase_wander_s).exp();
            phase_variance += wander * wander * correlated_variance_factor(rho);
        }
        let to_range = Scene::range_per_radian(frequency_hz);
        phase_variance * to_range * to_range
    }

    /// R (m²) at the antennas' typical read interval (the mean of those
    /// known; white alone before any antenna was read twice): for
    /// initialisation and the variants that fuse several antennas at once.
    fn range_variance(&self, frequency_hz: f64) -> f64 {
        let (sum, count) =
            self.antenna_clock.iter().map(|c| c.interval_s).filter(|t| t.is_finite()).fold((0.0, 0usize), |(s, n), t| (s + t, n + 1));
        let typical = if count == 0 { f64::INFINITY } else { sum / count as f64 };
        self.range_variance_after(frequency_hz, typical)
    }

    fn restart(&mut self) {
        self.phase = Phase::Initialising;
        self.reseed_streak = 0;
        self.reseeding = None;
        self.hypotheses.clear();
        self.group.clear();
        self.stats.reinitialisations += 1;
    }

    /// Initial state pruning over the buffer, once it allows one: starts
    /// the search as a job ([`Glac::advance_job`]; on success the
    /// hypotheses start at t_x and the buffered reads after t_x are
    /// replayed through them, all at or before the current read: still
    /// causal). False when the search cannot start.
    fn try_initialise(&mut self, now_s: f64) -> bool {
        let (first, last) = match (self.buffer.first(), self.buffer.last()) {
            (Some(f), Some(l)) => (f.time_s, l.time_s),
            _ => return false,
        };
        let span = last - first;
        if span < self.params.init_window_s {
            return false;
        }
        // Wait (up to init_max_window_s) until every antenna heard so far has
        // two reads: more antennas make far fewer surviving candidates.
        let mut counts = vec![0usize; self.scene.antennas.len()];
        for m in &self.buffer {
            counts[m.antenna] += 1;
        }
        let all_twice = counts.iter().all(|&c| c == 0 || c >= 2);
        if !all_twice && span < self.params.init_max_window_s {
            return false;
        }
        let range_sigma = self.initial_range_sigma(self.buffer[0].frequency_hz);
        let with_velocity = self.params.motion.has_velocity();
        match InitialSearch::new(&self.scene, &self.buffer, &self.params.initial, range_sigma, with_velocity) {
            Some(search) => {
                self.job = Some(Box::new(Job::Initial { search, last_s: last, counts, now_s }));
                true
            }
            None => {
                self.slide_window(last);
                false
            }
        }
    }

    /// After a failed search: keep only the newest init_max_window_s.
    fn slide_window(&mut self, last_s: f64) {
        let keep_from = last_s - self.params.init_max_window_s;
        self.buffer.retain(|m| m.time_s >= keep_from);
    }

    /// The initial search's hypotheses go live: the buffered reads after
    /// t_x are queued (first) to be replayed through them.
    fn commit(&mut self, t_x: f64, hypotheses: Hypotheses, last_s: f64, counts: Vec<usize>, now_s: f64, out: &mut Option<Estimate>) {
        self.hypotheses = hypotheses;
        self.stats.max_hypotheses = self.stats.max_hypotheses.max(self.hypotheses.len() as u64);
        self.time_s = t_x;
        self.bias_clock.fill(BiasClock::UNSET);
        self.seeded_s = last_s;
        self.switched_s = last_s;
        self.gated_since_seed = 0;
        self.recent.clear();
        self.recent.extend(self.buffer.iter().copied());
        self.group_antennas = counts.iter().map(|&c| c >= 2).collect();
        self.group.clear();
        self.phase = Phase::Tracking;
        let replay: Vec<PhaseRead> = self.buffer.iter().copied().filter(|m| m.time_s > t_x).collect();
        self.buffer.clear();
        for m in replay.into_iter().rev() {
            self.pending.push_front(Pending { read: m, replay: Some(now_s) });
        }
        if !self.pending.front().is_some_and(|p| p.replay.is_some()) {
            *out = self.remember(self.best_estimate(now_s));
        }
    }

    /// Runs `job` on within `budget`: `Some` (the job) while work is left.
    fn advance_job(&mut self, job: Job, budget: &mut Budget, out: &mut Option<Estimate>) -> Option<Job> {
        match job {
            Job::Initial { mut search, last_s, counts, now_s } => match search.advance(&self.scene, budget) {
                None => Some(Job::Initial { search, last_s, counts, now_s }),
                Some(None) => {
                    self.slide_window(last_s);
                    *out = self.coasting_estimate(now_s);
                    None
                }
                Some(Some((t_x, initial))) => {
                    let initial = self.reachable(initial, t_x);
                    let built = Hypotheses::with_capacity(initial.len(), self.biases());
                    self.advance_job(Job::Commit { t_x, initial, built, last_s, counts, now_s }, budget, out)
                }
            },
            Job::Commit { t_x, initial, mut built, last_s, counts, now_s } => {
                while built.len() < initial.len() {
                    let block = BUILD_BLOCK.min(initial.len() - built.len());
                    if !budget.try_spend_overhead(block as u64 * BUILD_UNITS) {
                        return Some(Job::Commit { t_x, initial, built, last_s, counts, now_s });
                    }
                    let from = built.len();
                    self.build_hypotheses(&mut built, &initial[from..from + block]);
                }
                if !budget.try_spend_overhead(1 + initial.len() as u64 / FINISH_PER_UNIT) {
                    return Some(Job::Commit { t_x, initial, built, last_s, counts, now_s });
                }
                built.normalise();
                self.commit(t_x, built, last_s, counts, now_s, out);
                None
            }
        }
    }

    /// Range sigma (m) of the initial search on carrier `frequency_hz`: the
    /// reads' noise at the typical interval, and the bias, which is part
    /// of each initial range's error too.
    fn initial_range_sigma(&self, frequency_hz: f64) -> f64 {
        let bias = self.params.bias_sigma_rad * Scene::range_per_radian(frequency_hz);
        (self.range_variance(frequency_hz) + bias * bias).sqrt()
    }

    /// Antennas with a bias state in every hypothesis (the first ones, at
    /// most [`MAX_BIASES`]; set from the scene in [`Glac::new`]).
    fn biases(&self) -> usize {
        self.hypotheses.biases
    }

    /// Hypotheses (normalised) started from initial candidates, with the
    /// initial covariance; in 2D pinned to the tag's plane.
    fn hypotheses_from(&self, initial: &[super::initial::InitialHypothesis]) -> Hypotheses {
        let mut hypotheses = Hypotheses::with_capacity(initial.len(), self.biases());
        self.build_hypotheses(&mut hypotheses, initial);
        hypotheses.normalise();
        hypotheses
    }

    /// Appends hypotheses started from `initial` (unnormalised; see
    /// [`Glac::hypotheses_from`]).
    fn build_hypotheses(&self, hypotheses: &mut Hypotheses, initial: &[super::initial::InitialHypothesis]) {
        let v_sigma = if self.params.motion.has_velocity() { self.params.init_velocity_sigma_m_s } else { 0.0 };
        let p0 = initial_covariance(self.axes, self.params.init_position_sigma_m, v_sigma);
        for h in initial {
            let mut x = h.state;
            if self.axes == 2 {
                x[2] = self.scene.plane_z;
                x[5] = 0.0;
            }
            hypotheses.push(x, p0, h.log_likelihood);
        }
    }

    /// Re-acquisition: of the initial candidates, those the tag can have
    /// reached from the last good state (within `max_speed_m_s` · Δt + 3σ
    /// of it, σ its largest position sigma). All of them when there is no
    /// last state, or when none is reachable (the bound was wrong: the tag
    /// was moved faster; searching everywhere beats losing it).
    fn reachable(&self, initial: Vec<super::initial::InitialHypothesis>, t_x: f64) -> Vec<super::initial::InitialHypothesis> {
        let Some((t, position, covariance)) = self.last_good else { return initial };
        let radius = self.params.max_speed_m_s * (t_x - t).max(0.0) + 3.0 * largest_sigma(&covariance);
        let near: Vec<_> = initial
            .iter()
            .filter(|h| (Vector3::new(h.state[0], h.state[1], h.state[2]) - position).norm() <= radius)
            .cloned()
            .collect();
        if near.is_empty() {
            initial
        } else {
            near
        }
    }

    /// Runs the re-seeding search `job` on within `budget` (what the reads
    /// left of it): `Some` (the job) while work is left. Its candidates
    /// are replayed, with their own clocks, through the recent reads up to
    /// the latest one tracked, then join the live hypotheses.
    fn advance_reseed(&mut self, job: Reseed, budget: &mut Budget) -> Option<Reseed> {
        match job {
            Reseed::Search { mut search, reads } => match search.advance(&self.scene, budget) {
                None => Some(Reseed::Search { search, reads }),
                Some(None) => None,
                Some(Some((t_x, initial))) => {
                    budget.spend_overhead(initial.len() as u64 * BUILD_UNITS);
                    let fresh = self.hypotheses_from(&initial);
                    let replayed_s = reads.last().map_or(t_x, |m| m.time_s);
                    let reads = reads.into_iter().filter(|m| m.time_s > t_x).collect();
                    let bias_clock = vec![BiasClock::UNSET; self.bias_clock.len()];
                    self.advance_reseed(Reseed::Replay { fresh, time_s: t_x, bias_clock, reads, replayed_s, progress: None }, budget)
                }
            },
            Reseed::Replay { mut fresh, mut time_s, mut bias_clock, mut reads, mut replayed_s, mut progress } => {
                // The candidates and their clocks stand in for the live ones
                // while they are stepped.
                std::mem::swap(&mut self.hypotheses, &mut fresh);
                std::mem::swap(&mut self.time_s, &mut time_s);
                std::mem::swap(&mut self.bias_clock, &mut bias_clock);
                let done = loop {
                    if let Some(p) = progress.take() {
                        // A replay reports nothing.
                        progress = self.advance_step(p, budget, &mut None);
                        if progress.is_some() {
                            break false;
                        }
                    }
                    if reads.is_empty() {
                        // Reads tracked since: the candidates follow them too.
                        reads.extend(self.recent.iter().copied().filter(|m| m.time_s > replayed_s));
                        replayed_s = reads.back().map_or(replayed_s, |m| m.time_s);
                    }
                    if self.hypotheses.len() == 0 || reads.is_empty() {
                        break true;
                    }
                    if !budget.try_spend_overhead(1) {
                        break false;
                    }
                    let m = reads.pop_front().expect("not empty");
                    progress = Some(self.begin_fast(&m, Purpose::Reseed));
                };
                std::mem::swap(&mut self.hypotheses, &mut fresh);
                std::mem::swap(&mut self.time_s, &mut time_s);
                std::mem::swap(&mut self.bias_clock, &mut bias_clock);
                let join = JOIN_UNITS * (fresh.len() + self.hypotheses.len()) as u64;
                if !done || !budget.try_spend_overhead(1 + join + self.hypotheses.len() as u64 / FINISH_PER_UNIT) {
                    return Some(Reseed::Replay { fresh, time_s, bias_clock, reads, replayed_s, progress });
                }
                self.join_reseeded(&fresh);
                None
            }
        }
    }

    /// Re-seeding (see `reseed_interval_s`): the initial search over the
    /// recent reads; its candidates are brought to the current time by
    /// replaying those reads through them alone, and the ones no live
    /// hypothesis follows (none within `RESEED_DISTANCE_M`) join with a
    /// total weight of [`RESEED_WEIGHT`], split by their own likelihoods.
    /// The live hypotheses are untouched. Causal: only reads up to now.
    #[cfg(test)]
    fn reseed(&mut self, now_s: f64) {
        self.start_reseed(now_s);
        while let Some(job) = self.reseeding.take() {
            self.reseeding = self.advance_reseed(*job, &mut Budget::unlimited()).map(Box::new);
        }
    }

    /// Seconds until the next re-seeding search may start: doubling with
    /// each search an unresolved track started on its own, capped at
    /// `reseed_max_interval_s`.
    fn reseed_interval(&self) -> f64 {
        let doubled = self.params.reseed_interval_s * 2f64.powi(self.reseed_streak.min(30) as i32);
        // A cap below the base interval leaves the base interval.
        doubled.min(self.params.reseed_max_interval_s.max(self.params.reseed_interval_s))
    }

    /// Starts re-seeding in the background ([`Glac::advance_reseed`]).
    fn start_reseed(&mut self, now_s: f64) {
        self.seeded_s = now_s;
        self.gated_since_seed = 0;
        self.stats.reseeds += 1;
        let reads: Vec<PhaseRead> = self.recent.iter().copied().collect();
        let started = reads.first().and_then(|first| {
            let range_sigma = self.initial_range_sigma(first.frequency_hz);
            let with_velocity = self.params.motion.has_velocity();
            // The likeliest few only: the search runs while tracking, and its
            // replay costs a filter update per candidate and read.
            let settings = InitialState { max_hypotheses: self.params.initial.max_hypotheses.min(RESEED_MAX_CANDIDATES), ..self.params.initial.clone() };
            InitialSearch::new(&self.scene, &reads, &settings, range_sigma, with_velocity)
        });
        self.reseeding = started.map(|search| Box::new(Reseed::Search { search, reads }));
    }

    /// The re-seeded candidates (brought to the current time) that no live
    /// hypothesis follows join the live ones.
    fn join_reseeded(&mut self, fresh: &Hypotheses) {
        // Live positions by RESEED_DISTANCE_M cell: a candidate is followed
        // when a live hypothesis lies within that distance, so only the 27
        // cells around it can hold one.
        let cell = |x: &StateVector| [0, 1, 2].map(|k| (x[k] / RESEED_DISTANCE_M).floor() as i64);
        let mut grid: super::key_hash::CellMap<Vec<usize>> = Default::default();
        for j in 0..self.hypotheses.len() {
            grid.entry(cell(&self.hypotheses.items[j].x[0])).or_default().push(j);
        }
        let live = &self.hypotheses;
        let followed = |x: &StateVector| {
            let c = cell(x);
            (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dz| {
                        grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).is_some_and(|ids| {
                            ids.iter().any(|&j| (live.items[j].x[0] - x).fixed_rows::<3>(0).norm() < RESEED_DISTANCE_M)
                        })
                    })
                })
            })
        };
        let joining: Vec<usize> = (0..fresh.len()).filter(|&i| !followed(&fresh.items[i].x[0])).collect();
        if joining.is_empty() {
            return;
        }
        let log_share = RESEED_WEIGHT.ln();
        for &i in &joining {
            self.hypotheses.append_from(fresh, i, log_share + fresh.items[i].log_likelihood);
        }
        self.prune();
    }

    /// One reading through every hypothesis (fast or naive inference), or
    /// into the current group (synchronous).
    fn track(&mut self, m: &PhaseRead) {
        match self.params.inference {
            Inference::Fast => {
                let mut progress = self.begin_fast(m, Purpose::Reseed);
                self.run_fast(&mut progress, &mut Budget::unlimited());
                self.finish_fast(&progress);
            }
            Inference::Naive => self.step_naive(m),
            Inference::Synchronous => self.step_synchronous(m),
        }
    }

    /// Fast inference: nearest-neighbour pruning (eq. 9), EKF update
    /// (eqs. 5–8), 3σ recovery, likelihood propagation (eqs. 11–13),
    /// normalisation, quick stop, region constraint.
    ///
    /// Ambiguity branching: nearest-neighbour pruning is safe only while
    /// the predicted range is known to well under half a candidate step.
    /// When 3√S exceeds s/2 (after a read gap or a hard manoeuvre, and
    /// twice as often on mod-π readers) the hypothesis also branches onto
    /// the second-nearest candidate, so a cycle slip leaves the true
    /// trajectory alive; the wrong branch dies by quick stop within a few
    /// readings. Bounded by `max_branching_hypotheses`.
    ///
    /// Spread over reads ([`StepProgress`]): `begin_fast` sets the step up,
    /// `run_fast` steps hypotheses while the budget lasts, `finish_fast`
    /// takes the branches and prunes. A chunked step never branches: it
    /// spans reads only when far more hypotheses than
    /// `max_branching_hypotheses` are live.
    fn begin_fast(&mut self, m: &PhaseRead, purpose: Purpose) -> StepProgress {
        let dt = (m.time_s - self.time_s).max(0.0);
        let step = FastStep {
            transition: self.params.motion.transition(dt, self.axes),
            manoeuvre: self.params.manoeuvre_q.map(|q| MotionModel::ConstantVelocity { q }.transition(dt, self.axes)),
            switch: self.params.model_switch_probability,
            antenna: self.scene.antennas[m.antenna].position,
            residue: self.scene.distance_residue(m.antenna, m.frequency_hz, m.phase_rad),
            spacing: self.scene.candidate_spacing(m.frequency_hz),
            r: self.range_variance_after(m.frequency_hz, self.antenna_clock[m.antenna].interval_s),
            gate2: self.params.gate_sigmas * self.params.gate_sigmas,
            likelihood: self.params.likelihood,
            axes: self.axes,
            multipath: self.multipath(m),
        };
        let bias = self.bias_step(m);
        StepProgress { read: *m, purpose, step, bias, n: self.hypotheses.len(), next: 0, branches: Vec::new(), origins: Vec::new() }
    }

    /// Steps hypotheses `next..n` while `budget` lasts (one unit each);
    /// true when all are done.
    fn run_fast(&mut self, s: &mut StepProgress, budget: &mut Budget) -> bool {
        let h = &mut self.hypotheses;
        let (n, step, bias) = (s.n, &s.step, &s.bias);
        let branch_limit = self.params.max_branching_hypotheses;
        while s.next < n {
            if !budget.try_spend(1) {
                return false;
            }
            let i = s.next;
            s.next += 1;
            let (range, variance, covariance, line) = step.predict(h, i);
            let b = predict_bias(bias, h, i);
            // The reading predicts range + bias, with both uncertainties.
            let (predicted, variance) = (range + b.mean, variance + b.variance);
            let z = nearest_candidate(step.residue, step.spacing, predicted);
            if n + s.branches.len() < branch_limit && 9.0 * variance > 0.25 * step.spacing * step.spacing {
                let second = if predicted > z { z + step.spacing } else { z - step.spacing };
                if second >= 0.0 {
                    // A branch is an exact copy of the predicted hypothesis: it
                    // keeps that prediction (bias, predicted reading, its variance).
                    h.duplicate(i);
                    let j = h.len() - 1;
                    // Hypothesis i's stored covariances are written by its
                    // update below; the copy takes the predicted ones now.
                    h.items[j].p = pack_pair(&covariance);
                    s.branches.push((j, second, b, predicted, variance));
                    s.origins.push(i);
                }
            }
            step.update_predicted(h, i, covariance, z - b.mean, b.variance, line);
            update_bias(bias, h, i, &b, z - predicted, variance);
        }
        true
    }

    /// The branches' updates, the counters, the clock and pruning.
    fn finish_fast(&mut self, s: &StepProgress) {
        let h = &mut self.hypotheses;
        for &(j, z, b, predicted, variance) in &s.branches {
            s.step.update_predicted(h, j, unpack_pair(&h.items[j].p), z - b.mean, b.variance, None);
            update_bias(&s.bias, h, j, &b, z - predicted, variance);
        }
        let models = if s.step.manoeuvre.is_some() { 2 } else { 1 };
        self.stats.filter_updates += (h.len() * models) as u64;
        if let (Some(log), Purpose::Track(_)) = (self.evidence.as_mut(), s.purpose) {
            if h.len() > 0 {
                log.push_back((s.read.time_s, read_evidence(h, s)));
            }
        }
        self.time_s = s.read.time_s;
        self.prune();
    }

    /// Advances a spread fast step: `Some` while hypotheses are left; at
    /// its end (when the budget covers it) the step finishes and a tracked
    /// read gets its per-read handling.
    fn advance_step(&mut self, mut s: StepProgress, budget: &mut Budget, out: &mut Option<Estimate>) -> Option<StepProgress> {
        if !self.run_fast(&mut s, budget) {
            return Some(s);
        }
        let finish = 1 + s.branches.len() as u64 + self.hypotheses.len() as u64 / FINISH_PER_UNIT;
        if !budget.try_spend_overhead(finish) {
            return Some(s);
        }
        self.finish_fast(&s);
        if let Purpose::Track(p) = s.purpose {
            self.after_track(p, out);
        }
        None
    }

    /// The reading's reflected paths, when the scene has reflectors.
    fn multipath(&self, m: &PhaseRead) -> Option<Multipath> {
        let paths = &self.reflected[m.antenna];
        (!paths.is_empty()).then(|| Multipath { wavenumber: 2.0 * std::f64::consts::PI * m.frequency_hz / SPEED_OF_LIGHT, paths: Arc::clone(paths) })
    }

    /// Naive inference: every hypothesis branches into one child per
    /// candidate distance the region allows (no nearest-neighbour pruning,
    /// no quick stop). Growth is O(nᵏ); the cap keeps the best
    /// `max_hypotheses` so that memory stays bounded.
    fn step_naive(&mut self, m: &PhaseRead) {
        let dt = (m.time_s - self.time_s).max(0.0);
        let transition = self.params.motion.transition(dt, self.axes);
        let antenna = self.scene.antennas[m.antenna].position;
        let residue = self.scene.distance_residue(m.antenna, m.frequency_hz, m.phase_rad);
        let spacing = self.scene.candidate_spacing(m.frequency_hz);
        let (lo, hi) = self.scene.distance_bounds(m.antenna);
        let r = self.range_variance_after(m.frequency_hz, self.antenna_clock[m.antenna].interval_s);
        let multipath = self.multipath(m);
        let n_lo = ((lo - residue) / spacing).floor().max(0.0) as i64;
        let n_hi = ((hi - residue) / spacing).ceil() as i64;
        self.scratch.clear();
        let h = &mut self.hypotheses;
        for i in 0..h.len() {
            let (mut x, mut p) = (h.items[i].x[0], h.items[i].p[0].unpack());
            predict(&mut x, &mut p, &transition);
            let (d, jac) = measured_range(&x, &antenna, multipath.as_ref(), self.axes, true);
            let jac = jac.unwrap();
            for n in n_lo..=n_hi {
                let z = residue + n as f64 * spacing;
                let (u, b) = innovation(&p, z, d, &jac, r);
                let (mut xc, mut pc) = (x, p);
                apply_scalar(&mut xc, &mut pc, &u, &b);
                self.scratch.push(xc, pc, h.items[i].log_likelihood + log_gaussian(u.innovation, u.variance));
            }
        }
        self.stats.filter_updates += self.scratch.len() as u64;
        std::mem::swap(&mut self.hypotheses, &mut self.scratch);
        let cap = self.params.max_hypotheses;
        if self.hypotheses.len() > cap {
            let mut order: Vec<f64> = self.hypotheses.log_likelihoods().collect();
            let k = order.len() - cap;
            order.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
            let threshold = order[k];
            let mut kept = 0usize;
            let ll: Vec<f64> = self.hypotheses.log_likelihoods().collect();
            // Keep at most `cap` at or above the threshold (ties broken by order).
            let keep: Vec<bool> = ll
                .iter()
                .map(|&l| {
                    let k = l >= threshold && kept < cap;
                    if k {
                        kept += 1;
                    }
                    k
                })
                .collect();
            self.hypotheses.retain(|i| keep[i]);
        }
        self.time_s = m.time_s;
        self.hypotheses.normalise();
        self.stats.max_hypotheses = self.stats.max_hypotheses.max(self.hypotheses.len() as u64);
    }

    /// Synchronous handling (sec. 5.2.2, scheme 3): reads are grouped until
    /// every antenna has been read once; the group is then treated as four
    /// simultaneous readings at the last read's time. Each hypothesis picks
    /// per antenna the candidate nearest its predicted range, trilaterates
    /// them into a position z with covariance σ_d² (JᵀJ)⁻¹, and updates with
    /// H = [I 0]; the likelihood is Πᵢ p(zᵢ* | θ). Under known reflectors
    /// the candidates are apparent ranges, each less the excess predicted
    /// at the hypothesis's predicted position.
    fn step_synchronous(&mut self, m: &PhaseRead) {
        if let Some(prev) = self.group.iter().position(|g| g.antenna == m.antenna) {
            // A second read of one antenna before the group is complete:
            // the newest read of that antenna replaces the older one.
            self.group.remove(prev);
        }
        self.group.push(*m);
        let complete = self
            .group_antennas
            .iter()
            .enumerate()
            .all(|(a, &needed)| !needed || self.group.iter().any(|g| g.antenna == a));
        if !complete {
            return;
        }
        let group = std::mem::take(&mut self.group);
        let dt = (m.time_s - self.time_s).max(0.0);
        // One model only here (no IMM): one fused position per ~4 reads
        // must follow the turns, so a constant-velocity model takes the
        // manoeuvre model's process noise when one is configured.
        let motion = match (self.params.motion, self.params.manoeuvre_q) {
            (MotionModel::ConstantVelocity { .. }, Some(q)) => MotionModel::ConstantVelocity { q },
            (motion, _) => motion,
        };
        let transition = motion.transition(dt, self.axes);
        let anchors: Vec<Vector3<f64>> = group.iter().map(|g| self.scene.antennas[g.antenna].position).collect();
        let residues: Vec<(f64, f64)> = group
            .iter()
            .map(|g| (self.scene.distance_residue(g.antenna, g.frequency_hz, g.phase_rad), self.scene.candidate_spacing(g.frequency_hz)))
            .collect();
        // Each read's known reflectors (once per group, not per hypothesis).
        let multipaths: Vec<Option<Multipath>> = group.iter().map(|g| self.multipath(g)).collect();
        let r = self.range_variance(m.frequency_hz);
        let gate2 = self.params.gate_sigmas * self.params.gate_sigmas * self.axes as f64;
        let mut distances = vec![0.0; group.len()];
        let h = &mut self.hypotheses;
        for hyp in &mut h.items {
            let mut covariance = hyp.p[0].unpack();
            let mut state = hyp.x[0];
            let (x, p) = (&mut state, &mut covariance);
            predict(x, p, &transition);
            let predicted = Vector3::new(x[0], x[1], x[2]);
            for (k, a) in anchors.iter().enumerate() {
                // Under known reflectors the phase measures the apparent
                // range: the candidate nearest the predicted apparent range,
                // less the excess there, is the direct range trilaterated.
                let direct = (predicted - a).norm();
                let excess = multipaths[k].as_ref().map_or(0.0, |mp| measured_range(x, a, Some(mp), self.axes, false).0 - direct);
                distances[k] = nearest_candidate(residues[k].0, residues[k].1, direct + excess) - excess;
            }
            let fix = multilaterate(&anchors, &distances, predicted, self.axes, 5);
            let mut log_l = -0.5 * (gate2 + group.len() as f64 * (2.0 * std::f64::consts::PI * r).ln());
            if let Some(fix) = fix.and_then(|f| f.normal.try_inverse().map(|inv| (f, inv))) {
                let (fix, normal_inv) = fix;
                let mut r_pos: Matrix3<f64> = normal_inv * r;
                if self.axes == 2 {
                    r_pos[(2, 2)] = r; // z is pinned by P = 0; any R works
                }
                let (mut xc, mut pc) = (*x, *p);
                if let Some((nu, s)) = update_position(&mut xc, &mut pc, &fix.position, &r_pos) {
                    let d2 = s.try_inverse().map_or(f64::INFINITY, |si| (nu.transpose() * si * nu)[(0, 0)]);
                    if d2 <= gate2 {
                        *x = xc;
                        *p = pc;
                        hyp.outliers = 0;
                        let post = Vector3::new(x[0], x[1], x[2]);
                        log_l = anchors
                            .iter()
                            .zip(&distances)
                            .map(|(a, &z)| log_gaussian((post - a).norm() - z, r))
                            .sum();
                    } else {
                        hyp.outliers += 1;
                    }
                } else {
                    hyp.outliers += 1;
                }
            } else {
                hyp.outliers += 1;
            }
            hyp.x[0] = state;
            hyp.p[0] = PackedCovariance::pack(&covariance);
            hyp.log_likelihood += log_l;
        }
        self.stats.filter_updates += h.len() as u64;
        self.time_s = m.time_s;
        self.prune();
    }

    /// Normalise (eqs. 11–13 are defined up to a constant), then quick stop,
    /// the region constraint, loss of lock and merging of hypotheses that
    /// converged onto one trajectory.
    fn prune(&mut self) {
        let h = &mut self.hypotheses;
        if h.len() == 0 {
            return;
        }
        h.normalise();
        let log_threshold = if self.params.quick_stop > 0.0 { self.params.quick_stop.ln() } else { f64::NEG_INFINITY };
        let margin = self.params.region_margin_m;
        let max_out = self.params.max_consecutive_outliers;
        let (region, axes) = (self.scene.region.clone(), self.axes);
        // On the stack while few (a converged tag's every read allocated here).
        let (mut few, mut many) = ([false; 16], Vec::new());
        let alive: &mut [bool] = if h.len() <= few.len() {
            &mut few[..h.len()]
        } else {
            many.resize(h.len(), false);
            &mut many
        };
        for (i, keep) in alive.iter_mut().enumerate() {
            let x = &h.items[i].x[0];
            let inside = region.as_ref().is_none_or(|r| r.contains(&Vector3::new(x[0], x[1], x[2]), margin, axes));
            *keep = h.items[i].log_likelihood >= log_threshold && inside && h.items[i].outliers < max_out && x.iter().all(|v| v.is_finite());
        }
        h.retain(|i| alive[i]);
        if h.len() > 1 && h.len() <= 64 && self.params.merge_distance_m > 0.0 {
            // Nearest-neighbour pruning makes neighbouring hypotheses pick
            // the same candidates and collapse onto one trajectory; keep
            // the likelier of any pair that coincides. Only when few are
            // left, so the O(n²) check stays cheap.
            let md2 = self.params.merge_distance_m * self.params.merge_distance_m;
            let n = h.len();
            let mut keep = vec![true; n];
            for i in 0..n {
                if !keep[i] {
                    continue;
                }
                for j in i + 1..n {
                    if keep[j] {
                        let dp = (h.items[i].x[0] - h.items[j].x[0]).fixed_rows::<3>(0).norm_squared();
                        if dp < md2 {
                            if h.items[i].log_likelihood >= h.items[j].log_likelihood {
                                keep[j] = false;
                            } else {
                                keep[i] = false;
                                break;
                            }
                        }
                    }
                }
            }
            h.retain(|i| keep[i]);
        }
        if h.len() > 0 {
            h.normalise();
        }
        self.stats.max_hypotheses = self.stats.max_hypotheses.max(h.len() as u64);
    }

    /// The likeliest hypothesis' state, with the covariance of everything
    /// the tracker still considers possible: the second moment of the
    /// hypothesis mixture about the reported state,
    /// `Σ = Σᵢ wᵢ (Pᵢ + (xᵢ − x̂)(xᵢ − x̂)ᵀ)` with wᵢ the normalised
    /// likelihoods ([`mixture_covariance`]). While candidates compete this
    /// is as wide as their spread; once one carries all the weight it is
    /// that hypothesis' own P.
    fn best_estimate(&self, time_s: f64) -> Option<Estimate> {
        let h = &self.hypotheses;
        let reported = self.reported()?;
        let (x, own) = h.state(reported);
        let mut p = if h.len() == 1 { own } else { mixture_covariance(h, &x, self.params.weight_temperature) };
        self.add_bias_covariance(&mut p, &x);
        self.add_twin_covariance(&mut p, &x);
        let velocity =
            if self.params.motion.has_velocity() { [x[3], x[4], x[5]] } else { [f64::NAN, f64::NAN, f64::NAN] };
        Some(Estimate {
            time_s,
            position: [x[0], x[1], x[2]],
            velocity,
            covariance: Estimate::covariance_from(&p),
            hypotheses: h.len(),
            weight: h.items[reported].log_likelihood.exp(),
        })
    }

    /// Adds the position covariance an unmodelled per-antenna range bias
    /// of 1-sigma σ_b λ/4π causes at `x` (see `bias_sigma_rad`): for
    /// position p from ranges d = h(p) + b by least squares,
    /// δp = (Jᵀ J)⁻¹ Jᵀ b, so Cov δp = σ² (Jᵀ J)⁻¹. Over the antennas that
    /// have read the tag; skipped when they cannot fix the position
    /// (singular JᵀJ), where the geometry check speaks instead.
    fn add_bias_covariance(&self, p: &mut StateMatrix, x: &StateVector) {
        let sigma_b = self.params.bias_sigma_rad;
        // With bias states the filter's own P carries the bias.
        let modelled = self.params.bias_state && self.params.inference == Inference::Fast;
        if sigma_b == 0.0 || modelled || !self.last_frequency_hz.is_finite() {
            return;
        }
        let position = Vector3::new(x[0], x[1], x[2]);
        let mut normal = Matrix3::zeros();
        for (a, antenna) in self.scene.antennas.iter().enumerate() {
            if !self.antenna_clock[a].read_s.is_finite() {
                continue;
            }
            let mut e = position - antenna.position;
            if self.axes == 2 {
                e.z = 0.0;
            }
            let norm = e.norm();
            if norm > 1e-9 {
                e /= norm;
                normal += e * e.transpose();
            }
        }
        if self.axes == 2 {
            normal[(2, 2)] = 1.0; // z is pinned; any value keeps it invertible
        }
        let Some(inverse) = normal.try_inverse() else { return };
        if !inverse.iter().all(|v| v.is_finite()) {
            return;
        }
        let to_range = Scene::range_per_radian(self.last_frequency_hz);
        let variance = sigma_b * sigma_b * to_range * to_range;
        let axes = self.axes;
        for r in 0..axes {
            for c in 0..axes {
                p[(r, c)] += variance * inverse[(r, c)];
            }
        }
    }

    /// The bias states' step for reading `m`, and the antenna's bias clock
    /// moved to its time.
    fn bias_step(&mut self, m: &PhaseRead) -> BiasStep {
        if !self.params.bias_state || m.antenna >= self.biases() || self.params.bias_sigma_rad == 0.0 {
            return BiasStep::NONE;
        }
        let clock = self.bias_clock[m.antenna];
        self.bias_clock[m.antenna] = BiasClock { time_s: m.time_s, frequency_hz: m.frequency_hz };
        let to_range = Scene::range_per_radian(m.frequency_hz);
        let stationary = (self.params.bias_sigma_rad * to_range).powi(2);
        let step = BiasStep::new(m.antenna, m.time_s - clock.time_s, stationary, self.params.bias_time_s);
        // A new carrier brings its own calibration residual and multipath
        // phase: that share of the bias is drawn afresh.
        if clock.time_s.is_finite() && clock.frequency_hz != m.frequency_hz {
            step.with_jump((self.params.hop_bias_sigma_rad * to_range).powi(2))
        } else {
            step
        }
    }

    /// Three antennas on a line (one off it, one channel): the twins of the
    /// reported position (the free antenna's range shifted by 1–3
    /// candidate spacings, inside the region) fit every phase as well as it
    /// does, so they count as equally likely: `Σ_t d_t d_tᵀ / (K + 1)` is
    /// added to the position covariance, d_t the offset of twin t (the
    /// second moment of the K + 1 equally weighted points about the
    /// reported one). Hopping over calibrated channels breaks the twins,
    /// and then nothing is added.
    fn add_twin_covariance(&self, p: &mut StateMatrix, x: &StateVector) {
        let Some(layout) = &self.line_layout else { return };
        if !self.last_frequency_hz.is_finite() || (self.hopped && !self.scene.channel_offsets.is_empty()) {
            return;
        }
        let position = Vector3::new(x[0], x[1], x[2]);
        let spacing = self.scene.candidate_spacing(self.last_frequency_hz);
        let margin = self.params.region_margin_m;
        let region = self.scene.region.as_ref();
        let twins = line_twins(layout, &position, spacing, MAX_TWIN_SHIFT, |q| region.is_none_or(|r| r.contains(q, margin, 3)));
        if twins.is_empty() {
            return;
        }
        let weight = 1.0 / (twins.len() + 1) as f64;
        let mut block = p.fixed_view_mut::<3, 3>(0, 0);
        for q in &twins {
            let d = q - position;
            block += (d * weight) * d.transpose();
        }
    }

    /// The hypothesis reported: the likeliest until a report of this tag
    /// has been resolved once; from then on, of those within
    /// [`REPORT_HOLD_NATS`] of the likeliest, the one nearest the last
    /// report. Candidates are at least λ/4 apart and a read moves a tag by
    /// millimetres, so that is the trajectory reported before while it
    /// stays a contender, and after a gap the candidate nearest where the
    /// tag was last seen (re-acquisition from the last good state). Not
    /// before the first resolved report: at acquisition the first leader is
    /// a guess, and holding it delayed the right candidate's win (dev
    /// seeds: docs/notes/glac-experiments.md). The covariance is taken
    /// about it ([`mixture_covariance`]), so the competitors' spread still
    /// shows in the sigma.
    fn reported(&self) -> Option<usize> {
        let h = &self.hypotheses;
        let best = h.best()?;
        let Some((_, previous, _)) = self.last_good else { return Some(best) };
        if h.len() == 1 || !self.resolved_once {
            return Some(best);
        }
        let floor = h.items[best].log_likelihood - REPORT_HOLD_NATS;
        let distance = |i: usize| {
            let x = &h.items[i].x[0];
            (Vector3::new(x[0], x[1], x[2]) - previous).norm_squared()
        };
        (0..h.len()).filter(|&i| h.items[i].log_likelihood >= floor).min_by(|&a, &b| distance(a).total_cmp(&distance(b)))
    }

    /// Notes a switch of the reported trajectory: the reported hypothesis
    /// lies more than [`RESEED_SIGMA_M`] beyond where the previous estimate
    /// could have moved at its speed.
    fn note_switch(&mut self, now_s: f64) {
        let (Some(best), Some((t, previous, _))) = (self.reported(), self.last_good) else { return };
        let x = &self.hypotheses.items[best].x[0];
        let moved = (Vector3::new(x[0], x[1], x[2]) - previous).norm();
        let speed = Vector3::new(x[3], x[4], x[5]).norm();
        if moved > RESEED_SIGMA_M + speed * (now_s - t).max(0.0) {
            self.switched_s = now_s;
        }
    }

    /// Whether competing candidates leave the track unresolved (one of
    /// re-seeding's triggers). Within [`SWITCH_MEMORY_S`] of a switch of
    /// the reported trajectory (the commit counts as one): its reported
    /// sigma, which tempers the weights, above [`RESEED_SIGMA_M`]. After
    /// that, the spread of the hypotheses with their plain weights: the
    /// reported sigma of a track that has held its trajectory is mostly the
    /// last search's newcomers (each ≈ 10⁻⁵ plain, ≈ 0.02 tempered), so it
    /// would call the next search every `reseed_interval_s` for as long as
    /// the tag is read (docs/notes/glac-outliers.md: on the raised layout
    /// at rest a 5 mm track kept a 0.4 m sigma; a third of the 20 s
    /// many-tags run's time). Measured on dev seeds 1000–1049: the
    /// robustness cells' accuracy and coverage as before.
    fn unresolved(&self, now_s: f64) -> bool {
        if self.hypotheses.len() <= 1 {
            return false;
        }
        let spread = if now_s - self.switched_s < SWITCH_MEMORY_S {
            self.last_good.map_or(0.0, |(_, _, c)| largest_sigma(&c))
        } else {
            plain_spread(&self.hypotheses)
        };
        spread > RESEED_SIGMA_M
    }

    /// Whether the reported hypothesis gated the latest reading.
    fn best_gated_last(&self) -> bool {
        let h = &self.hypotheses;
        h.best().is_some_and(|b| h.items[b].outliers > 0)
    }
}

/// Second moment of the hypothesis mixture about `centre`:
/// `Σᵢ wᵢ (Pᵢ + (xᵢ − c)(xᵢ − c)ᵀ)`, with tempered weights
/// wᵢ ∝ exp(ℓᵢ / T) (ℓᵢ the log-likelihoods, T = `temperature` ≥ 1).
/// About the reported state rather than the mixture mean because that is
/// what a user's error is measured from: the truth lies in some hypothesis,
/// and its distance from the reported one must show in the sigma.
/// Tempering, because the log-likelihood ratios between hypotheses add up
/// every read as if the errors were independent, while real phase errors
/// are correlated (and the likelihood is only as right as its noise
/// model): T divides the evidence before it sets how much the competitors
/// count. T = 1 is the plain posterior. Weights below 1e-12 are skipped.
fn mixture_covariance(h: &Hypotheses, centre: &StateVector, temperature: f64) -> StateMatrix {
    let max = h.log_likelihoods().fold(f64::NEG_INFINITY, f64::max);
    let weights: Vec<f64> = h.log_likelihoods().map(|l| ((l - max) / temperature).exp()).collect();
    let total: f64 = weights.iter().sum();
    let mut sum = StateMatrix::zeros();
    for (i, w) in weights.iter().enumerate() {
        let w = w / total;
        if w < 1e-12 {
            continue;
        }
        let (x, p) = h.state(i);
        let d = x - centre;
        sum += (p + d * d.transpose()) * w;
    }
    sum
}

/// Largest per-axis spread (m) of the hypotheses' positions about the
/// likeliest one, with their plain (normalised) weights:
/// `max_k √(Σᵢ wᵢ (xᵢₖ − x̂ₖ)²)`, the positions' part of the untempered
/// mixture covariance ([`mixture_covariance`] at T = 1 without the
/// hypotheses' own P, which is millimetres where this matters).
fn plain_spread(h: &Hypotheses) -> f64 {
    let Some(best) = h.best() else { return 0.0 };
    let centre = h.items[best].x[0].fixed_rows::<3>(0).into_owned();
    let max = h.items[best].log_likelihood;
    let (mut total, mut second) = (0.0, Vector3::zeros());
    for item in &h.items {
        let w = (item.log_likelihood - max).exp();
        let d = item.x[0].fixed_rows::<3>(0) - centre;
        total += w;
        second += d.component_mul(&d) * w;
    }
    (second / total).max().sqrt()
}

/// Largest per-axis 1-sigma of a position covariance, metres.
fn largest_sigma(covariance: &Matrix3<f64>) -> f64 {
    covariance.diagonal().iter().fold(0.0f64, |m, v| m.max(*v)).sqrt()
}

/// log p(z_k | z_1:k−1) of a fast step, before pruning: the log of
/// Σᵢ wᵢ p(z_k | hypothesis i) over the normalised prior weights wᵢ, which
/// is the log-sum-exp of the updated log-likelihoods (what `normalise`
/// subtracts), except that an ambiguity branch and the hypothesis it
/// copied share that hypothesis' prior weight (each carries it whole).
fn read_evidence(h: &Hypotheses, s: &StepProgress) -> f64 {
    let max = h.log_likelihoods().fold(f64::NEG_INFINITY, f64::max);
    let mut sum: f64 = h.log_likelihoods().map(|l| (l - max).exp()).sum();
    for (&(j, ..), &i) in s.branches.iter().zip(&s.origins) {
        sum -= 0.5 * ((h.items[i].log_likelihood - max).exp() + (h.items[j].log_likelihood - max).exp());
    }
    max + sum.max(f64::MIN_POSITIVE).ln()
}

/// [`BiasStep`] applied to hypothesis `i`'s state of the step's antenna.
fn predict_bias(step: &BiasStep, h: &Hypotheses, i: usize) -> BiasPrediction {
    match step.antenna {
        Some(a) => {
            let [mean, variance] = h.bias[i * h.biases + a];
            step.predict(mean, variance)
        }
        None => BiasPrediction::default(),
    }
}

/// The bias update of hypothesis `i` after its state update: a gated
/// reading (its outlier count rose) leaves the bias at its prediction.
fn update_bias(step: &BiasStep, h: &mut Hypotheses, i: usize, b: &BiasPrediction, innovation: f64, variance: f64) {
    let Some(a) = step.antenna else { return };
    let (mean, var) = if h.items[i].outliers == 0 { b.update(innovation, variance) } else { (b.mean, b.variance) };
    h.bias[i * h.biases + a] = [mean, var];
}

/// Everything one reading means for every hypothesis (fast inference).
struct FastStep {
    transition: Transition,
    /// The IMM's manoeuvre model, if enabled.
    manoeuvre: Option<Transition>,
    switch: f64,
    antenna: Vector3<f64>,
    /// Distance residue d₀ (m) and candidate step s (m) of the reading.
    residue: f64,
    spacing: f64,
    /// Range noise variance R, m².
    r: f64,
    /// Squared gate in sigmas.
    gate2: f64,
    likelihood: Likelihood,
    axes: usize,
    /// Known reflectors' paths for this reading (None: single path).
    multipath: Option<Multipath>,
}

/// A reading's reflected paths and its wavenumber k = 2π f / c (rad/m).
struct Multipath {
    wavenumber: f64,
    paths: Arc<[ReflectedPath]>,
}

/// The range a reading from `antenna` measures (m) and, on request, its
/// Jacobian: the apparent range under `multipath`'s reflected paths, else
/// the direct one.
#[inline]
fn measured_range(x: &StateVector, antenna: &Vector3<f64>, multipath: Option<&Multipath>, axes: usize, jacobian: bool) -> (f64, Option<StateVector>) {
    match multipath {
        None => range(x, antenna, axes, jacobian),
        Some(m) => apparent_range(x, antenna, &m.paths, m.wavenumber, axes, jacobian),
    }
}

impl FastStep {
    /// The range the reading measures ([`measured_range`]).
    #[inline]
    fn range(&self, x: &StateVector, jacobian: bool) -> (f64, Option<StateVector>) {
        measured_range(x, &self.antenna, self.multipath.as_ref(), self.axes, jacobian)
    }

    /// Predicts hypothesis `i` to the reading's time (IMM: mixing first;
    /// the predicted model probabilities c are kept in μ until the update)
    /// and returns its predicted range (m) and innovation variance S (m²)
    /// under the combined prediction, and the predicted covariances (slot
    /// 1 unused by a single model), which [`FastStep::update_predicted`]
    /// takes: the hypothesis' stored covariances are written once a read,
    /// by the update. A single model also returns the range and its
    /// Jacobian at the predicted state, which the update linearises at
    /// (computed once: under known reflectors it is the costly part).
    fn predict(&self, h: &mut Hypotheses, i: usize) -> (f64, f64, [StateMatrix; 2], Option<(f64, StateVector)>) {
        let h = &mut h.items[i];
        match self.manoeuvre {
            None => {
                let mut p = h.p[0].unpack();
                predict(&mut h.x[0], &mut p, &self.transition);
                let (d, jac) = self.range(&h.x[0], true);
                let jac = jac.unwrap();
                (d, jac.dot(&(p * jac)) + self.r, [p, StateMatrix::zeros()], Some((d, jac)))
            }
            Some(manoeuvre) => {
                let mut p = unpack_pair(&h.p);
                let mu = h.mu;
                let c = imm::mix(&mut h.x, &mut p, &mu, self.switch);
                h.mu = c;
                predict(&mut h.x[0], &mut p[0], &self.transition);
                predict(&mut h.x[1], &mut p[1], &manoeuvre);
                // The combined prediction's range variance without forming
                // the combined P: H P H = Σ c_j (H P_j Hᵀ + (H (x_j − x̂))²).
                let x = h.x[0] * c[0] + h.x[1] * c[1];
                let (d, jac) = self.range(&x, true);
                let jac = jac.unwrap();
                let spread = |j: usize| {
                    let offset = jac.dot(&(h.x[j] - x));
                    jac.dot(&(p[j] * jac)) + offset * offset
                };
                (d, c[0] * spread(0) + c[1] * spread(1) + self.r, p, None)
            }
        }
    }

    /// Updates predicted hypothesis `i` with candidate distance `z` (m)
    /// and `extra_r` (m²) of noise beyond R (the bias state's variance),
    /// gating (3σ recovery) and adding the reading's log-likelihood. A
    /// gated reading is charged the density at the gate, so a hypothesis
    /// cannot gain by rejecting data.
    /// `predicted`: the covariances [`FastStep::predict`] returned;
    /// `line`: its range and Jacobian at the predicted state, if it gave
    /// them (else they are computed here).
    fn update_predicted(&self, h: &mut Hypotheses, i: usize, predicted: [StateMatrix; 2], z: f64, extra_r: f64, line: Option<(f64, StateVector)>) {
        let gated = |s: f64| -0.5 * (self.gate2 + (2.0 * std::f64::consts::PI * s).ln());
        let r = self.r + extra_r;
        let h = &mut h.items[i];
        if self.manoeuvre.is_none() {
            let [mut p, _] = predicted;
            let x_predicted = h.x[0];
            let (d, jac) = line.unwrap_or_else(|| {
                let (d, jac) = self.range(&h.x[0], true);
                (d, jac.unwrap())
            });
            let (u, b) = innovation(&p, z, d, &jac, r);
            h.log_likelihood += if u.innovation * u.innovation <= self.gate2 * u.variance {
                h.outliers = 0;
                let x = &mut h.x[0];
                apply_scalar(x, &mut p, &u, &b);
                match self.likelihood {
                    Likelihood::Innovation => log_gaussian(u.innovation, u.variance),
                    Likelihood::Paper => {
                        let d_post = self.range(x, false).0;
                        log_gaussian(d_post - z, r) + transition_log_density(x, &x_predicted, &self.transition)
                    }
                }
            } else {
                h.outliers += 1;
                gated(u.variance)
            };
            h.p[0] = PackedCovariance::pack(&p);
            return;
        }
        // IMM: update each model, μ_j ∝ c_j Λ_j, factor Σ c_j Λ_j.
        let c = h.mu;
        let mut density = [0.0; 2];
        let mut variance = [0.0; 2];
        let mut accepted = false;
        // Fixed-size, no allocation: this runs for every hypothesis on
        // every reading.
        let mut p = predicted;
        let updates: [_; 2] = std::array::from_fn(|j| {
            let (d, jac) = self.range(&h.x[j], true);
            let (u, b) = innovation(&p[j], z, d, &jac.unwrap(), r);
            accepted |= u.innovation * u.innovation <= self.gate2 * u.variance;
            density[j] = log_gaussian(u.innovation, u.variance);
            variance[j] = u.variance;
            (u, b)
        });
        if accepted {
            h.outliers = 0;
            let max = density[0].max(density[1]);
            let w = [c[0] * (density[0] - max).exp(), c[1] * (density[1] - max).exp()];
            let total = w[0] + w[1];
            for (j, (u, b)) in updates.iter().enumerate() {
                apply_scalar(&mut h.x[j], &mut p[j], u, b);
            }
            h.mu = [w[0] / total, w[1] / total];
            h.log_likelihood += max + total.ln();
        } else {
            h.outliers += 1;
            h.log_likelihood += gated(variance[0].min(variance[1]));
        }
        h.p = pack_pair(&p);
    }
}

/// log F(θ_{k+1}; Aθ_k, Q) (eq. 13), with `predicted` = Aθ_k, for the block-diagonal Q of the motion
/// models: per axis a 2×2 block [[Qpp, Qpv], [Qpv, Qvv]] (or a scalar Qpp
/// without velocity), inverted in closed form.
fn transition_log_density(x: &StateVector, predicted: &StateVector, t: &Transition) -> f64 {
    let dx = x - predicted;
    let [pp, pv, vv] = t.q_blocks;
    let mut log_density = 0.0;
    for i in 0..t.axes {
        if t.with_velocity {
            let det = pp * vv - pv * pv;
            if det <= 0.0 {
                continue;
            }
            let (a, b) = (dx[i], dx[i + 3]);
            let maha = (vv * a * a - 2.0 * pv * a * b + pp * b * b) / det;
            log_density += -0.5 * (maha + (4.0 * std::f64::consts::PI * std::f64::consts::PI * det).ln());
        } else if pp > 0.0 {
            log_density += log_gaussian(dx[i], pp);
        }
    }
    log_density
}

impl Glac {
    /// One phase reading (the body of [`Tracker::step`]): queued, then
    /// the queue is worked off within the read budget. The estimate is the
    /// one after this read when the tracker caught up; while work is left,
    /// nothing (or, re-initialising, the re-acquisition estimate).
    fn step_read(&mut self, m: &PhaseRead) -> Option<Estimate> {
        self.stats.measurements += 1;
        let valid = m.antenna < self.scene.antennas.len()
            && m.time_s.is_finite()
            && m.frequency_hz.is_finite()
            && m.frequency_hz > 0.0
            && m.phase_rad.is_finite();
        if !valid {
            self.stats.invalid += 1;
            return None;
        }
        if m.time_s < self.arrival_s {
            self.stats.out_of_order += 1;
            return None;
        }
        self.arrival_s = m.time_s;
        let read = Pending { read: *m, replay: None };
        // The variants' steps cannot be split (naive: every hypothesis
        // times every candidate), so they run unbudgeted, as before.
        let limit = if self.params.inference == Inference::Fast { self.params.read_budget as u64 } else { u64::MAX };
        let mut budget = Budget::new(limit);
        // The estimate after the latest read taken through: on the stack
        // while this call works, kept in the tracker only while reads are
        // left for later calls (the tag-state line holding it stays cold
        // on a converged tag's read; `take` would copy all of it).
        let mut latest = if self.result.is_some() { self.result.take() } else { None };
        if self.job.is_none() && self.progress.is_none() && self.pending.is_empty() {
            // Nothing queued (a converged tag): straight in, without
            // touching the queue's memory.
            self.work(&mut budget, Some(read), &mut latest);
        } else {
            self.pending.push_back(read);
            self.work(&mut budget, None, &mut latest);
        }
        self.stats.max_expanded_per_read = self.stats.max_expanded_per_read.max(budget.expanded());
        if self.job.is_none() && self.progress.is_none() && self.pending.is_empty() {
            latest
        } else {
            self.result = latest;
            if self.phase == Phase::Initialising {
                self.coasting_estimate(m.time_s)
            } else {
                None
            }
        }
    }

    /// Works off the job, the step under way and the queued reads, in that
    /// order, while `budget` lasts; `first`, a read that would be queued
    /// last on an empty queue, goes first.
    fn work(&mut self, budget: &mut Budget, mut first: Option<Pending>, out: &mut Option<Estimate>) {
        loop {
            if let Some(mut job) = self.job.take() {
                if let Some(left) = self.advance_job(*job, budget, out) {
                    *job = left; // the box is reused while the job spans reads
                    self.job = Some(job);
                    return;
                }
                continue;
            }
            if let Some(mut progress) = self.progress.take() {
                if let Some(left) = self.advance_step(*progress, budget, out) {
                    *progress = left;
                    self.progress = Some(progress);
                    return;
                }
                continue;
            }
            let next = match first.take() {
                Some(read) => read,
                None => match self.pending.pop_front() {
                    Some(read) => read,
                    None => {
                        if let Some(mut job) = self.reseeding.take() {
                            if let Some(left) = self.advance_reseed(*job, budget) {
                                *job = left;
                                self.reseeding = Some(job);
                            }
                        }
                        return;
                    }
                },
            };
            if !budget.try_spend_overhead(1) {
                self.pending.push_front(next);
                return;
            }
            // The step stays on the stack unless the budget runs out: a
            // converged tag's read then writes none of it to the tag's
            // (cold) memory.
            if let Some(started) = self.begin_read(next, budget, out) {
                if let Some(left) = self.advance_step(started, budget, out) {
                    self.progress = Some(Box::new(left));
                    return;
                }
            }
        }
    }

    /// Takes queued read `p` in: its bookkeeping (a fresh read), then the
    /// initial buffer or the hypotheses; the fast step it starts, if any.
    fn begin_read(&mut self, p: Pending, budget: &mut Budget, out: &mut Option<Estimate>) -> Option<StepProgress> {
        let m = &p.read;
        if p.replay.is_none() {
            if self.phase == Phase::Tracking && m.time_s - self.last_time_s > self.params.reinit_gap_s {
                self.restart();
            }
            self.last_time_s = m.time_s;
            self.last_frequency_hz = m.frequency_hz;
            if !self.first_frequency_hz.is_finite() {
                self.first_frequency_hz = m.frequency_hz;
            } else if (m.frequency_hz - self.first_frequency_hz).abs() > 1e3 {
                self.hopped = true;
            }
            let clock = &mut self.antenna_clock[m.antenna];
            *clock = AntennaClock { read_s: m.time_s, interval_s: m.time_s - clock.read_s };
        }
        if self.phase == Phase::Initialising {
            self.stats.initialising += 1;
            self.buffer.push(*m);
            *out = None;
            if !self.try_initialise(m.time_s) {
                *out = self.coasting_estimate(m.time_s);
            }
            return None;
        }
        match self.params.inference {
            Inference::Fast => Some(self.begin_fast(m, Purpose::Track(p))),
            // The variants' steps run whole (their cost: every hypothesis,
            // times every candidate for the naive one).
            Inference::Naive | Inference::Synchronous => {
                let before = self.stats.filter_updates;
                self.track(m);
                budget.spend(self.stats.filter_updates - before);
                self.after_track(p, out);
                None
            }
        }
    }

    /// The per-read handling after read `p` went through the hypotheses.
    fn after_track(&mut self, p: Pending, out: &mut Option<Estimate>) {
        let m = &p.read;
        if let Some(report_s) = p.replay {
            if self.hypotheses.len() == 0 {
                // Every hypothesis died during the replay: keep collecting.
                while self.pending.front().is_some_and(|q| q.replay.is_some()) {
                    self.pending.pop_front();
                }
                self.restart();
                *out = self.coasting_estimate(report_s);
            } else if !self.pending.front().is_some_and(|q| q.replay.is_some()) {
                *out = self.remember(self.best_estimate(report_s));
            }
            return;
        }
        if self.hypotheses.len() == 0 {
            // Every hypothesis lost lock: start over from this read.
            self.restart();
            self.buffer.push(*m);
            self.stats.initialising += 1;
            *out = self.coasting_estimate(m.time_s);
            return;
        }
        if self.params.inference != Inference::Naive && self.best_gated_last() {
            self.stats.outliers += 1;
            self.gated_since_seed += 1;
        }
        if self.params.inference == Inference::Fast && self.params.reseed_interval_s > 0.0 {
            self.recent.push_back(*m);
            let keep_from = m.time_s - self.params.init_max_window_s;
            while self.recent.front().is_some_and(|r| r.time_s < keep_from) {
                self.recent.pop_front();
            }
            self.note_switch(m.time_s);
            let unresolved = self.unresolved(m.time_s);
            let lost = self.gated_since_seed >= 2;
            if lost || !unresolved {
                self.reseed_streak = 0;
            }
            let due = m.time_s - self.seeded_s >= self.reseed_interval() && (unresolved || lost);
            if due && self.reseeding.is_none() {
                if !lost {
                    self.reseed_streak = self.reseed_streak.saturating_add(1);
                }
                self.start_reseed(m.time_s);
            }
        }
        if self.params.inference == Inference::Synchronous && !self.group.is_empty() {
            *out = None; // no new estimate until the group completes
            return;
        }
        *out = self.remember(self.best_estimate(m.time_s));
    }

    /// Keeps `estimate` as the last good state (for re-acquisition), and
    /// notes a resolved report. Resolved: the reported sigma, or the
    /// hypotheses' plain-weight spread ([`plain_spread`]), is below
    /// [`RESEED_SIGMA_M`]. The plain spread counts because a re-seeding
    /// search's newcomers, tempered one by one, keep the reported sigma at
    /// decimetres on some layouts while the track holds > 99 % of the plain
    /// weight. Such a track was never held, so after a gap it restarted
    /// from the likeliest candidate, not the nearest. Dev seeds 1000-1049,
    /// raised layout, 10 s dropout: back within 1 s 2 -> 68 %. Wins within
    /// 1 s are unchanged in every cell (docs/notes/glac-experiments.md).
    fn remember(&mut self, estimate: Option<Estimate>) -> Option<Estimate> {
        if let Some(e) = &estimate {
            let c = &e.covariance;
            let covariance = Matrix3::from_fn(|r, k| c[r * 6 + k]);
            self.last_good = Some((e.time_s, Vector3::from(e.position), covariance));
            if !self.resolved_once {
                self.resolved_once = largest_sigma(&covariance) < RESEED_SIGMA_M || plain_spread(&self.hypotheses) < RESEED_SIGMA_M;
            }
        }
        estimate
    }

    /// While re-initialising after a restart: the last good position, with
    /// its covariance grown by the ball the tag can have reached since,
    /// radius r = `max_speed_m_s` · Δt (a uniform ball's per-axis variance
    /// r²/5 is added; 3σ then exceeds r). Velocity 0 ± `max_speed_m_s`.
    /// Honest rather than silent: the user sees where the tag can be.
    fn coasting_estimate(&self, time_s: f64) -> Option<Estimate> {
        let (t, position, covariance) = self.last_good?;
        let radius = self.params.max_speed_m_s * (time_s - t).max(0.0);
        let mut c = [0.0; 36];
        for r in 0..3 {
            for k in 0..3 {
                c[r * 6 + k] = covariance[(r, k)];
            }
        }
        for k in 0..self.axes {
            c[k * 6 + k] += radius * radius / 5.0;
            c[(k + 3) * 6 + k + 3] = self.params.max_speed_m_s * self.params.max_speed_m_s;
        }
        Some(Estimate {
            time_s,
            position: [position.x, position.y, position.z],
            velocity: [0.0; 3],
            covariance: c,
            hypotheses: 0,
            weight: 0.0,
        })
    }
}

impl Tracker for Glac {
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate> {
        match measurement {
            Measurement::Phase(read) => self.step_read(read),
            Measurement::Wideband(_) => self.stats.decline_invalid(),
        }
    }

    fn stats(&self) -> TrackerStats {
        self.stats
    }

    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        (0..self.hypotheses.len())
            .map(|i| {
                let (x, _) = self.hypotheses.state(i);
                ([x[0], x[1], x[2]], self.hypotheses.items[i].log_likelihood)
            })
            .collect()
    }

    fn fresh(&self) -> Option<Box<dyn Tracker>> {
        Some(Box::new(Self::with_shared(self.scene.clone(), self.params.clone(), self.line_layout.clone())))
    }

    fn prefetch(&self) {
        use crate::prefetch;
        // The fields a converged read touches come before `result`.
        prefetch::bytes((self as *const Self).cast(), std::mem::offset_of!(Glac, result));
        // The first hypotheses: a converged tag has one; more are worth
        // asking for only while they are few.
        let items = &self.hypotheses.items;
        prefetch::value(&items[..items.len().min(2)]);
        let bias = &self.hypotheses.bias;
        prefetch::value(&bias[..bias.len().min(2 * self.hypotheses.biases)]);
        prefetch::value(self.antenna_clock.as_slice());
        prefetch::value(self.bias_clock.as_slice());
        if let Some(last) = self.recent.back() {
            prefetch::value(last); // the next read goes after it
        }
        if let Some(oldest) = self.recent.front() {
            prefetch::value(oldest); // each read checks whether it has aged out
        }
    }

    fn reset(&mut self) {
        self.phase = Phase::Initialising;
        self.pending.clear();
        self.progress = None;
        self.job = None;
        self.reseeding = None;
        self.result = None;
        self.arrival_s = f64::NEG_INFINITY;
        self.buffer.clear();
        self.hypotheses.clear();
        self.group.clear();
        self.time_s = f64::NEG_INFINITY;
        self.last_time_s = f64::NEG_INFINITY;
        self.antenna_clock.fill(AntennaClock::UNREAD);
        self.last_good = None;
        self.first_frequency_hz = f64::NAN;
        self.hopped = false;
        self.bias_clock.fill(BiasClock::UNSET);
        if let Some(log) = self.evidence.as_mut() {
            log.clear();
        }
    }
}

/// How much more an error with AR(1) correlation ρ between successive reads
/// of one antenna weighs than white noise of the same variance: the
/// long-run variance of a sum of such errors is n σ² (1 + ρ)/(1 − ρ) where
/// white errors give n σ². A filter that takes each read as independent
/// must count the correlated share at that inflated variance, or it
/// believes n reads average it down √n times when they hardly do. ρ =
/// exp(−Δt/τ) with Δt the antenna's read interval and τ the correlation
/// time: at 30 reads/s over 4 antennas (Δt ≈ 0.13 s) and τ = 0.5 s the
/// factor is 7.6. Capped at 1e4 (ρ → 1).
pub fn correlated_variance_factor(rho: f64) -> f64 {
    let rho = rho.clamp(0.0, 1.0);
    ((1.0 + rho) / (1.0 - rho)).min(1e4)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::{Antenna, Region};

    #[test]
    fn pruning_to_a_few_hypotheses_gives_back_their_room() {
        let mut h = Hypotheses::with_capacity(200, 4);
        for k in 0..200 {
            h.push(StateVector::repeat(k as f64), StateMatrix::identity(), -(k as f64));
            for a in 0..4 {
                h.bias[k * 4 + a] = [k as f64, a as f64];
            }
        }
        h.retain(|i| i % 10 == 0); // 20 of 200 left: shrunk to what is live
        assert_eq!(h.len(), 20);
        assert!(h.items.capacity() < 200 && h.bias.capacity() < 4 * 200);
        h.retain(|i| i == 3);
        assert_eq!(h.len(), 1);
        assert_eq!(h.items[0].x[0][0], 30.0, "retain keeps order and contents");
        assert_eq!(h.biases_of(0), &[[30.0, 0.0], [30.0, 1.0], [30.0, 2.0], [30.0, 3.0]], "and the bias states with them");
        for capacity in [h.items.capacity(), h.bias.capacity() / 4] {
            assert!(capacity <= SHRINK_CAPACITY, "capacity {capacity} after converging");
        }
        // Small arrays are left alone (no churn while a few hypotheses live).
        let mut small = Hypotheses::with_capacity(SHRINK_CAPACITY, 4);
        for _ in 0..SHRINK_CAPACITY {
            small.push(StateVector::zeros(), StateMatrix::identity(), 0.0);
        }
        small.retain(|i| i == 0);
        assert_eq!(small.items.capacity(), SHRINK_CAPACITY);
    }

    fn scene() -> Scene {
        planar_scene(0.1)
    }

    /// The paper's 2D layout (four antennas in the plane z = 0) with a
    /// region that excludes the mirror, phase noise `phase_noise_rad`.
    pub(crate) fn planar_scene(phase_noise_rad: f64) -> Scene {
        let pos = [[0.0, 0.0], [0.0, 0.3], [0.0, 0.8], [0.8, 0.8]];
        let antennas = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: 0.0, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(0.1, -0.5, 0.0), max: Vector3::new(1.6, 1.5, 0.0) };
        Scene::new(2, 0.0, 1.0, std::f64::consts::TAU, phase_noise_rad, antennas, Some(region), vec![]).unwrap()
    }

    fn reads(scene: &Scene, n: usize) -> Vec<PhaseRead> {
        (0..n)
            .map(|k| {
                let t = 0.033 * k as f64;
                let p = Vector3::new(0.6 + 0.1 * t, 0.3 + 0.05 * t, 0.0);
                let a = k % 4;
                let d = (p - scene.antennas[a].position).norm();
                PhaseRead { time_s: t, antenna: a, frequency_hz: 915.25e6, phase_rad: scene.ideal_phase(a, 915.25e6, d) }
            })
            .collect()
    }

    /// Property: after every step the hypotheses' weights sum to 1.
    #[test]
    fn weights_sum_to_one() {
        let scene = scene();
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let mut seen_estimate = false;
        for m in reads(&scene, 120) {
            if tracker.step(&Measurement::Phase(m)).is_some() {
                seen_estimate = true;
                let total: f64 = tracker.hypotheses.log_likelihoods().map(|l| l.exp()).sum();
                assert!((total - 1.0).abs() < 1e-9, "weights sum to {total}");
            }
        }
        assert!(seen_estimate);
    }

    /// Two hypotheses 0.2 m apart in x, the first (returned with their
    /// common covariance) at plain weight `w`, the second at 1 − `w`.
    fn two_hypotheses(w: f64) -> (Hypotheses, StateVector, StateMatrix) {
        let mut h = Hypotheses::with_capacity(0, 4);
        let p = StateMatrix::identity() * 1e-6;
        let a = StateVector::from_iterator([0.5, 0.5, 0.5, 0.0, 0.0, 0.0]);
        h.push(a, p, w.ln());
        h.push(StateVector::from_iterator([0.7, 0.5, 0.5, 0.0, 0.0, 0.0]), p, (1.0 - w).ln());
        (h, a, p)
    }

    /// The reported covariance is the mixture's second moment about the
    /// reported state: two equally likely hypotheses 0.2 m apart in x give
    /// σx² = P + ½ · 0.2², and the reported one alone gives its own P.
    #[test]
    fn covariance_covers_competing_hypotheses() {
        let (mut h, a, p) = two_hypotheses(0.5);
        let sigma = mixture_covariance(&h, &a, 1.0);
        assert!((sigma[(0, 0)] - (1e-6 + 0.5 * 0.04)).abs() < 1e-12);
        assert!((sigma[(1, 1)] - 1e-6).abs() < 1e-15);
        // The truth at either hypothesis lies within 3 sigma of the report.
        assert!(0.2 < 3.0 * sigma[(0, 0)].sqrt());
        // One hypothesis with all the weight: its own covariance.
        (h.items[0].log_likelihood, h.items[1].log_likelihood) = (0.0, -1e3);
        assert!((mixture_covariance(&h, &a, 1.0) - p).norm() < 1e-15);
        // Tempered: a hypothesis 6 nats behind counts as one 2 nats behind.
        (h.items[0].log_likelihood, h.items[1].log_likelihood) = (0.0, -6.0);
        let tempered = mixture_covariance(&h, &a, 3.0);
        let w = (-2.0f64).exp() / (1.0 + (-2.0f64).exp());
        assert!((tempered[(0, 0)] - (1e-6 + w * 0.04)).abs() < 1e-12);
    }

    /// The unmodelled bias adds σ_b² (λ/4π)² (JᵀJ)⁻¹: with antennas on the
    /// three axes (J = I) exactly σ_b² (λ/4π)² per axis, and only for
    /// antennas that have read the tag.
    #[test]
    fn bias_covariance_is_the_least_squares_spread_of_a_range_bias() {
        let positions = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let antennas = positions
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], p[2]), phase_offset_rad: 0.0, role: Default::default() })
            .collect();
        let scene = Scene::new(3, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, None, vec![]).unwrap();
        let params = GlacParams { bias_sigma_rad: 0.1, bias_state: false, ..GlacParams::default() };
        let mut tracker = Glac::new(scene, params).unwrap();
        let x = StateVector::zeros();
        let mut p = StateMatrix::zeros();
        tracker.add_bias_covariance(&mut p, &x);
        assert_eq!(p, StateMatrix::zeros(), "no read yet: nothing known of the carrier");
        tracker.last_frequency_hz = 915e6;
        tracker.antenna_clock = vec![AntennaClock { read_s: 0.0, interval_s: f64::INFINITY }; 3];
        tracker.add_bias_covariance(&mut p, &x);
        let to_range = Scene::range_per_radian(915e6);
        let expected = (0.1 * to_range).powi(2);
        for k in 0..3 {
            assert!((p[(k, k)] - expected).abs() < 1e-15);
        }
        assert!(p[(0, 1)].abs() < 1e-18 && p[(3, 3)] == 0.0);
        // Two antennas cannot fix a 3D position: nothing is added (the
        // geometry check reports such layouts).
        let mut q = StateMatrix::zeros();
        tracker.antenna_clock[2].read_s = f64::NEG_INFINITY;
        tracker.add_bias_covariance(&mut q, &x);
        assert_eq!(q, StateMatrix::zeros());
    }

    /// After a read gap the tracker reports the last good position with
    /// the reachable ball as its uncertainty until it re-commits, and the
    /// new search keeps only candidates the tag can have reached.
    #[test]
    fn reacquires_from_the_last_good_state_after_a_gap() {
        let scene = scene();
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let all = reads(&scene, 300); // 10 s at 30 reads/s
        // Reads stop from 4 s to 5.5 s (longer than reinit_gap_s = 1 s).
        let kept: Vec<_> = all.iter().filter(|m| m.time_s < 4.0 || m.time_s >= 5.5).collect();
        let mut before = None;
        let mut coasting = Vec::new();
        let mut after = Vec::new();
        for m in kept {
            let Some(e) = tracker.step(&Measurement::Phase(*m)) else { continue };
            if m.time_s < 4.0 {
                before = Some(e);
            } else if e.hypotheses == 0 {
                coasting.push(e);
            } else {
                after.push((m.time_s, e));
            }
        }
        assert_eq!(tracker.stats().reinitialisations, 1);
        let before = before.unwrap();
        assert!(!coasting.is_empty(), "no estimate while re-initialising");
        for e in &coasting {
            assert_eq!(e.position, before.position);
            let radius = tracker.params().max_speed_m_s * (e.time_s - before.time_s);
            assert!(e.position_sigma()[0] * 3.0 >= radius, "the reachable ball must lie within 3 sigma");
        }
        // Re-committed within the re-initialisation window, on the truth.
        let (t, first) = &after[0];
        assert!(*t < 5.5 + 2.0 * GlacParams::default().init_max_window_s);
        let truth = Vector3::new(0.6 + 0.1 * t, 0.3 + 0.05 * t, 0.0);
        assert!((Vector3::from(first.position) - truth).norm() < 0.01);
    }

    #[test]
    fn reachable_keeps_candidates_within_the_speed_bound() {
        let mut tracker = Glac::new(scene(), GlacParams { max_speed_m_s: 0.5, ..GlacParams::default() }).unwrap();
        let at = |x: f64| super::super::initial::InitialHypothesis {
            state: StateVector::from_iterator([x, 0.3, 0.0, 0.0, 0.0, 0.0]),
            log_likelihood: 0.0,
            max_residual_m: 0.0,
        };
        let candidates = || vec![at(0.5), at(0.9), at(1.5)];
        assert_eq!(tracker.reachable(candidates(), 1.0).len(), 3, "no last state: every candidate");
        tracker.last_good = Some((0.0, Vector3::new(0.5, 0.3, 0.0), Matrix3::identity() * 1e-6));
        // 1 s at 0.5 m/s + 3 mm: 0.5 and 0.9 are reachable, 1.5 is not.
        let kept: Vec<f64> = tracker.reachable(candidates(), 1.0).iter().map(|h| h.state[0]).collect();
        assert_eq!(kept, vec![0.5, 0.9]);
        // None reachable: the bound was wrong, search everywhere.
        assert_eq!(tracker.reachable(vec![at(1.5)], 1.0).len(), 1);
    }

    /// The report: the likeliest until a resolved report; then the
    /// hypothesis nearest the last report while it is within
    /// `REPORT_HOLD_NATS` of the likeliest, and the likeliest beyond that.
    #[test]
    fn a_resolved_report_holds_its_trajectory_against_a_near_equal_rival() {
        let mut tracker = Glac::new(scene(), GlacParams::default()).unwrap();
        let (h, a, _) = two_hypotheses(0.4);
        tracker.hypotheses = h;
        let at_a = Some((0.0, Vector3::new(a[0], a[1], a[2]), Matrix3::identity() * 1e-6));
        tracker.last_good = at_a;
        // Never resolved: the likeliest (the second, 0.6 against 0.4).
        assert_eq!(tracker.reported(), Some(1));
        tracker.remember(tracker.best_estimate(0.0));
        assert!(!tracker.resolved_once, "a report covering both rivals is not resolved");
        tracker.resolved_once = true;
        tracker.last_good = at_a;
        // Resolved once: the first, nearest the last report, 0.4 nats behind.
        assert_eq!(tracker.reported(), Some(0));
        // A rival REPORT_HOLD_NATS + 0.1 ahead takes the report.
        let lead = tracker.hypotheses.items[0].log_likelihood + REPORT_HOLD_NATS + 0.1;
        tracker.hypotheses.items[1].log_likelihood = lead;
        assert_eq!(tracker.reported(), Some(1));
    }

    /// The AR(1) bias prediction: ρ = exp(−Δt/τ) since the antenna's last
    /// read, stationary on its first read.
    #[test]
    fn bias_state_follows_the_ar1_model() {
        let scene = scene();
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let read = |t: f64| PhaseRead { time_s: t, antenna: 1, frequency_hz: 915e6, phase_rad: 0.0 };
        let to_range = Scene::range_per_radian(915e6);
        let stationary = (0.07 * to_range).powi(2);
        let first = tracker.bias_step(&read(1.0));
        assert_eq!((first.antenna, first.rho), (Some(1), 0.0));
        assert!((first.drive - stationary).abs() < 1e-18);
        let next = tracker.bias_step(&read(1.25));
        assert!((next.rho - (-0.25f64 / 0.5).exp()).abs() < 1e-12);
        assert!((next.drive - stationary * (1.0 - next.rho * next.rho)).abs() < 1e-18);
        let mut off = Glac::new(scene.clone(), GlacParams { bias_state: false, ..GlacParams::default() }).unwrap();
        assert_eq!(off.bias_step(&read(1.0)).antenna, None);
    }

    /// A read on another carrier than the antenna's previous one adds the
    /// hop share of the bias to the drive; the same carrier, or another
    /// antenna's clock, does not.
    #[test]
    fn a_new_carrier_draws_the_hop_share_of_the_bias_afresh() {
        let scene = scene();
        let mut tracker = Glac::new(scene.clone(), GlacParams { hop_bias_sigma_rad: 0.1, ..GlacParams::default() }).unwrap();
        let read = |t: f64, antenna: usize, f: f64| PhaseRead { time_s: t, antenna, frequency_hz: f, phase_rad: 0.0 };
        let first = tracker.bias_step(&read(1.0, 1, 915e6));
        assert_eq!(first.rho, 0.0);
        let other_antenna = tracker.bias_step(&read(1.1, 2, 903e6));
        assert_eq!(other_antenna.rho, 0.0, "antenna 2's first read is its stationary prior");
        let same = tracker.bias_step(&read(1.25, 1, 915e6));
        let hopped = tracker.bias_step(&read(1.5, 1, 903e6));
        let (rho, stationary) = ((-0.25f64 / 0.5).exp(), |f: f64| (0.07 * Scene::range_per_radian(f)).powi(2));
        assert!((same.drive - stationary(915e6) * (1.0 - rho * rho)).abs() < 1e-18);
        let jump = (0.1 * Scene::range_per_radian(903e6)).powi(2);
        assert!((hopped.rho - rho).abs() < 1e-12);
        assert!((hopped.drive - (stationary(903e6) * (1.0 - rho * rho) + jump)).abs() < 1e-18);
        let mut off = Glac::new(scene, GlacParams { hop_bias_sigma_rad: 0.0, ..GlacParams::default() }).unwrap();
        off.bias_step(&read(1.0, 1, 915e6));
        let no_jump = off.bias_step(&read(1.25, 1, 903e6));
        assert!((no_jump.drive - stationary(903e6) * (1.0 - rho * rho)).abs() < 1e-18);
    }

    /// A slow phase bias on one antenna (0.15 rad, a 3 s sinusoid, as
    /// multipath or wander would give): the bias states absorb it, and
    /// the track is closer to the truth than without them.
    #[test]
    fn bias_states_absorb_a_slow_antenna_bias() {
        let scene = scene();
        let biased: Vec<PhaseRead> = reads(&scene, 240)
            .into_iter()
            .map(|mut m| {
                if m.antenna == 2 {
                    m.phase_rad = (m.phase_rad + 0.15 * (std::f64::consts::TAU * m.time_s / 3.0).sin()).rem_euclid(std::f64::consts::TAU);
                }
                m
            })
            .collect();
        let error = |bias_state: bool| {
            let params = GlacParams { bias_state, bias_sigma_rad: 0.15, phase_noise_rad: Some(0.02), ..GlacParams::default() };
            let mut tracker = Glac::new(scene.clone(), params).unwrap();
            let mut sum = 0.0;
            let mut count = 0;
            for m in &biased {
                if let Some(e) = tracker.step(&Measurement::Phase(*m)) {
                    if m.time_s > 3.0 {
                        let t = m.time_s;
                        let truth = Vector3::new(0.6 + 0.1 * t, 0.3 + 0.05 * t, 0.0);
                        sum += (Vector3::from(e.position) - truth).norm();
                        count += 1;
                    }
                }
            }
            sum / count as f64
        };
        let (with, without) = (error(true), error(false));
        assert!(with < 0.8 * without, "mean error with bias states {with} m, without {without} m");
    }

    /// Searches an unresolved track starts on its own double the interval
    /// up to `reseed_max_interval_s`; a cap below the base leaves the base.
    #[test]
    fn the_reseed_interval_backs_off_up_to_its_cap() {
        let params = GlacParams { reseed_interval_s: 1.0, reseed_max_interval_s: 8.0, ..GlacParams::default() };
        let mut tracker = Glac::new(scene(), params).unwrap();
        let intervals: Vec<f64> = (0..6)
            .map(|streak| {
                tracker.reseed_streak = streak;
                tracker.reseed_interval()
            })
            .collect();
        assert_eq!(intervals, [1.0, 2.0, 4.0, 8.0, 8.0, 8.0]);
        let mut tracker = Glac::new(scene(), GlacParams { reseed_interval_s: 2.0, reseed_max_interval_s: 1.0, ..GlacParams::default() }).unwrap();
        tracker.reseed_streak = 3;
        assert_eq!(tracker.reseed_interval(), 2.0);
        tracker.restart();
        assert_eq!(tracker.reseed_streak, 0);
    }

    /// The plain-weight spread is the untempered mixture's position part
    /// about the likeliest hypothesis.
    #[test]
    fn plain_spread_weighs_the_competitors_untempered() {
        let (h, _, _) = two_hypotheses(0.9);
        assert!((plain_spread(&h) - (0.1f64 * 0.04).sqrt()).abs() < 1e-12);
        assert_eq!(plain_spread(&Hypotheses::with_capacity(0, 4)), 0.0);
    }

    /// A track that has held its trajectory is judged by the plain spread:
    /// a newcomer at 10⁻⁵, 0.5 m away, leaves it resolved although the
    /// reported (tempered) sigma is decimetres; within SWITCH_MEMORY_S of
    /// a switch the reported sigma decides.
    #[test]
    fn newcomers_do_not_keep_a_held_track_unresolved() {
        let mut tracker = Glac::new(scene(), GlacParams::default()).unwrap();
        let p = StateMatrix::identity() * 1e-6;
        let a = StateVector::from_iterator([0.5, 0.5, 0.5, 0.0, 0.0, 0.0]);
        let b = StateVector::from_iterator([1.0, 0.5, 0.5, 0.0, 0.0, 0.0]);
        tracker.hypotheses.push(a, p, 0.0);
        tracker.hypotheses.push(b, p, 1e-5f64.ln());
        tracker.last_good = Some((0.9, Vector3::new(0.5, 0.5, 0.5), Matrix3::identity() * 0.2 * 0.2));
        tracker.switched_s = 0.0;
        assert!(tracker.unresolved(1.0));
        assert!(!tracker.unresolved(SWITCH_MEMORY_S + 0.1));
        // Competitors with real weight keep it unresolved either way.
        tracker.hypotheses.items[1].log_likelihood = 0.2f64.ln();
        assert!(tracker.unresolved(SWITCH_MEMORY_S + 0.1));
        // One hypothesis is resolved.
        tracker.hypotheses.retain(|i| i == 0);
        assert!(!tracker.unresolved(1.0));
    }

    /// A report is resolved when its sigma is small, or when the plain
    /// weights leave no real competitor although the tempered sigma is
    /// wide (a newcomer at 10⁻⁵, 0.5 m away); not while a competitor holds
    /// a fifth of the plain weight.
    #[test]
    fn a_report_is_resolved_by_its_sigma_or_its_plain_spread() {
        let estimate = |covariance_m2: f64| {
            Some(Estimate::from_position(1.0, &Vector3::new(0.5, 0.5, 0.5), &(Matrix3::identity() * covariance_m2), [0.0; 3], 2, 1.0))
        };
        let p = StateMatrix::identity() * 1e-6;
        let a = StateVector::from_iterator([0.5, 0.5, 0.5, 0.0, 0.0, 0.0]);
        let b = StateVector::from_iterator([1.0, 0.5, 0.5, 0.0, 0.0, 0.0]);
        let mut tracker = Glac::new(scene(), GlacParams::default()).unwrap();
        tracker.hypotheses.push(a, p, 0.0);
        tracker.hypotheses.push(b, p, 0.2f64.ln());
        tracker.remember(estimate(0.2 * 0.2));
        assert!(!tracker.resolved_once, "a competitor with a fifth of the weight, 0.5 m away");
        tracker.remember(estimate(0.01 * 0.01));
        assert!(tracker.resolved_once, "a 1 cm sigma is resolved");
        let mut tracker = Glac::new(scene(), GlacParams::default()).unwrap();
        tracker.hypotheses.push(a, p, 0.0);
        tracker.hypotheses.push(b, p, 1e-5f64.ln());
        tracker.remember(estimate(0.2 * 0.2));
        assert!(tracker.resolved_once, "a newcomer at 1e-5 leaves the plain spread at 1.6 mm");
    }

    /// A jump of the reported trajectory beyond what its speed explains is
    /// a switch; following a moving tag is not.
    #[test]
    fn a_jump_to_another_candidate_is_a_switch() {
        let mut tracker = Glac::new(scene(), GlacParams::default()).unwrap();
        let moving = StateVector::from_iterator([0.53, 0.5, 0.5, 0.3, 0.0, 0.0]);
        tracker.hypotheses.push(moving, StateMatrix::identity() * 1e-6, 0.0);
        tracker.last_good = Some((1.0, Vector3::new(0.5, 0.5, 0.5), Matrix3::identity() * 1e-6));
        tracker.note_switch(1.1); // 3 cm in 0.1 s at 0.3 m/s
        assert_eq!(tracker.switched_s, f64::NEG_INFINITY);
        tracker.hypotheses.items[0].x[0][0] = 0.66; // 16 cm: another candidate
        tracker.note_switch(1.1);
        assert_eq!(tracker.switched_s, 1.1);
    }

    /// Re-seeding brings back a true trajectory the hypotheses lost: with
    /// only a wrong hypothesis left (the truth shifted 8 cm), a search over
    /// the recent reads adds the truth at the re-seeding weight, and the
    /// reads that follow make it win.
    #[test]
    fn reseeding_recovers_a_lost_true_trajectory() {
        let scene = scene();
        let all = reads(&scene, 240);
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let truth = |t: f64| Vector3::new(0.6 + 0.1 * t, 0.3 + 0.05 * t, 0.0);
        let split = 90; // 3 s
        for m in &all[..split] {
            tracker.step(&Measurement::Phase(*m));
        }
        // Keep one hypothesis and move it off the truth.
        let keep = tracker.hypotheses.best().unwrap();
        tracker.hypotheses.retain(|i| i == keep);
        tracker.hypotheses.items[0].x[0][0] += 0.08;
        tracker.hypotheses.items[0].x[1][0] += 0.08;
        tracker.hypotheses.items[0].log_likelihood = 0.0;
        let now = all[split - 1].time_s;
        let before = tracker.stats().reseeds;
        tracker.reseed(now);
        assert_eq!(tracker.stats().reseeds, before + 1);
        let t = |i: usize| Vector3::new(tracker.hypotheses.items[i].x[0][0], tracker.hypotheses.items[i].x[0][1], 0.0);
        let near: Vec<usize> = (0..tracker.hypotheses.len()).filter(|&i| (t(i) - truth(now)).norm() < 0.01).collect();
        assert!(!near.is_empty(), "the search over the recent reads finds the truth again");
        let weight: f64 = near.iter().map(|&i| tracker.hypotheses.items[i].log_likelihood.exp()).sum();
        assert!(weight < 10.0 * RESEED_WEIGHT, "a newcomer joins at a small weight, got {weight}");
        let mut last = None;
        for m in &all[split..] {
            last = tracker.step(&Measurement::Phase(*m)).map(|e| (m.time_s, e));
        }
        let (t_end, e) = last.unwrap();
        assert!((Vector3::from(e.position) - truth(t_end)).norm() < 0.01, "the true trajectory wins back");
    }

    /// On the paper's layout, even a tracker holding only a twin of the
    /// truth reports a covariance that covers the truth (within 3 sigma on
    /// every axis); hopping over calibrated channels takes the twins away.
    #[test]
    fn twins_of_three_antennas_on_a_line_widen_the_sigma() {
        let pos = [[0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.8, 0.0], [0.8, 0.8, 0.0]];
        let antennas = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], p[2]), phase_offset_rad: 0.0, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(-0.5, -0.5, 0.05), max: Vector3::new(1.5, 1.5, 2.0) };
        let channel = vec![crate::scene::ChannelOffset { frequency_hz: 915e6, phase_offset_rad: 0.0 }];
        let scene = Scene::new(3, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, Some(region), channel).unwrap();
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let truth = Vector3::new(0.45, 0.35, 0.7);
        let layout = tracker.line_layout.clone().expect("the paper's layout has a line");
        let twin = line_twins(&layout, &truth, scene.candidate_spacing(915e6), 1, |q| q.z > 0.05)[0];
        tracker.last_frequency_hz = 915e6;
        tracker.first_frequency_hz = 915e6;
        let x = StateVector::from_iterator([twin.x, twin.y, twin.z, 0.0, 0.0, 0.0]);
        tracker.hypotheses.push(x, StateMatrix::identity() * 1e-6, 0.0);
        let e = tracker.best_estimate(1.0).unwrap();
        let sigma = e.position_sigma();
        for k in 0..3 {
            assert!((truth[k] - twin[k]).abs() <= 3.0 * sigma[k], "axis {k}: {} vs sigma {}", truth[k] - twin[k], sigma[k]);
        }
        tracker.hopped = true;
        assert!(tracker.best_estimate(1.0).unwrap().position_sigma()[0] < 0.01, "calibrated hopping fixes the integer");
    }

    /// Reads of a tag moving in front of a wall (Γ = 0.3, 0.6 m behind the
    /// work area), generated with the apparent range: the tracker told of
    /// the wall follows the tag; the one that is not carries the ripple as
    /// a bias of millimetres to a centimetre.
    #[test]
    fn a_known_wall_removes_its_ripple_from_the_track() {
        use crate::scene::Reflector;
        let wall = vec![Reflector::Plane { point: Vector3::new(1.6, 0.0, 0.0), normal: Vector3::new(-1.0, 0.0, 0.0), coefficient: 0.3 }];
        let pos = [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.8, 0.0], [0.8, 0.8, 0.4]];
        let antennas: Vec<Antenna> = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], p[2]), phase_offset_rad: 0.0, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(-0.2, -0.2, 0.1), max: Vector3::new(1.2, 1.2, 1.4) };
        let plain = Scene::new(3, 0.0, 1.0, std::f64::consts::TAU, 0.05, antennas, Some(region), vec![]).unwrap();
        let walled = plain.clone().with_reflectors(wall).unwrap();
        let truth = |t: f64| Vector3::new(0.45 + 0.25 * (0.6 * t).cos(), 0.4 + 0.25 * (0.6 * t).sin(), 0.6 + 0.1 * (0.9 * t).sin());
        let frequency = 915.25e6;
        let k = 2.0 * std::f64::consts::PI * frequency / SPEED_OF_LIGHT;
        let paths: Vec<Vec<ReflectedPath>> = walled.antennas.iter().map(|a| reflected_paths(&a.position, &walled.reflectors)).collect();
        let mut state = 11u64;
        let reads: Vec<PhaseRead> = (0..600)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let noise = 0.08 * (((state >> 11) as f64) / (1u64 << 53) as f64 - 0.5);
                let t = 0.033 * i as f64;
                let a = i % 4;
                let p = truth(t);
                let x = StateVector::from_iterator([p.x, p.y, p.z, 0.0, 0.0, 0.0]);
                let (d, _) = apparent_range(&x, &walled.antennas[a].position, &paths[a], k, 3, false);
                PhaseRead { time_s: t, antenna: a, frequency_hz: frequency, phase_rad: walled.ideal_phase(a, frequency, d) + noise }
            })
            .collect();
        // RMS error after 10 s, and the number of estimates it rests on.
        let rms = |scene: &Scene, inference: Inference| {
            let mut tracker = Glac::new(scene.clone(), GlacParams { inference, ..GlacParams::default() }).unwrap();
            let errors: Vec<f64> = reads
                .iter()
                .filter_map(|m| tracker.step(&Measurement::Phase(*m)).map(|e| (m.time_s, e)))
                .filter(|(t, _)| *t > 10.0)
                .map(|(t, e)| (Vector3::new(e.position[0], e.position[1], e.position[2]) - truth(t)).norm_squared())
                .collect();
            ((errors.iter().sum::<f64>() / errors.len().max(1) as f64).sqrt(), errors.len())
        };
        let fast = GlacParams::default().inference;
        let ((with, n_with), (without, n_without)) = (rms(&walled, fast), rms(&plain, fast));
        assert!(n_with > 100 && n_without > 100, "{n_with} {n_without}");
        assert!(with < 0.003, "told of the wall: {with} m RMS");
        assert!(without > 2.0 * with, "not told: {without} m RMS against {with}");
        // The synchronous scheme (one estimate per group of four reads)
        // trilaterates the candidates less the excess.
        let ((with, n_with), (without, n_without)) = (rms(&walled, Inference::Synchronous), rms(&plain, Inference::Synchronous));
        assert!(n_with > 50 && n_without > 50, "{n_with} {n_without}");
        assert!(with < 0.02, "synchronous, told of the wall: {with} m RMS");
        assert!(without > 1.5 * with, "synchronous, not told: {without} m RMS against {with}");
    }

    #[test]
    fn silent_until_initialised_then_causal_estimates() {
        let scene = scene();
        let mut tracker = Glac::new(scene.clone(), GlacParams::default()).unwrap();
        let all = reads(&scene, 60);
        let first = all.iter().position(|m| tracker.step(&Measurement::Phase(*m)).is_some()).unwrap();
        assert!(all[first].time_s >= GlacParams::default().init_window_s);
        assert_eq!(tracker.stats().initialising as usize, first + 1);
        tracker.reset();
        assert_eq!(tracker.hypothesis_count(), 0);
    }

    /// A mod-π 3D recording (a slow 3D loop, 30 reads/s, σφ ≈ 0.05 rad):
    /// the initial search leaves thousands of hypotheses.
    fn mod_pi_3d() -> (Scene, Vec<PhaseRead>, impl Fn(f64) -> Vector3<f64>) {
        let pos = [[0.0, 0.0], [0.3, 0.0], [0.0, 0.8], [0.8, 0.8]];
        let antennas = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: 0.9 * i as f64, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(-0.1, -0.3, 0.05), max: Vector3::new(1.2, 1.2, 1.2) };
        let scene = Scene::new(3, 0.0, 1.0, std::f64::consts::PI, 0.05, antennas, Some(region), vec![]).unwrap();
        let truth = |t: f64| {
            let a = 0.5 * t;
            Vector3::new(0.45 + 0.2 * a.cos(), 0.4 + 0.2 * a.sin(), 0.6 + 0.1 * a.sin())
        };
        let mut state = 7u64;
        let reads = (0..240)
            .map(|k| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let noise = 0.1 * (((state >> 11) as f64) / (1u64 << 53) as f64 - 0.5);
                let t = 0.033 * k as f64;
                let a = k % 4;
                let d = (truth(t) - scene.antennas[a].position).norm();
                let phase = (scene.ideal_phase(a, 915.25e6, d) + noise).rem_euclid(std::f64::consts::PI);
                PhaseRead { time_s: t, antenna: a, frequency_hz: 915.25e6, phase_rad: phase }
            })
            .collect();
        (scene, reads, truth)
    }

    /// The read budget bounds the hypotheses expanded (and initial
    /// candidates scored) per read on a mod-π 3D recording, whose search,
    /// replay and re-seeding would take many budgets at once; the work is
    /// carried, not dropped. Without re-seeding (which runs in the
    /// background, so its candidates join later) every estimate, once
    /// caught up, is the one an unlimited budget gives.
    #[test]
    fn the_read_budget_bounds_each_read_and_keeps_the_result() {
        let (scene, reads, truth) = mod_pi_3d();
        let run = |read_budget: usize, reseed_interval_s: f64| {
            let params = GlacParams { read_budget, reseed_interval_s, ..GlacParams::default() };
            let mut tracker = Glac::new(scene.clone(), params).unwrap();
            let estimates: Vec<Option<Estimate>> = reads.iter().map(|m| tracker.step(&Measurement::Phase(*m))).collect();
            (tracker.stats(), estimates)
        };
        let count = |e: &[Option<Estimate>]| e.iter().filter(|e| e.is_some()).count();
        let budget = 2_000;
        for reseed_interval_s in [0.0, 1.0] {
            let (bounded, late) = run(budget, reseed_interval_s);
            let (unbounded, prompt) = run(usize::MAX, reseed_interval_s);
            assert!(bounded.max_expanded_per_read <= budget as u64, "{bounded:?}");
            assert!(unbounded.max_expanded_per_read > 4 * budget as u64, "the recording must need the budget: {unbounded:?}");
            assert!(bounded.max_hypotheses > budget as u64, "a step through more hypotheses than the budget spans reads");
            assert!(count(&late) > 100 && count(&late) < count(&prompt), "{} of {}", count(&late), count(&prompt));
            let error = |e: &[Option<Estimate>]| {
                let last = e.last().unwrap().as_ref().expect("caught up by the end");
                (Vector3::from(last.position) - truth(reads.last().unwrap().time_s)).norm()
            };
            assert!(error(&late) <= error(&prompt) + 0.005);
            if reseed_interval_s == 0.0 {
                assert_eq!(bounded.filter_updates, unbounded.filter_updates, "the same work, spread");
                for (k, (a, b)) in late.iter().zip(&prompt).enumerate() {
                    if let (Some(a), Some(b)) = (a, b) {
                        assert_eq!((a.position, a.covariance), (b.position, b.covariance), "read {k}");
                    }
                }
            }
        }
    }

    #[test]
    fn naive_inference_respects_the_cap() {
        let scene = scene();
        let params = GlacParams { inference: Inference::Naive, max_hypotheses: 500, ..GlacParams::default() };
        let mut tracker = Glac::new(scene.clone(), params).unwrap();
        for m in reads(&scene, 20) {
            tracker.step(&Measurement::Phase(m));
            assert!(tracker.hypothesis_count() <= 500);
        }
        assert!(tracker.stats().max_hypotheses >= 100, "naive inference should branch");
    }

    #[test]
    fn rejects_invalid_parameters() {
        let bad = GlacParams { quick_stop: 1.5, ..GlacParams::default() };
        assert!(Glac::new(scene(), bad).is_err());
        let bad = GlacParams { motion: MotionModel::ConstantVelocity { q: -1.0 }, ..GlacParams::default() };
        assert!(Glac::new(scene(), bad).is_err());
        let bad = GlacParams { phase_wander_rad: -0.1, ..GlacParams::default() };
        assert!(Glac::new(scene(), bad).is_err());
        let bad = GlacParams { phase_wander_s: 0.0, ..GlacParams::default() };
        assert!(Glac::new(scene(), bad).is_err());
    }

    #[test]
    fn correlated_error_weighs_by_its_long_run_variance() {
        assert_eq!(correlated_variance_factor(0.0), 1.0);
        assert!((correlated_variance_factor(0.5) - 3.0).abs() < 1e-12);
        assert_eq!(correlated_variance_factor(1.0), 1e4);
        // The factor is exactly the variance of a sum of AR(1) errors over
        // white errors, n → ∞: check it by simulating a long AR(1) chain.
        let (rho, n, blocks) = (0.7_f64, 200usize, 400usize);
        let mut state = 12345u64;
        let mut gaussian = || {
            // Box–Muller from a 64-bit LCG: deterministic, no dependency.
            let mut uniform = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (u1, u2) = (uniform(), uniform());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let mut e = gaussian();
        let mut sums = Vec::with_capacity(blocks);
        for _ in 0..blocks {
            let mut sum = 0.0;
            for _ in 0..n {
                e = rho * e + (1.0 - rho * rho).sqrt() * gaussian();
                sum += e;
            }
            sums.push(sum);
        }
        let variance = sums.iter().map(|s| s * s).sum::<f64>() / blocks as f64 / n as f64;
        let expected = correlated_variance_factor(rho);
        assert!((variance / expected - 1.0).abs() < 0.2, "simulated {variance}, factor {expected}");
    }

    #[test]
    fn range_noise_grows_as_an_antenna_is_read_again_sooner() {
        let white = Glac::new(scene(), GlacParams::default()).unwrap();
        let params = GlacParams { phase_noise_rad: Some(0.015), phase_wander_rad: 0.12, ..GlacParams::default() };
        let wander = Glac::new(scene(), params).unwrap();
        let f = 915.25e6;
        let to_range = Scene::range_per_radian(f);
        // No wander: the scene's white noise, whatever the interval.
        for dt in [0.01, 0.13, f64::INFINITY] {
            assert!((white.range_variance_after(f, dt) - (0.1 * to_range).powi(2)).abs() < 1e-15);
        }
        // First read of an antenna: the stationary variance.
        let stationary = (0.015f64.powi(2) + 0.12f64.powi(2)) * to_range * to_range;
        assert!((wander.range_variance_after(f, f64::INFINITY) - stationary).abs() < 1e-15);
        // 4 antennas at 30 reads/s (0.133 s apart), τ = 0.5 s: σ_φ ≈ 0.33 rad.
        let sigma = wander.range_variance_after(f, 0.133).sqrt() / to_range;
        assert!((0.30..0.36).contains(&sigma), "{sigma}");
        assert!(wander.range_variance_after(f, 0.05) > wander.range_variance_after(f, 0.133));
    }
}
