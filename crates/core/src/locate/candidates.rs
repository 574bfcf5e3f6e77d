//! One tag's phase candidates: search, weights and covariances.

use nalgebra::{Matrix3, Vector3};

use super::hop_centre::{infinite, invert};
use super::{hop_centre, search, PhaseReads};

/// 4π/c, s/m: k = m s (4π/c) f.
const FOUR_PI_OVER_C: f64 = 4.0 * std::f64::consts::PI / crate::scene::SPEED_OF_LIGHT;

/// The choices behind the candidates (Python `scattertrack.locate` holds the values).
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Weights ∝ exp(Δℓ / T): correlated phase errors overcount evidence.
    pub temperature: f64,
    /// Per-antenna phase bias left after calibration, 1-sigma rad.
    pub bias_sigma_rad: f64,
    /// Reads of one antenna and channel within this long (s) count as one
    /// independent error (real readers' errors wander over about 0.5 s).
    pub correlation_s: f64,
    /// Candidates kept before the Python side lists the likeliest few.
    pub max_candidates: usize,
    /// Candidates below this weight are dropped.
    pub min_weight: f64,
    /// Carriers spread (std) at least this wide (Hz), on ≥ 4 channels,
    /// range by frequency diversity, which bounds the search box.
    pub hopping_spread_hz: f64,
    /// Grid points at most.
    pub max_points: usize,
}

/// One candidate position.
#[derive(Debug, Clone, Copy)]
pub struct Candidate {
    /// m.
    pub position: Vector3<f64>,
    /// m², zero beyond the scene's axes.
    pub covariance: Matrix3<f64>,
    /// Sums to 1 over a tag's candidates.
    pub weight: f64,
    /// R at the position.
    pub coherence: f64,
}

/// The tag's candidates, best first (empty when nothing fits the box).
///
/// * **Box**: hopping reads ([`Settings::hopping_spread_hz`]) search the
///   carrier's lattice near the hop-range position ([`hop_centre`]),
///   ±3σ each way, at least half a lattice step and at most 0.5 m; other
///   reads search the whole region `[low, high]`.
/// * **Weights**: with σ = √(−2 ln R̂) the phase noise the best fit shows
///   (von Mises: R ≈ e^{−σ²/2}) and N the independent reads, a candidate's
///   log-likelihood is N R / σ² (up to a constant), tempered by T.
/// * **Covariance**: the Fisher covariance σ² (J̃ᵀJ̃)⁻¹ (J̃ the Jacobian
///   k u centred over reads: the tag's offset is a nuisance), scaled by
///   n / N for the correlated reads, plus σ_b² / k̄² (UᵀU)⁻¹, the consider
///   covariance of a per-antenna bias σ_b over the antennas' unit vectors U.
///
/// Every step but the count of independent reads runs on the reads
/// summed per antenna and channel ([`PhaseReads::grouped`]).
pub fn phase_candidates(single: &PhaseReads, time_s: &[f64], low: Vector3<f64>, high: Vector3<f64>, axes: usize, settings: &Settings) -> Vec<Candidate> {
    if single.z.is_empty() {
        return Vec::new();
    }
    let independent = independent_reads(single, time_s, settings.correlation_s);
    let grouped = single.grouped();
    let reads = &grouped.reads(single);
    let n = reads.total();
    let mean_k = (0..reads.z.len()).map(|i| reads.count(i) * reads.k[i].abs()).sum::<f64>() / n;
    let spacing = 2.0 * std::f64::consts::PI / mean_k;
    let spread_hz = ((0..reads.z.len()).map(|i| reads.count(i) * (reads.k[i].abs() - mean_k).powi(2)).sum::<f64>() / n).sqrt() / FOUR_PI_OVER_C;
    let mut channels: Vec<i64> = reads.k.iter().map(|k| (k.abs() * 1e6).round() as i64).collect();
    channels.sort_unstable();
    channels.dedup();
    let (mut box_low, mut box_high) = (low, high);
    if spread_hz >= settings.hopping_spread_hz && channels.len() >= 4 {
        if let Some((centre, coarse)) = hop_centre(reads, &low, &high, axes).filter(|(_, c)| c.iter().all(|v| v.is_finite())) {
            for axis in 0..axes {
                let half = (3.0 * coarse[(axis, axis)].max(0.0).sqrt()).max(0.5 * spacing).min(0.5);
                box_low[axis] = (centre[axis] - half).max(low[axis] - 0.05);
                box_high[axis] = (centre[axis] + half).min(high[axis] + 0.05);
            }
            for axis in axes..3 {
                box_low[axis] = centre[axis].max(low[axis] - 0.05);
                box_high[axis] = centre[axis].min(high[axis] + 0.05);
            }
        }
    }
    // ℓ per unit of coherence at the best fit's noise.
    let kappa_n = |best_r: f64| independent as f64 / (-2.0 * best_r.max(1e-6).ln()).max(1e-6);
    // Seeds whose weight would be below min_weight e⁻⁵ are not refined
    // (a 2·10⁻⁴ coherence margin covers the tables' error, ≤ 10⁻⁴, and the last climb).
    let cut = (1.0 / settings.min_weight).ln() + 5.0;
    let polish = |best: f64, r: f64| kappa_n(best) * (best - r - 2e-4) / settings.temperature <= cut;
    let found = search(reads, box_low, box_high, axes, settings.max_points, 4 * settings.max_candidates, &polish);
    let Some(&(_, best_r)) = found.first() else { return Vec::new() };
    let sigma = (-2.0 * best_r.max(1e-6).ln()).max(1e-6).sqrt();
    let kappa_n = kappa_n(best_r);
    let weights: Vec<f64> = found.iter().map(|(_, r)| (kappa_n * (r - best_r) / settings.temperature).exp()).collect();
    let total: f64 = weights.iter().sum();
    let correlation_scale = n / independent.max(1) as f64;
    let mut candidates: Vec<Candidate> = found
        .iter()
        .zip(&weights)
        .filter(|(_, w)| *w / total >= settings.min_weight)
        .map(|(&(position, coherence), w)| {
            let covariance = fisher_covariance(reads, &position, sigma, axes) * correlation_scale + bias_covariance(reads, &position, mean_k, settings.bias_sigma_rad, axes);
            Candidate { position, covariance, weight: *w, coherence }
        })
        .collect();
    let kept: f64 = candidates.iter().map(|c| c.weight).sum();
    for c in &mut candidates {
        c.weight /= kept;
    }
    candidates
}

/// Reads that carry independent errors: per antenna and channel, one per `correlation_s`.
fn independent_reads(reads: &PhaseReads, time_s: &[f64], correlation_s: f64) -> usize {
    let mut keys: Vec<(usize, i64, i64)> =
        (0..reads.z.len()).map(|i| (reads.antenna[i], (reads.k[i] * 1e6).round() as i64, (time_s[i] / correlation_s).floor() as i64)).collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len()
}

/// σ² (J̃ᵀJ̃)⁻¹, J̃ᵢ = kᵢ uᵢ centred over the reads (candidates' docs).
fn fisher_covariance(reads: &PhaseReads, p: &Vector3<f64>, sigma_rad: f64, axes: usize) -> Matrix3<f64> {
    let rows: Vec<Vector3<f64>> = (0..reads.z.len()).map(|i| reads.distance_gradient(i, p).1 * reads.k[i]).collect();
    let mean: Vector3<f64> = rows.iter().enumerate().map(|(i, j)| j * reads.count(i)).sum::<Vector3<f64>>() / reads.total();
    let information: Matrix3<f64> =
        rows.iter().enumerate().map(|(i, j)| reads.count(i) * (j - mean) * (j - mean).transpose()).sum::<Matrix3<f64>>() / (sigma_rad * sigma_rad);
    invert(&information, axes).unwrap_or_else(|| infinite(axes))
}

/// σ_b² / k̄² (UᵀU)⁻¹ over the antennas that read the tag.
fn bias_covariance(reads: &PhaseReads, p: &Vector3<f64>, mean_k: f64, bias_sigma_rad: f64, axes: usize) -> Matrix3<f64> {
    let mut normal = Matrix3::zeros();
    for a in reads.used_anchors() {
        let u = (p - reads.anchors[a]).normalize();
        normal += u * u.transpose();
    }
    invert(&normal, axes).map(|inverse| inverse * (bias_sigma_rad / mean_k).powi(2)).unwrap_or_else(|| infinite(axes))
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    pub(crate) fn settings() -> Settings {
        Settings { temperature: 1.0, bias_sigma_rad: 0.07, correlation_s: 0.5, max_candidates: 5, min_weight: 1e-3, hopping_spread_hz: 2e6, max_points: 100_000 }
    }

    #[test]
    fn hopping_reads_give_one_confident_candidate_at_the_truth() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let time: Vec<f64> = (0..z.len()).map(|i| i as f64 * 0.03).collect();
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let found = phase_candidates(&reads, &time, Vector3::zeros(), Vector3::repeat(1.5), 3, &settings());
        assert!((found[0].position - truth).norm() < 1e-5, "{:?}", found[0]);
        assert!(found[0].weight > 0.99);
        // The bias term alone: (0.07 / 19 rad/m)² times a geometry factor, so mm-scale sigmas.
        let sigma = found[0].covariance.diagonal().map(f64::sqrt);
        assert!(sigma.iter().all(|s| *s > 1e-4 && *s < 0.05), "{sigma:?}");
        assert!((found.iter().map(|c| c.weight).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn one_channel_lists_several_candidates() {
        let anchors = layout();
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &[915.25e6]);
        // Repeat the reads so the fit has some noise-free evidence.
        let time: Vec<f64> = (0..z.len()).map(|i| i as f64).collect();
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let found = phase_candidates(&reads, &time, Vector3::zeros(), Vector3::repeat(1.2), 3, &settings());
        assert!(found.len() > 1, "{}", found.len());
    }

    #[test]
    fn a_declared_wall_puts_the_best_candidate_back_on_the_truth() {
        use super::super::fixtures::{reads_under, wall_paths};
        use super::super::Paths;
        let anchors = layout();
        let truth = Vector3::new(0.9, 0.6, 0.7);
        let paths = wall_paths(&anchors, 0.5);
        // A mod-2π and a mod-π reader (the latter's lattice is twice as dense).
        for multiplier in [1.0, 2.0] {
            let (z, k, antenna) = reads_under(truth, &anchors, &paths, &us_band(), multiplier);
            let time: Vec<f64> = (0..z.len()).map(|i| i as f64 * 0.03).collect();
            let single = PhaseReads::new(&z, &k, &antenna, &anchors);
            let blind = phase_candidates(&single, &time, Vector3::zeros(), Vector3::repeat(1.5), 3, &settings());
            let told = phase_candidates(&single.with_paths(Paths { per_anchor: &paths, phase_multiplier: multiplier }), &time, Vector3::zeros(), Vector3::repeat(1.5), 3, &settings());
            // Without the wall the single-path fit lands off the truth ...
            assert!((blind[0].position - truth).norm() > 2e-3, "{multiplier}: {:?}", blind[0].position - truth);
            // ... with it, on the truth, and alone.
            assert!((told[0].position - truth).norm() < 1e-5, "{multiplier}: {:?}", told[0].position - truth);
            assert!(told[0].weight > 0.99 && told[0].coherence > 0.999999, "{multiplier}: {:?}", told[0]);
        }
    }

    #[test]
    fn independent_reads_bin_by_antenna_channel_and_time() {
        let anchors = layout();
        let z = vec![nalgebra::Complex::new(1.0, 0.0); 4];
        let k = vec![19.0, 19.0, 19.0, 19.1];
        let antenna = vec![0, 0, 1, 0];
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        assert_eq!(independent_reads(&reads, &[0.0, 0.4, 0.1, 0.2], 0.5), 3);
        assert_eq!(independent_reads(&reads, &[0.0, 0.6, 0.1, 0.2], 0.5), 4);
    }
}
