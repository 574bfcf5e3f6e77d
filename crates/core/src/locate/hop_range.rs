//! One antenna's range from the phase slope across hop channels.

use nalgebra::Complex;

use super::rotation;

/// One antenna's range from its reads over several channels (m, 1-sigma m):
/// a scan at a tenth of the peak width 1/std(k), then Gauss–Newton on the
/// phase slope; σ = σ_φ / (std(k) √n) with σ_φ from the peak's coherence.
/// `count`: reads per entry (groups, [`super::PhaseReads::grouped`]), `None`
/// for single reads. `None` when the reads do not spread in k.
pub fn hop_range(z: &[Complex<f64>], k: &[f64], count: Option<&[f64]>, max_range_m: f64) -> Option<(f64, f64)> {
    let m = z.len();
    let w = |i: usize| count.map_or(1.0, |c| c[i]);
    let n: f64 = (0..m).map(w).sum();
    if n < 3.0 {
        return None;
    }
    let mean_k = (0..m).map(|i| w(i) * k[i]).sum::<f64>() / n;
    let spread = ((0..m).map(|i| w(i) * (k[i] - mean_k).powi(2)).sum::<f64>() / n).sqrt();
    if spread <= 0.0 {
        return None;
    }
    let spectrum = |d: f64| (0..m).map(|i| z[i] * rotation(k[i] * d)).sum::<Complex<f64>>().norm() / n;
    let step = 0.1 / spread;
    let (mut best, mut best_value) = (0.0, f64::NEG_INFINITY);
    let mut d = 0.0;
    while d <= max_range_m + step {
        let v = spectrum(d);
        if v > best_value {
            best = d;
            best_value = v;
        }
        d += step;
    }
    let mut rotated = vec![Complex::new(0.0, 0.0); m];
    for _ in 0..5 {
        let mut sum = Complex::new(0.0, 0.0);
        for i in 0..m {
            rotated[i] = z[i] * rotation(k[i] * best);
            sum += rotated[i];
        }
        let theta = Complex::new(0.0, -sum.arg()).exp();
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..m {
            let c = k[i] - mean_k;
            num += w(i) * c * (rotated[i] * theta).arg();
            den += w(i) * c * c;
        }
        best += num / den;
    }
    let peak = spectrum(best).max(1e-6);
    let sigma_phase = (-2.0 * peak.ln()).max(1e-6).sqrt();
    Some((best, sigma_phase / (spread * n.sqrt())))
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{reads_at, us_band};
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn hop_range_is_the_phase_slope() {
        let anchors = [Vector3::zeros()];
        let (z, k, _) = reads_at(Vector3::new(1.234, 0.0, 0.0), &anchors, &us_band());
        let (d, sigma) = hop_range(&z, &k, None, 5.0).unwrap();
        assert!((d - 1.234).abs() < 1e-6, "{d}");
        assert!(sigma < 1e-3);
        assert!(hop_range(&z[..2], &k[..2], None, 5.0).is_none());
    }
}
