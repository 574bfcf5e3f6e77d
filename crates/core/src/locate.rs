//! A static tag's position from carrier phase: the search behind
//! `scattertrack locate` (Python `scattertrack.locate`, docs/calibration.md).
//!
//! Each read k of one tag leaves, after the calibrated offsets, the unit
//! phasor z_k ≈ exp(j (k_k d_k(p) + θ)) with k_k = m s 4π f_k / c (rad/m,
//! m = 2π/P) and θ the tag's own offset. Profiling θ out, a position p
//! explains the reads as well as their coherence
//!
//!   R(p) = |Σ_k z_k exp(−j k_k d_k(p))| / n,
//!
//! whose local maxima are the candidates. Steps:
//!
//! 1. **Hop ranging** (several channels): per antenna, the phase slope
//!    against k is its range ([`hop_range`]); multilaterated, a centre and
//!    its covariance bound the box to search.
//! 2. **Grid** over the box at a quarter of the lattice step 2π/k̄, the best
//!    points at least half a step apart as seeds (those reaching half the
//!    best coherence).
//! 3. **Refinement** of each seed by Gauss–Newton on the wrapped residuals
//!    with θ re-profiled ([`refine`]); duplicates (< 5 mm) merged.

use nalgebra::{Complex, Matrix3, Vector3};

/// One tag's reads for the phase search.
pub struct PhaseReads<'a> {
    /// Unit phasors z_k (offsets removed).
    pub z: &'a [Complex<f64>],
    /// Wavenumbers k_k = m s 4π f_k / c, rad/m.
    pub k: &'a [f64],
    /// Antenna of each read (an index into `anchors`).
    pub antenna: &'a [usize],
    /// Antenna positions, m.
    pub anchors: &'a [Vector3<f64>],
}

impl PhaseReads<'_> {
    fn distance(&self, i: usize, p: &Vector3<f64>) -> f64 {
        (p - self.anchors[self.antenna[i]]).norm()
    }
}

/// R(p) (see the module docs).
pub fn coherence(reads: &PhaseReads, p: &Vector3<f64>) -> f64 {
    let mut sum = Complex::new(0.0, 0.0);
    for i in 0..reads.z.len() {
        let phase = -reads.k[i] * reads.distance(i, p);
        sum += reads.z[i] * Complex::new(phase.cos(), phase.sin());
    }
    sum.norm() / reads.z.len().max(1) as f64
}

/// The local maximum of R near `start`: Gauss–Newton on
/// r_k = arg(z_k e^{−j k_k d_k} e^{−jθ}), θ re-profiled each step, the
/// Jacobian centred over reads (θ is a nuisance). `axes` = 2 keeps z.
pub fn refine(reads: &PhaseReads, start: Vector3<f64>, axes: usize, iterations: usize) -> (Vector3<f64>, f64) {
    let n = reads.z.len();
    let mut p = start;
    let mut rotated = vec![Complex::new(0.0, 0.0); n];
    let mut jacobian = vec![Vector3::zeros(); n];
    for _ in 0..iterations {
        let mut sum = Complex::new(0.0, 0.0);
        for i in 0..n {
            let offset = p - reads.anchors[reads.antenna[i]];
            let d = offset.norm();
            let phase = -reads.k[i] * d;
            rotated[i] = reads.z[i] * Complex::new(phase.cos(), phase.sin());
            sum += rotated[i];
            jacobian[i] = offset * (reads.k[i] / d.max(1e-9));
        }
        let theta = Complex::new(0.0, -sum.arg()).exp();
        let mean: Vector3<f64> = jacobian.iter().sum::<Vector3<f64>>() / n as f64;
        let mut normal = Matrix3::zeros();
        let mut gradient = Vector3::zeros();
        for i in 0..n {
            let mut j = jacobian[i] - mean;
            if axes == 2 {
                j.z = 0.0;
            }
            let r = (rotated[i] * theta).arg();
            normal += j * j.transpose();
            gradient += j * r;
        }
        if axes == 2 {
            normal[(2, 2)] = 1.0;
        }
        let Some(inverse) = normal.try_inverse() else { break };
        let step = inverse * gradient;
        p += step;
        if step.norm() < 1e-7 {
            break;
        }
    }
    (p, coherence(reads, &p))
}

/// One antenna's range from its reads over several channels (m, 1-sigma m):
/// a scan at a tenth of the peak width 1/std(k), then Gauss–Newton on the
/// phase slope; σ = σ_φ / (std(k) √n) with σ_φ from the peak's coherence.
/// `None` when the reads do not spread in k.
pub fn hop_range(z: &[Complex<f64>], k: &[f64], max_range_m: f64) -> Option<(f64, f64)> {
    let n = z.len();
    if n < 3 {
        return None;
    }
    let mean_k = k.iter().sum::<f64>() / n as f64;
    let spread = (k.iter().map(|v| (v - mean_k).powi(2)).sum::<f64>() / n as f64).sqrt();
    if spread <= 0.0 {
        return None;
    }
    let spectrum = |d: f64| {
        let mut sum = Complex::new(0.0, 0.0);
        for i in 0..n {
            let phase = -k[i] * d;
            sum += z[i] * Complex::new(phase.cos(), phase.sin());
        }
        sum.norm() / n as f64
    };
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
    for _ in 0..5 {
        let mut sum = Complex::new(0.0, 0.0);
        let rotated: Vec<Complex<f64>> = (0..n)
            .map(|i| {
                let phase = -k[i] * best;
                let r = z[i] * Complex::new(phase.cos(), phase.sin());
                sum += r;
                r
            })
            .collect();
        let theta = Complex::new(0.0, -sum.arg()).exp();
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..n {
            let c = k[i] - mean_k;
            num += c * (rotated[i] * theta).arg();
            den += c * c;
        }
        best += num / den;
    }
    let peak = spectrum(best).max(1e-6);
    let sigma_phase = (-2.0 * peak.ln()).max(1e-6).sqrt();
    Some((best, sigma_phase / (spread * (n as f64).sqrt())))
}

/// The candidates of one tag: positions with their coherence, best first.
pub fn search(reads: &PhaseReads, low: Vector3<f64>, high: Vector3<f64>, axes: usize, max_points: usize, max_seeds: usize) -> Vec<(Vector3<f64>, f64)> {
    let mean_k = reads.k.iter().map(|v| v.abs()).sum::<f64>() / reads.k.len().max(1) as f64;
    if mean_k <= 0.0 {
        return Vec::new();
    }
    let spacing = 2.0 * std::f64::consts::PI / mean_k;
    let mut step = spacing / 4.0;
    let count = |step: f64| -> usize {
        (0..3).map(|a| if high[a] > low[a] { ((high[a] - low[a]) / step).floor() as usize + 1 } else { 1 }).product()
    };
    while count(step) > max_points {
        step *= 1.25;
    }
    let sizes: Vec<usize> = (0..3).map(|a| if high[a] > low[a] { ((high[a] - low[a]) / step).floor() as usize + 1 } else { 1 }).collect();
    let mut points = Vec::with_capacity(count(step));
    for ix in 0..sizes[0] {
        for iy in 0..sizes[1] {
            for iz in 0..sizes[2] {
                let p = Vector3::new(low.x + ix as f64 * step, low.y + iy as f64 * step, low.z + iz as f64 * step);
                points.push((p, coherence(reads, &p)));
            }
        }
    }
    points.sort_by(|a, b| b.1.total_cmp(&a.1));
    let floor = points.first().map_or(0.0, |p| 0.5 * p.1);
    let mut seeds: Vec<Vector3<f64>> = Vec::new();
    for (p, value) in points.iter().take(50 * max_seeds.max(1)) {
        if seeds.len() >= max_seeds || *value < floor {
            break;
        }
        if seeds.iter().all(|s| (s - p).norm() > 0.5 * spacing) {
            seeds.push(*p);
        }
    }
    let margin = 0.05;
    let mut refined: Vec<(Vector3<f64>, f64)> = Vec::new();
    for seed in seeds {
        let (p, r) = refine(reads, seed, axes, 8);
        let inside = (0..3).all(|a| p[a] >= low[a] - margin && p[a] <= high[a] + margin);
        if inside && p.iter().all(|v| v.is_finite()) && refined.iter().all(|(q, _)| (q - p).norm() > 0.005) {
            refined.push((p, r));
        }
    }
    refined.sort_by(|a, b| b.1.total_cmp(&a.1));
    refined
}

#[cfg(test)]
mod tests {
    use super::*;

    const C: f64 = 299_792_458.0;

    fn reads_at(truth: Vector3<f64>, anchors: &[Vector3<f64>], frequencies: &[f64]) -> (Vec<Complex<f64>>, Vec<f64>, Vec<usize>) {
        let (mut z, mut k, mut antenna) = (Vec::new(), Vec::new(), Vec::new());
        for (a, anchor) in anchors.iter().enumerate() {
            for f in frequencies {
                let kk = 4.0 * std::f64::consts::PI * f / C;
                let phase = kk * (truth - anchor).norm() + 0.7; // 0.7: the tag's own offset
                z.push(Complex::new(phase.cos(), phase.sin()));
                k.push(kk);
                antenna.push(a);
            }
        }
        (z, k, antenna)
    }

    fn layout() -> Vec<Vector3<f64>> {
        vec![Vector3::new(0.0, 0.3, 0.2), Vector3::new(0.0, 0.9, 1.1), Vector3::new(0.4, 0.0, 1.2), Vector3::new(1.0, 0.0, 0.2)]
    }

    #[test]
    fn hop_range_is_the_phase_slope() {
        let frequencies: Vec<f64> = (0..50).map(|i| 902.75e6 + 0.5e6 * i as f64).collect();
        let anchors = [Vector3::zeros()];
        let (z, k, _) = reads_at(Vector3::new(1.234, 0.0, 0.0), &anchors, &frequencies);
        let (d, sigma) = hop_range(&z, &k, 5.0).unwrap();
        assert!((d - 1.234).abs() < 1e-6, "{d}");
        assert!(sigma < 1e-3);
        assert!(hop_range(&z[..2], &k[..2], 5.0).is_none());
    }

    #[test]
    fn refine_climbs_to_the_true_position_and_search_finds_it() {
        let anchors = layout();
        let frequencies: Vec<f64> = (0..50).map(|i| 902.75e6 + 0.5e6 * i as f64).collect();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &frequencies);
        let reads = PhaseReads { z: &z, k: &k, antenna: &antenna, anchors: &anchors };
        assert!((coherence(&reads, &truth) - 1.0).abs() < 1e-12);
        let (p, r) = refine(&reads, truth + Vector3::new(0.01, -0.008, 0.005), 3, 10);
        assert!((p - truth).norm() < 1e-6 && r > 0.999999);
        let found = search(&reads, truth - Vector3::repeat(0.1), truth + Vector3::repeat(0.1), 3, 100_000, 20);
        assert!((found[0].0 - truth).norm() < 1e-5, "{:?}", found[0]);
        assert!(found.windows(2).all(|w| w[0].1 >= w[1].1));
    }
}
