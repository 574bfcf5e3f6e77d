//! The resting tag's coherent average: a static tag's position from every
//! frame since it came to rest, not from the particles' lineages.
//!
//! While a tag rests, the particle filter's static mode averages it over
//! frames by selection: lineages that explain the frames survive
//! resampling. With N = 100 particles resampling collapses the lineages
//! onto a few ancestors faster than one frame's weak information moves
//! them along a poorly observed direction (a rotation about an in-line row
//! of receivers, seen by the one receiver off the row at about a centimetre
//! per frame at 8 dB), so the cloud settles where its surviving ancestors
//! happen to be, centimetres off for seconds. A Metropolis move of the
//! static particles against the same target was tried and not kept: its
//! random-walk steps follow the chord of the arc and leave the likelihood's
//! ridge (docs/notes/turbotrack-experiments.md).
//!
//! For a tag at rest the frames have a sufficient statistic. With
//! calibrated channels `h_k(f) = a e^{−j 2π f d(x) / c} + noise`, the
//! log-likelihood of frames `1..K` is, up to terms free of `x`,
//! `Σ_k Re(h_k(f) e^{j 2π f d(x)/c}) = Re((Σ_k h_k(f)) e^{j 2π f d(x)/c})`:
//! the frames' coherent average `h̄(f)` carries it at K times one frame's
//! SNR. Its candidates (eq. 5.1 on `h̄`, σ_w floored at the per-frame floor
//! over √K: K frames' product has that floor / √K) are fitted by
//! Gauss–Newton on their teeth nearest the static particles' mean
//! (`lobes::refine_on_teeth`): that fit, with the averaged frame's Gaussian
//! covariance `(Σ_j g_j g_jᵀ / σ_j²)⁻¹`, is the estimate while the tag
//! rests. The average forgets with `α = e^{−Δt/τ}` (`static_average_s` = τ)
//! so a tag creeping by millimetres does not blur it, and starts over when
//! its fit leaves the particles' mode (the tag moves) and on a restart; a
//! lobe switch keeps it (the average is the frames' data, whatever lobe it
//! is fitted on). The lobe stays the filter's: the fit keeps the static
//! mean's teeth and is dropped if it leaves them.

use nalgebra::{Complex, Matrix3, Vector3};

use super::bistatic::{information_covariance, HelperGeometry, Receiver};
use super::WidebandFrame;
use crate::geometry::bistatic_distance;
use crate::model::wideband::{distance_candidates, CandidateParams};
use crate::scene::Scene;

/// The exponentially forgotten coherent average of a resting tag's frames,
/// per receive antenna: `Σ_k α^{t−t_k} h_k / Σ_k α^{t−t_k}`.
#[derive(Debug, Default, Clone)]
pub struct ChannelAverage {
    /// Forgetting time constant τ, s.
    time_constant_s: f64,
    time_s: f64,
    tx: usize,
    frequencies_hz: Vec<f64>,
    /// Receive antennas seen, with their weighted sums (F each) and total weights.
    rx: Vec<usize>,
    sums: Vec<Vec<Complex<f64>>>,
    weights: Vec<f64>,
}

impl ChannelAverage {
    pub fn new(time_constant_s: f64) -> Self {
        Self { time_constant_s, ..Default::default() }
    }

    pub fn clear(&mut self) {
        self.rx.clear();
        self.sums.clear();
        self.weights.clear();
        self.frequencies_hz.clear();
    }

    /// Adds a frame; a frame on other subcarriers or another transmitter
    /// starts the average over.
    pub fn add(&mut self, frame: &WidebandFrame) {
        let f = frame.frequencies_hz.len();
        if f == 0 || frame.h.len() != frame.rx.len() * f {
            return;
        }
        if self.rx.is_empty() || frame.tx != self.tx || frame.frequencies_hz != self.frequencies_hz {
            self.clear();
            self.tx = frame.tx;
            self.frequencies_hz.clone_from(&frame.frequencies_hz);
        } else {
            let decay = (-(frame.time_s - self.time_s).max(0.0) / self.time_constant_s).exp();
            self.sums.iter_mut().flatten().for_each(|h| *h *= decay);
            self.weights.iter_mut().for_each(|w| *w *= decay);
        }
        self.time_s = frame.time_s;
        for (r, &antenna) in frame.rx.iter().enumerate() {
            let slot = match self.rx.iter().position(|&a| a == antenna) {
                Some(slot) => slot,
                None => {
                    self.rx.push(antenna);
                    self.sums.push(vec![Complex::new(0.0, 0.0); f]);
                    self.weights.push(0.0);
                    self.rx.len() - 1
                }
            };
            self.sums[slot].iter_mut().zip(&frame.h[r * f..(r + 1) * f]).for_each(|(s, h)| *s += h);
            self.weights[slot] += 1.0;
        }
    }

    /// The smallest receiver's effective number of frames `Σ_k α^{t−t_k}`.
    pub fn frames(&self) -> f64 {
        self.weights.iter().copied().reduce(f64::min).unwrap_or(0.0)
    }

    /// The averaged frame (time of the newest frame), None when empty.
    pub fn frame(&self) -> Option<WidebandFrame> {
        if self.rx.is_empty() {
            return None;
        }
        let h = self.sums.iter().zip(&self.weights).flat_map(|(sum, w)| sum.iter().map(move |h| h / *w)).collect();
        Some(WidebandFrame { time_s: self.time_s, tx: self.tx, rx: self.rx.clone(), frequencies_hz: self.frequencies_hz.clone(), h })
    }
}

/// Half-width of the path-sum interval searched on the averaged frame around
/// the static mean's path sum, m: the fit needs the tooth nearest that path
/// sum and the envelope's weight of its neighbours (one tooth, 33 cm, each
/// side); a narrower interval is a cheaper candidate extraction, and it runs
/// on every frame at rest.
const SEARCH_M: f64 = 0.35;

/// The averaged frame's receivers: eq. 5.1 on each receiver's averaged
/// channel, within `SEARCH_M` of its path sum at `near`, with σ_w's floor
/// (and a fixed σ_w, if configured) divided by `√frames`. A receiver
/// without candidates is left out.
pub fn averaged_receivers(
    scene: &Scene,
    geometry: &HelperGeometry,
    average: &ChannelAverage,
    candidates: &CandidateParams,
    fixed_sigma_m: Option<f64>,
    near: &Vector3<f64>,
) -> Vec<Receiver> {
    let Some(frame) = average.frame() else { return Vec::new() };
    let shrink = average.frames().max(1.0).sqrt().recip();
    let mut params = candidates.clone();
    params.min_sigma_m *= shrink;
    let f = frame.frequencies_hz.len();
    let mut receivers = Vec::with_capacity(frame.rx.len());
    for (r, &antenna) in frame.rx.iter().enumerate() {
        let position = scene.antennas[antenna].position;
        let predicted = bistatic_distance(near, &geometry.tx_position, &position).0;
        let (lo, hi) = geometry.bounds[antenna];
        let (lo, hi) = (lo.max(predicted - SEARCH_M), hi.min(predicted + SEARCH_M));
        if let Some(mut c) = distance_candidates(&frame.frequencies_hz, &frame.h[r * f..(r + 1) * f], lo, hi, &params) {
            if let Some(s) = fixed_sigma_m {
                c.sigma_m = s * shrink;
            }
            receivers.push(Receiver { antenna, position, candidates: c });
        }
    }
    receivers
}

/// The Gaussian posterior covariance of one frame's receivers at `p`, m²:
/// `(Σ_j g_j g_jᵀ / σ_j²)⁻¹` (planar scenes: the x–y block, z left at 0).
/// None when the geometry is singular there.
pub fn frame_covariance(geometry: &HelperGeometry, receivers: &[Receiver], p: &Vector3<f64>) -> Option<Matrix3<f64>> {
    let planar = geometry.dimensions == 2;
    let mut information = Matrix3::zeros();
    for rx in receivers {
        let (_, mut g) = bistatic_distance(p, &geometry.tx_position, &rx.position);
        if planar {
            g.z = 0.0;
        }
        information += g * g.transpose() / (rx.candidates.sigma_m * rx.candidates.sigma_m);
    }
    information_covariance(&information, planar)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(time_s: f64, value: f64) -> WidebandFrame {
        WidebandFrame { time_s, tx: 0, rx: vec![1], frequencies_hz: vec![9e8, 9.1e8], h: vec![Complex::new(value, 0.0); 2] }
    }

    /// The average of frames is their weighted mean, the older ones
    /// forgotten by `e^{−Δt/τ}`; another subcarrier set starts it over.
    #[test]
    fn channel_average_forgets_old_frames() {
        let mut average = ChannelAverage::new(1.0);
        assert!(average.frame().is_none());
        assert_eq!(average.frames(), 0.0);
        average.add(&frame(0.0, 1.0));
        average.add(&frame(1.0, 2.0));
        let alpha = (-1.0f64).exp();
        let expected = (alpha * 1.0 + 2.0) / (alpha + 1.0);
        let a = average.frame().unwrap();
        assert!((a.h[0].re - expected).abs() < 1e-12);
        assert!((average.frames() - (1.0 + alpha)).abs() < 1e-12);
        let mut other = frame(2.0, 5.0);
        other.frequencies_hz = vec![9e8, 9.2e8];
        average.add(&other);
        assert_eq!(average.frames(), 1.0);
        assert_eq!(average.frame().unwrap().h[0].re, 5.0);
    }

    /// The covariance is the inverse of the stacked gradients' information:
    /// four receivers around the tag, 3 mm each, give millimetres.
    #[test]
    fn frame_covariance_inverts_the_information() {
        use crate::model::wideband::Candidates;
        let geometry = HelperGeometry { tx: 0, tx_position: Vector3::new(0.0, 0.0, 0.0), bounds: vec![], dimensions: 3, plane_z: 0.0 };
        let candidates = Candidates { distances_m: vec![2.0], weights: vec![1.0], spacing_m: 0.33, sigma_m: 0.003, best: 0, residual_coherence: 0.0 };
        let at = |x: f64, y: f64, z: f64| Receiver { antenna: 1, position: Vector3::new(x, y, z), candidates: candidates.clone() };
        let receivers = vec![at(1.0, 0.0, 0.0), at(0.0, 1.0, 0.0), at(-1.0, 0.0, 0.0), at(0.0, 0.0, 1.0)];
        let p = Vector3::new(0.3, 0.8, 0.5);
        let c = frame_covariance(&geometry, &receivers, &p).unwrap();
        let mut information = Matrix3::zeros();
        for rx in &receivers {
            let g = bistatic_distance(&p, &geometry.tx_position, &rx.position).1;
            information += g * g.transpose() / 0.003f64.powi(2);
        }
        assert!((c * information - Matrix3::identity()).norm() < 1e-9);
        assert!(c.diagonal().iter().all(|v| v.sqrt() < 0.02));
    }
}
