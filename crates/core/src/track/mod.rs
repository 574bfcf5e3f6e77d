//! Trackers: one file per method, all behind the same causal interface.
//!
//! Contract: a [`Tracker`] consumes one [`Measurement`] at a time, in time
//! order, and returns an [`Estimate`] once it has committed to one. The
//! estimate at time t uses only measurements at or before t. Batch use is a
//! loop over `step` ([`run`]); nothing else is special-cased. Measurements a
//! tracker declines (out of order, gated outliers, unknown antenna) are
//! counted in [`TrackerStats`], never dropped silently.
//!
//! Registering a method: add its file, one arm in [`make`], and its tests.

mod candidates;
mod glac;
mod initial;

pub use candidates::nearest_candidate;
pub use glac::{Glac, GlacParams, Inference, Likelihood};
pub use initial::{initial_hypotheses, InitialHypothesis, InitialState};

use crate::error::{Error, Result};
use crate::model::StateMatrix;
use crate::scene::Scene;

/// One phase reading from one antenna (a row of reads.csv for one tag).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Read time on the reader clock, seconds.
    pub time_s: f64,
    /// Index into `Scene::antennas` (not the port id).
    pub antenna: usize,
    /// Carrier frequency of this read, Hz.
    pub frequency_hz: f64,
    /// Reported phase in [0, P), radians.
    pub phase_rad: f64,
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
}

/// The causal tracking interface every method implements.
pub trait Tracker: Send + Sync {
    /// Folds in one measurement; returns the current estimate once committed.
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate>;
    /// Counters of what happened to the input so far.
    fn stats(&self) -> TrackerStats;
    /// Forgets everything (as if newly created), keeping the counters.
    fn reset(&mut self);
    /// Live hypotheses: position (m) and normalised log-likelihood each,
    /// for plots like GLAC's Fig. 5. Single-hypothesis methods return one.
    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        Vec::new()
    }
}

/// Registered method names, for messages and the CLI.
pub const METHODS: &[&str] = &["glac", "glac-no-velocity", "glac-sync", "glac-sync-no-velocity", "glac-naive"];

/// Builds a tracker by name with the given parameters; the variant names
/// set the parameters that define them (GLAC sec. 5.2.2 and 5.2.3) on top
/// of `params`.
pub fn make(name: &str, scene: &Scene, params: &GlacParams) -> Result<Box<dyn Tracker>> {
    let mut p = params.clone();
    match name {
        "glac" => {}
        "glac-no-velocity" => p.motion_model_no_velocity(),
        "glac-sync" => p.inference = Inference::Synchronous,
        "glac-sync-no-velocity" => {
            p.inference = Inference::Synchronous;
            p.motion_model_no_velocity();
        }
        "glac-naive" => p.inference = Inference::Naive,
        _ => return Err(Error::UnknownMethod(name.to_string(), METHODS.join(", "))),
    }
    Ok(Box::new(Glac::new(scene.clone(), p)?))
}

/// Runs a tracker over measurements (time-ordered) and collects estimates.
pub fn run(tracker: &mut dyn Tracker, measurements: &[Measurement]) -> Vec<Estimate> {
    measurements.iter().filter_map(|m| tracker.step(m)).collect()
}
