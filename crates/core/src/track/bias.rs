//! A slow phase bias per antenna, as an AR(1) state (GLAC's `bias_state`).
//!
//! Real readers show, beyond their read-to-read noise, a bias that wanders
//! over ~0.5 s (and calibration residuals, multipath that changes as the
//! tag moves). Per antenna a and hypothesis, with ρ = exp(−Δt/τ_b) since
//! the antenna's previous read (ρ = 0 on its first: the stationary prior):
//!
//! * predict: `b ← ρ b`, `V ← ρ² V + σ_b² (1 − ρ²)`, plus `σ_h²` when the
//!   read is on another carrier than the antenna's previous one (a hopping
//!   reader: the channel's calibration residual and its multipath phase are
//!   that channel's own, so that share is drawn afresh);
//! * the reading then predicts range + b, with variance H P Hᵀ + V + R;
//! * update, after the state's: `b ← b + V/S · ν`, `V ← V − V²/S`, with ν
//!   and S the reading's innovation and its variance.
//!
//! The cross-covariance of bias and state that an exact joint filter would
//! carry is dropped (a decoupled scalar filter per antenna): that overstates
//! the next innovation's variance a little (conservative) and keeps a step
//! O(1) in the number of antennas.

/// When, and on which carrier, an antenna's bias states were last
/// propagated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasClock {
    /// Seconds; −∞: not yet (the next read starts the states).
    pub time_s: f64,
    /// Hz.
    pub frequency_hz: f64,
}

impl BiasClock {
    /// No read yet.
    pub const UNSET: BiasClock = BiasClock { time_s: f64::NEG_INFINITY, frequency_hz: f64::NAN };
}

/// One antenna's bias prediction for one hypothesis at the reading's time:
/// mean (m) and variance (m²).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BiasPrediction {
    pub mean: f64,
    pub variance: f64,
}

impl BiasPrediction {
    /// The posterior `(mean, variance)` (m, m²) after a reading whose
    /// innovation against range + bias is `innovation` (m), with variance
    /// `innovation_variance` (S, m²).
    pub fn update(&self, innovation: f64, innovation_variance: f64) -> (f64, f64) {
        if !(innovation_variance > 0.0) {
            return (self.mean, self.variance);
        }
        let gain = self.variance / innovation_variance;
        (self.mean + gain * innovation, self.variance * (1.0 - gain))
    }
}

/// What one reading means for the bias states of its antenna: the AR(1)
/// coefficient and drive since that antenna's previous read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasStep {
    /// Antenna index, if it has a bias state.
    pub antenna: Option<usize>,
    /// ρ = exp(−Δt/τ_b).
    pub rho: f64,
    /// σ_b² (1 − ρ²), m².
    pub drive: f64,
}

impl BiasStep {
    /// No bias state for this reading.
    pub const NONE: BiasStep = BiasStep { antenna: None, rho: 0.0, drive: 0.0 };

    /// The step for antenna `antenna` read `interval_s` after its previous
    /// read (∞ if none), stationary variance `stationary_m2` (m²) and
    /// correlation time `time_s` (s).
    pub fn new(antenna: usize, interval_s: f64, stationary_m2: f64, time_s: f64) -> Self {
        let rho = if interval_s.is_finite() { (-interval_s.max(0.0) / time_s).exp() } else { 0.0 };
        Self { antenna: Some(antenna), rho, drive: stationary_m2 * (1.0 - rho * rho) }
    }

    /// The same step with `jump_m2` (m²) more drive: a share of the bias
    /// drawn afresh (on a new carrier), independent of the rest.
    pub fn with_jump(self, jump_m2: f64) -> Self {
        Self { drive: self.drive + jump_m2, ..self }
    }

    /// The prediction from a hypothesis' last `(mean, variance)`.
    pub fn predict(&self, mean: f64, variance: f64) -> BiasPrediction {
        BiasPrediction { mean: self.rho * mean, variance: self.rho * self.rho * variance + self.drive }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_read_is_the_stationary_prior_and_later_reads_decay() {
        let first = BiasStep::new(2, f64::INFINITY, 4e-6, 0.5);
        assert_eq!(first.predict(1e-3, 1e-6), BiasPrediction { mean: 0.0, variance: 4e-6 });
        let next = BiasStep::new(2, 0.25, 4e-6, 0.5);
        let rho = (-0.5f64).exp();
        let b = next.predict(1e-3, 1e-6);
        assert!((b.mean - rho * 1e-3).abs() < 1e-18);
        assert!((b.variance - (rho * rho * 1e-6 + 4e-6 * (1.0 - rho * rho))).abs() < 1e-18);
    }

    /// The stationary variance is a fixed point of the prediction.
    #[test]
    fn the_stationary_variance_is_kept() {
        let step = BiasStep::new(0, 0.13, 2e-6, 0.5);
        assert!((step.predict(0.0, 2e-6).variance - 2e-6).abs() < 1e-18);
    }

    /// A jump adds its variance to the drive and leaves ρ alone.
    #[test]
    fn a_jump_adds_independent_variance() {
        let step = BiasStep::new(1, 0.25, 4e-6, 0.5).with_jump(1e-6);
        let plain = BiasStep::new(1, 0.25, 4e-6, 0.5);
        assert_eq!(step.rho, plain.rho);
        assert!((step.predict(2e-3, 1e-6).variance - (plain.predict(2e-3, 1e-6).variance + 1e-6)).abs() < 1e-18);
        assert_eq!(step.predict(2e-3, 1e-6).mean, plain.predict(2e-3, 1e-6).mean);
    }

    /// The update is the scalar Kalman update with gain V/S.
    #[test]
    fn update_takes_its_share_of_the_innovation() {
        let b = BiasPrediction { mean: 0.001, variance: 1e-6 };
        let (mean, variance) = b.update(0.004, 4e-6);
        assert!((mean - (0.001 + 0.25 * 0.004)).abs() < 1e-15);
        assert!((variance - 0.75e-6).abs() < 1e-18);
        assert_eq!(b.update(0.004, 0.0), (0.001, 1e-6));
    }
}
