//! Trackers: one file per method, all behind the same causal interface.
//!
//! Contract: a [`Tracker`] consumes one [`Measurement`] at a time, in time
//! order, and returns an [`Estimate`] once it has committed to one. The
//! estimate at time t uses only measurements at or before t. Batch use is a
//! loop over `step` ([`run`]); nothing else is special-cased. Measurements a
//! tracker declines (out of order, gated outliers, unknown antenna) are
//! counted in [`TrackerStats`], never dropped silently.
//!
//! Registering a method: add its file (the tracker, its `build`
//! constructor, its tests) and its entry in [`registry::METHODS`] (name,
//! pipeline, input, parameter table, constructor, description); [`make`]
//! finds it there, and the file may be declared next to that entry (see
//! [`registry`]). Variants of a tracker are named constructors in
//! [`variants`]. Parameters: [`glac_params`], [`turbotrack_params`].

pub mod bistatic;
mod bias;
mod candidates;
mod ellipse_intersection;
pub mod far_lobes;
mod glac;
mod glac_bank;
pub mod glac_params;
mod initial;
mod key_hash;
mod line_twins;
mod read_budget;
pub mod resting_average;
pub mod lobes;
pub mod registry;
mod rfind;
mod turbotrack;
pub mod turbotrack_params;
mod variants;

pub use candidates::nearest_candidate;
pub use glac::{Glac, GlacParams, Inference, Likelihood};
pub use initial::{initial_hypotheses, InitialHypothesis, InitialState};
pub use ellipse_intersection::EllipseIntersection;
pub use rfind::RFind;
pub use turbotrack::{InitialSampling, Proposal, TurboTrack, TurboTrackParams, WidebandLikelihood};
pub use variants::GAUSSIAN_PF_SIGMA_M;

use crate::error::{Error, Result};
use nalgebra::Complex;

use crate::model::StateMatrix;
use crate::scene::Scene;

/// One phase reading from one antenna (a row of reads.csv for one tag).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseRead {
    /// Read time on the reader clock, seconds.
    pub time_s: f64,
    /// Index into `Scene::antennas` (not the port id).
    pub antenna: usize,
    /// Carrier frequency of this read, Hz.
    pub frequency_hz: f64,
    /// Reported phase in [0, P), radians.
    pub phase_rad: f64,
}

/// One wideband frame of an SDR localization helper: the tag channel
/// estimated from a single reply at every subcarrier of every receive
/// antenna (the rows of frames.csv with one `time_s`, docs/formats.md §5).
///
/// After calibration one path of length `d = |tx − tag| + |tag − rx|`
/// (m) contributes `a · exp(−j 2π f d / c)` with `a > 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct WidebandFrame {
    /// Reply time, seconds.
    pub time_s: f64,
    /// Index into `Scene::antennas` of the transmit antenna.
    pub tx: usize,
    /// Index into `Scene::antennas` of each receive antenna, one per channel block.
    pub rx: Vec<usize>,
    /// Subcarrier frequencies, Hz, shared by every receive antenna.
    pub frequencies_hz: Vec<f64>,
    /// Tag channel, row-major `rx.len() × frequencies_hz.len()`:
    /// `h[r * F + k]` is receive antenna `rx[r]` at subcarrier `k`.
    pub h: Vec<Complex<f64>>,
}

/// What a tracker consumes: one reading of one tag. Each method accepts
/// the kinds its hardware produces and counts any other as invalid.
#[derive(Debug, Clone, PartialEq)]
pub enum Measurement {
    /// A COTS reader's phase reading (GLAC).
    Phase(PhaseRead),
    /// A localization helper's wideband frame (TurboTrack).
    Wideband(WidebandFrame),
}

impl Measurement {
    /// Time of the reading, seconds.
    pub fn time_s(&self) -> f64 {
        match self {
            Measurement::Phase(r) => r.time_s,
            Measurement::Wideband(f) => f.time_s,
        }
    }
}

impl From<PhaseRead> for Measurement {
    fn from(r: PhaseRead) -> Self {
        Measurement::Phase(r)
    }
}

impl From<WidebandFrame> for Measurement {
    fn from(f: WidebandFrame) -> Self {
        Measurement::Wideband(f)
    }
}

/// A tracker's output after one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Time of the measurement that produced it, seconds.
    pub time_s: f64,
    /// Position, metres.
    pub position: [f64; 3],
    /// Velocity, m/s (NaN for methods without a velocity state).
    pub velocity: [f64; 3],
    /// State covariance of [p, v] (m², m²/s, m²/s²), row-major 6×6.
    pub covariance: [f64; 36],
    /// Live hypotheses (candidate trajectories) after this step.
    pub hypotheses: usize,
    /// Normalised likelihood of the reported hypothesis, in (0, 1].
    pub weight: f64,
}

impl Estimate {
    pub(crate) fn covariance_from(p: &StateMatrix) -> [f64; 36] {
        let mut c = [0.0; 36];
        for r in 0..6 {
            for k in 0..6 {
                c[r * 6 + k] = p[(r, k)];
            }
        }
        c
    }

    /// An estimate of methods whose state is a position: `covariance` is
    /// its 3×3 covariance (m²); the velocity block stays NaN (unknown).
    pub(crate) fn from_position(
        time_s: f64,
        position: &nalgebra::Vector3<f64>,
        covariance: &nalgebra::Matrix3<f64>,
        velocity: [f64; 3],
        hypotheses: usize,
        weight: f64,
    ) -> Self {
        let mut c = [0.0; 36];
        for r in 0..3 {
            for k in 0..3 {
                c[r * 6 + k] = covariance[(r, k)];
            }
        }
        for k in 3..6 {
            c[k * 6 + k] = f64::NAN;
        }
        Self { time_s, position: [position.x, position.y, position.z], velocity, covariance: c, hypotheses, weight }
    }

    /// 1-sigma position uncertainty per axis, metres.
    pub fn position_sigma(&self) -> [f64; 3] {
        [self.covariance[0].sqrt(), self.covariance[7].sqrt(), self.covariance[14].sqrt()]
    }
}

/// What a tracker did with its input, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackerStats {
    /// Measurements received.
    pub measurements: u64,
    /// Measurements with a time before the previous one (declined).
    pub out_of_order: u64,
    /// Measurements naming an antenna the scene lacks, or non-finite (declined).
    pub invalid: u64,
    /// Measurements the reported hypothesis gated out as outliers
    /// (GLAC's 3σ recovery replaced them by the prediction).
    pub outliers: u64,
    /// Measurements consumed while (re)initialising.
    pub initialising: u64,
    /// Times the tracker started over (all hypotheses died, or a read gap).
    pub reinitialisations: u64,
    /// Largest number of live hypotheses seen.
    pub max_hypotheses: u64,
    /// EKF updates performed (all hypotheses), a measure of work.
    pub filter_updates: u64,
    /// Re-seeding searches run while tracking (GLAC).
    pub reseeds: u64,
    /// Times the particles moved to another lobe because its accumulated
    /// evidence passed the switch level (TurboTrack's lobe test).
    pub lobe_switches: u64,
    /// Most work one read did (GLAC: hypothesis steps plus initial-search
    /// work, in the units of its `read_budget`).
    pub max_expanded_per_read: u64,
}

impl TrackerStats {
    /// Counts a measurement of a kind this method does not consume
    /// (declined as invalid; no estimate).
    pub(crate) fn decline_invalid(&mut self) -> Option<Estimate> {
        self.measurements += 1;
        self.invalid += 1;
        None
    }
}

/// The causal tracking interface every method implements.
pub trait Tracker: Send + Sync {
    /// Folds in one measurement; returns the current estimate once committed.
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate>;
    /// Counters of what happened to the input so far.
    fn stats(&self) -> TrackerStats;
    /// Forgets everything (as if newly created), keeping the counters.
    fn reset(&mut self);
    /// A new tracker of the same method, scene and parameters, in its
    /// initial state, for another tag: it may share with this one what
    /// never changes (GLAC shares the scene and the parameters, so that
    /// thousands of tags read one copy). `None`: build one with [`make`].
    fn fresh(&self) -> Option<Box<dyn Tracker>> {
        None
    }
    /// Starts loading into cache what this tracker's next step reads
    /// ([`crate::prefetch`]); only a hint, so the default does nothing.
    fn prefetch(&self) {}
    /// Live hypotheses: position (m) and normalised log-likelihood each,
    /// for plots like GLAC's Fig. 5. Single-hypothesis methods return one.
    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        Vec::new()
    }
    /// The method's smoothed (backtracked) trajectory so far, as (time s,
    /// position m), oldest first: TurboTrack's MAP trajectory. Methods
    /// that do not revise the past return nothing.
    fn trajectory(&self) -> Vec<(f64, [f64; 3])> {
        Vec::new()
    }
}

pub use registry::METHODS;

/// Every method's parameters; [`make`] uses the block of the named method.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Params {
    pub glac: GlacParams,
    pub turbotrack: TurboTrackParams,
}

impl From<GlacParams> for Params {
    fn from(glac: GlacParams) -> Self {
        Self { glac, ..Default::default() }
    }
}

impl From<TurboTrackParams> for Params {
    fn from(turbotrack: TurboTrackParams) -> Self {
        Self { turbotrack, ..Default::default() }
    }
}

/// Builds a tracker by name with the given parameters: the registry's
/// constructor of that method ([`registry::Method::build`]), which sets
/// the parameters that define a variant on top of `params` (GLAC sec.
/// 5.2.2–5.2.3; TurboTrack thesis §7.2).
pub fn make(name: &str, scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    let build = registry::method(name)?.build.ok_or_else(|| Error::NotInCore(name.to_string()))?;
    build(scene, params)
}

/// Runs a tracker over measurements (time-ordered) and collects estimates.
pub fn run(tracker: &mut dyn Tracker, measurements: &[Measurement]) -> Vec<Estimate> {
    measurements.iter().filter_map(|m| tracker.step(m)).collect()
}
