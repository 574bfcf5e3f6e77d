//! Distance candidates from one wideband channel (TurboTrack thesis §5.1
//! and eq. 5.1): the measurement model of the localization helper.
//!
//! After calibration a path of length `d` (m) gives, at subcarrier `f`
//! (Hz), `h(f) = a · exp(−j 2π f d / c)` (docs/formats.md §5). The
//! fractional Fourier transform ("delay-domain beamformer")
//!
//! `B(d) = Σ_k h(f_k) · exp(+j 2π f_k d / c)`
//!
//! is `K a` at the true `d`. Around it, for subcarriers symmetric about
//! `f_c`, `B(d) ≈ K a · E(d − d_true) · exp(j 2π f_c (d − d_true) / c)`
//! with a real envelope `E` whose main lobe is `c / Δf_total` wide (3 m
//! for 100 MHz). So the *magnitude* only says roughly where the tag is,
//! but the *phase* of `B` is zero exactly at `d_true + n λ_c`, `λ_c =
//! c / f_c`: the candidates are one wavelength apart, with weights from
//! the envelope. That is the mixture of Gaussians of eq. 5.1.

use nalgebra::Complex;

use crate::scene::SPEED_OF_LIGHT;

/// Tunables of candidate extraction.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateParams {
    /// Keep candidates whose envelope is at least this fraction of the
    /// peak (0–1): the "N" of eq. 5.1.
    pub min_relative_weight: f64,
    /// Largest number of candidates kept per receive antenna.
    pub max_candidates: usize,
    /// How the comb teeth are weighted.
    pub weighting: CandidateWeighting,
    /// Exponent of the amplitude weighting `|B(d_n)|^weight_exponent`.
    pub weight_exponent: f64,
    /// Temper κ ∈ (0, 1] of the likelihood weighting.
    pub likelihood_temper: f64,
    /// Smallest 1-sigma distance error σ_w reported, m (residual
    /// calibration error puts a floor under the noise-based estimate).
    pub min_sigma_m: f64,
    /// Largest σ_w reported, m.
    pub max_sigma_m: f64,
    /// Whether to measure [`Candidates::residual_coherence`] (about a
    /// microsecond a receiver; 0 when not measured).
    pub measure_coherence: bool,
}

impl Default for CandidateParams {
    fn default() -> Self {
        Self {
            min_relative_weight: 0.5,
            max_candidates: 15,
            weighting: CandidateWeighting::Likelihood,
            weight_exponent: 1.0,
            likelihood_temper: 1.0,
            min_sigma_m: 0.003,
            max_sigma_m: 0.05,
            measure_coherence: true,
        }
    }
}

/// The weights `w(n)` of eq. 5.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CandidateWeighting {
    /// The thesis: the fractional-Fourier amplitude `|B(d_n)|^p`. Over
    /// 100 MHz neighbouring teeth differ by ~2 %, so this barely ranks them.
    Amplitude,
    /// The profile likelihood of one path with unknown complex amplitude
    /// in white noise of per-subcarrier variance σ̂² (estimated from the
    /// frame's own fit residual): `log w(n) = κ (|B(d_n)|² − |B_max|²) / (K σ̂²)`.
    /// The same envelope, weighed by the frame's SNR: sharp when the single-path
    /// model fits, flat when multipath inflates the residual. (The thesis
    /// allows "a MUSIC projection" here for sharper weights.)
    Likelihood,
}

/// The candidates of one receive antenna: path lengths `d0 + n λ` with
/// weights `w(n)` (eq. 5.1) and one noise level σ_w.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidates {
    /// Candidate path lengths tx → tag → rx, ascending and exactly
    /// `spacing_m` apart, m.
    pub distances_m: Vec<f64>,
    /// Mixture weights, summing to 1.
    pub weights: Vec<f64>,
    /// Spacing between candidates (the centre wavelength `c / f̄`), m.
    pub spacing_m: f64,
    /// 1-sigma error of each candidate, m (from the residual of the
    /// single-path fit, clamped to the parameter bounds).
    pub sigma_m: f64,
    /// Index of the highest-weight candidate.
    pub best: usize,
    /// How much of the single-path fit's residual one other path explains,
    /// 0–1 ([`residual_coherence`]): near 1 when a reflection, not noise,
    /// is what the fit leaves.
    pub residual_coherence: f64,
}

impl Candidates {
    /// Index `n` (relative to `distances_m[0]`, may be outside the kept
    /// list) of the candidate nearest to path length `d` (m).
    #[inline]
    pub fn nearest_index(&self, d: f64) -> i64 {
        ((d - self.distances_m[0]) / self.spacing_m).round() as i64
    }

    /// Path length (m) of candidate index `n` (any integer: the comb
    /// continues beyond the kept list).
    #[inline]
    pub fn distance(&self, n: i64) -> f64 {
        self.distances_m[0] + n as f64 * self.spacing_m
    }

    /// Mixture weight of candidate index `n`; `floor` outside the kept list.
    #[inline]
    pub fn weight(&self, n: i64, floor: f64) -> f64 {
        if n >= 0 && (n as usize) < self.weights.len() {
            self.weights[n as usize].max(floor)
        } else {
            floor
        }
    }
}

/// Subcarriers re-anchored on an exact `sin_cos` this often in the
/// recurrence of [`steering`]: each complex multiply adds a rounding error
/// of about 1e-16, so the phasors stay within 1e-14 of the exact ones.
const STEERING_ANCHOR: usize = 32;

/// The steering phasors `e^{+j 2π f_k d / c}` of every subcarrier, written
/// into `out` (same length as `frequencies_hz`).
///
/// Why not one `sin_cos` each: candidate extraction needs them at about
/// ten path lengths per receiver and frame, and `sin_cos` was most of a
/// TurboTrack step. Evenly spaced subcarriers (OFDM) take two: with
/// `ω_k = ω_0 + k Δω`, `e^{jω_k d} = e^{jω_0 d} (e^{jΔω d})^k`, one complex
/// multiply per subcarrier, re-anchored every `STEERING_ANCHOR`. Uneven
/// spacing (a notched band) falls back to one `sin_cos` per subcarrier.
pub fn steering(frequencies_hz: &[f64], d: f64, out: &mut [Complex<f64>]) {
    let two_pi_over_c = 2.0 * std::f64::consts::PI / SPEED_OF_LIGHT;
    let exact = |f: f64| {
        let (s, c) = (two_pi_over_c * f * d).sin_cos();
        Complex::new(c, s)
    };
    match even_spacing_hz(frequencies_hz) {
        Some(spacing) => {
            let rotation = exact(spacing);
            let mut current = Complex::new(1.0, 0.0);
            for (k, (o, &f)) in out.iter_mut().zip(frequencies_hz).enumerate() {
                current = if k % STEERING_ANCHOR == 0 { exact(f) } else { current * rotation };
                *o = current;
            }
        }
        None => out.iter_mut().zip(frequencies_hz).for_each(|(o, &f)| *o = exact(f)),
    }
}

/// `f_1 − f_0` when every step `f_{k+1} − f_k` equals it within 1 ppm of
/// the step (and there are at least two subcarriers), else None.
fn even_spacing_hz(frequencies_hz: &[f64]) -> Option<f64> {
    let spacing = frequencies_hz.get(1)? - frequencies_hz[0];
    let tolerance = 1e-6 * spacing.abs();
    (spacing != 0.0 && frequencies_hz.windows(2).all(|w| ((w[1] - w[0]) - spacing).abs() <= tolerance)).then_some(spacing)
}

/// `B(d) = Σ h_k exp(+j 2π f_k d / c)` at one path length `d` (m); the
/// steering phasors at `d` are left in `phasors` (length of `frequencies_hz`).
fn beamform(frequencies_hz: &[f64], h: &[Complex<f64>], d: f64, phasors: &mut [Complex<f64>]) -> Complex<f64> {
    steering(frequencies_hz, d, phasors);
    h.iter().zip(phasors.iter()).map(|(hk, e)| hk * e).sum()
}

/// Distance candidates of one receive antenna from its channel `h` at
/// `frequencies_hz`, searching path lengths in `[d_min, d_max]` (m).
///
/// Steps: (1) `|B(d)|` on a grid of λ/8 (phasor recurrence: one complex
/// multiply per subcarrier and step) finds the envelope peak; (2) the
/// phase of `B` is zeroed by Newton steps (`∂ arg B / ∂d ≈ 2π f̄ / c`)
/// near the peak: the phase-refined candidate; (3) the comb `d0 + n λ̄`
/// is walked both ways while the envelope stays above the threshold.
/// Returns None when the channel
/// has no finite, non-zero value or the interval is empty.
pub fn distance_candidates(
    frequencies_hz: &[f64],
    h: &[Complex<f64>],
    d_min: f64,
    d_max: f64,
    params: &CandidateParams,
) -> Option<Candidates> {
    let k = frequencies_hz.len();
    if k == 0 || h.len() != k || !(d_max > d_min) {
        return None;
    }
    if h.iter().any(|v| !(v.re.is_finite() && v.im.is_finite())) || frequencies_hz.iter().any(|f| !(*f > 0.0)) {
        return None;
    }
    let energy: f64 = h.iter().map(|v| v.norm_sqr()).sum();
    if energy <= 0.0 {
        return None;
    }
    let f_mean = frequencies_hz.iter().sum::<f64>() / k as f64;
    let lambda = SPEED_OF_LIGHT / f_mean;
    let two_pi_over_c = 2.0 * std::f64::consts::PI / SPEED_OF_LIGHT;

    // (1) Coarse envelope peak by phasor recurrence. |B| is a smooth
    // envelope (the carrier cancels in the magnitude) with a c/B-wide main
    // lobe, so a quarter-wavelength grid finds its top.
    let step = lambda / 4.0;
    let n_grid = ((d_max - d_min) / step).ceil() as usize + 1;
    let mut scratch = vec![Complex::new(0.0, 0.0); k];
    steering(frequencies_hz, d_min, &mut scratch);
    let mut phasor: Vec<Complex<f64>> = h.iter().zip(&scratch).map(|(hk, e)| hk * e).collect();
    let mut rotation = vec![Complex::new(0.0, 0.0); k];
    steering(frequencies_hz, step, &mut rotation);
    let (mut best_d, mut best_mag) = (d_min, -1.0);
    for i in 0..n_grid {
        let mag = phasor.iter().sum::<Complex<f64>>().norm_sqr();
        if mag > best_mag {
            best_mag = mag;
            best_d = d_min + i as f64 * step;
        }
        for (p, r) in phasor.iter_mut().zip(&rotation) {
            *p *= r;
        }
    }

    // (2) Zero the phase near the peak.
    let slope = two_pi_over_c * f_mean;
    let mut d_peak = best_d;
    for _ in 0..3 {
        d_peak -= beamform(frequencies_hz, h, d_peak, &mut scratch).arg() / slope;
    }
    let peak = beamform(frequencies_hz, h, d_peak, &mut scratch).norm();
    if !(peak > 0.0) {
        return None;
    }

    // (3) Walk the comb both ways, exactly λ̄ apart: for subcarriers
    // symmetric about f̄, arg B(d0 + n λ̄) = 0 for every n on a single path,
    // so one refinement (at the peak) serves every tooth. Magnitudes by
    // phasor recurrence: g_k = h_k e^{jω_k d0}, each tooth rotates g_k by
    // e^{±jω_k λ̄} (one complex multiply per subcarrier and tooth).
    // `scratch` holds the steering phasors at `d_peak` from the line above.
    let base: Vec<Complex<f64>> = h.iter().zip(&scratch).map(|(hk, e)| hk * e).collect();
    let mut tooth = vec![Complex::new(0.0, 0.0); k];
    steering(frequencies_hz, lambda, &mut tooth);
    let mut teeth: Vec<(f64, f64)> = vec![(d_peak, peak)];
    for direction in [-1.0f64, 1.0] {
        let mut g = base.clone();
        let mut n = 0.0;
        loop {
            n += direction;
            let d = d_peak + n * lambda;
            if d < d_min - lambda / 2.0 || d > d_max + lambda / 2.0 || teeth.len() > 4 * params.max_candidates {
                break;
            }
            for (gk, r) in g.iter_mut().zip(&tooth) {
                *gk *= if direction > 0.0 { *r } else { r.conj() };
            }
            let mag = g.iter().sum::<Complex<f64>>().norm();
            if mag < params.min_relative_weight * peak {
                break;
            }
            teeth.push((d, mag));
        }
    }
    teeth.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Keep the strongest `max_candidates` as a contiguous run (the comb
    // must stay evenly spaced for `nearest_index`).
    while teeth.len() > params.max_candidates {
        if teeth[0].1 <= teeth[teeth.len() - 1].1 {
            teeth.remove(0);
        } else {
            teeth.pop();
        }
    }
    // σ_w from the residual of the single-path fit at the peak: with
    // noise σ per subcarrier and amplitude a, the phase of B has
    // variance σ² / (2 K a²); distance = phase / slope.
    // |h_k − a e^{−jω_k d}|² = |h_k e^{jω_k d} − a|²: the base phasors serve.
    let a = peak / k as f64;
    let residual: f64 = base.iter().map(|g| (g - a).norm_sqr()).sum::<f64>() / k as f64;
    let coherence = if params.measure_coherence {
        // The coarse search's phasors are spent: they hold the residual.
        phasor.iter_mut().zip(&base).for_each(|(p, g)| *p = g - a);
        residual_coherence(frequencies_hz, &mut phasor, &mut scratch)
    } else {
        0.0
    };
    let sigma_phase = (residual / (2.0 * k as f64 * a * a)).sqrt();
    let mut weights: Vec<f64> = match params.weighting {
        CandidateWeighting::Amplitude => teeth.iter().map(|t| t.1.powf(params.weight_exponent)).collect(),
        CandidateWeighting::Likelihood => {
            // Residual variance with K − 2 degrees of freedom used (a, d);
            // never below 1e-6 of the signal so a noiseless channel stays finite.
            let noise = (residual * k as f64 / (k as f64 - 2.0).max(1.0)).max(1e-6 * a * a);
            let top = teeth.iter().map(|t| t.1).fold(0.0, f64::max);
            teeth.iter().map(|t| (params.likelihood_temper * (t.1 * t.1 - top * top) / (k as f64 * noise)).exp()).collect()
        }
    };
    let total: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|w| *w /= total);
    let best = weights.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    let sigma_m = (sigma_phase / slope).clamp(params.min_sigma_m, params.max_sigma_m);
    Some(Candidates {
        distances_m: teeth.iter().map(|t| t.0).collect(),
        weights,
        spacing_m: lambda,
        sigma_m,
        best,
        residual_coherence: coherence,
    })
}

/// The share of a residual `r` (per subcarrier, after the single-path fit)
/// that one more path explains: `max_δ |Σ_k r_k e^{jω_k δ}|² / (K Σ_k |r_k|²)`
/// over excess delays `δ` spanning the subcarriers' alias-free range
/// `c / Δf` at half the `c / (K Δf)` resolution.
///
/// Why: the candidates' weights read the envelope `|B(d)|` as a single
/// path's, and a reflection a few dB below the direct path shifts its peak
/// by teeth. White noise spreads the residual over every delay (median
/// 0.19 for 20 subcarriers, above 0.3 in 4 % and above 0.4 in 0.2 % of
/// frames); one reflection puts it at one delay (up to 1). Lobe-level
/// tests read the envelope and skip frames where this is high
/// (`track::lobes::MULTIPATH_COHERENCE`). `r` is rotated in place (it is
/// left as scratch); `scratch`: length of `r`.
pub fn residual_coherence(frequencies_hz: &[f64], r: &mut [Complex<f64>], scratch: &mut [Complex<f64>]) -> f64 {
    let k = r.len();
    let energy: f64 = r.iter().map(|v| v.norm_sqr()).sum();
    if k < 2 || !(energy > 0.0) {
        return 0.0;
    }
    let span = frequencies_hz.last().copied().unwrap_or(0.0) - frequencies_hz[0];
    let spacing = span / (k - 1) as f64;
    if !(spacing > 0.0) {
        return 0.0;
    }
    let steps = 2 * k;
    let step_m = SPEED_OF_LIGHT / spacing / steps as f64;
    steering(frequencies_hz, step_m, scratch);
    let mut best = 0.0f64;
    for _ in 0..steps {
        best = best.max(r.iter().sum::<Complex<f64>>().norm_sqr());
        r.iter_mut().zip(scratch.iter()).for_each(|(p, e)| *p *= e);
    }
    (best / (k as f64 * energy)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn subcarriers() -> Vec<f64> {
        (0..20).map(|k| 867.5e6 + 5e6 * k as f64).collect()
    }

    fn channel(freqs: &[f64], d: f64, a: f64) -> Vec<Complex<f64>> {
        freqs
            .iter()
            .map(|&f| {
                let (s, c) = (2.0 * std::f64::consts::PI * f * d / SPEED_OF_LIGHT).sin_cos();
                Complex::new(c, -s) * a
            })
            .collect()
    }

    /// The recurrence matches one `sin_cos` per subcarrier, for even
    /// spacing past several re-anchorings and for uneven spacing.
    #[test]
    fn steering_matches_the_exact_phasors() {
        let even: Vec<f64> = (0..100).map(|k| 867.5e6 + 1.25e6 * k as f64).collect();
        let mut uneven = subcarriers();
        uneven[7] += 0.3e6;
        assert!(even_spacing_hz(&even).is_some() && even_spacing_hz(&uneven).is_none());
        assert!(even_spacing_hz(&[9e8]).is_none() && even_spacing_hz(&[9e8, 9e8]).is_none());
        for f in [even, uneven] {
            for d in [0.0, 0.083, 3.7, 41.25] {
                let mut out = vec![Complex::new(0.0, 0.0); f.len()];
                steering(&f, d, &mut out);
                for (o, &fk) in out.iter().zip(&f) {
                    let (s, c) = (2.0 * std::f64::consts::PI * fk * d / SPEED_OF_LIGHT).sin_cos();
                    assert!((o - Complex::new(c, s)).norm() < 1e-12, "f={fk} d={d}");
                }
            }
        }
    }

    /// A reflection leaves a coherent residual; white noise does not.
    #[test]
    fn residual_coherence_tells_a_reflection_from_noise() {
        let f = subcarriers();
        let direct = channel(&f, 2.0, 1.0);
        let reflected = channel(&f, 3.1, 0.4);
        let two: Vec<Complex<f64>> = direct.iter().zip(&reflected).map(|(a, b)| a + b).collect();
        let c = distance_candidates(&f, &two, 0.5, 6.0, &CandidateParams::default()).unwrap();
        assert!(c.residual_coherence > 0.6, "{}", c.residual_coherence);
        // Deterministic pseudo-noise at 8 dB.
        let mut state = 12345u64;
        let mut uniform = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut high = 0;
        for _ in 0..200 {
            let noisy: Vec<Complex<f64>> = direct
                .iter()
                .map(|h| {
                    let (u, v) = (uniform().max(1e-12), uniform());
                    let r = (-2.0 * u.ln()).sqrt() * 0.4 / std::f64::consts::SQRT_2;
                    h + Complex::from_polar(r, 2.0 * std::f64::consts::PI * v)
                })
                .collect();
            let c = distance_candidates(&f, &noisy, 0.5, 6.0, &CandidateParams::default()).unwrap();
            high += usize::from(c.residual_coherence > 0.5);
        }
        assert!(high <= 4, "{high} of 200 noise-only frames look coherent");
    }

    #[test]
    fn noiseless_channel_puts_a_candidate_on_the_truth() {
        let f = subcarriers();
        for d in [1.234, 2.5, 4.71, 7.9] {
            let c = distance_candidates(&f, &channel(&f, d, 0.3), 0.5, 12.0, &CandidateParams::default()).unwrap();
            let n = c.nearest_index(d);
            assert!((c.distance(n) - d).abs() < 1e-6, "d={d}: {:?}", c.distances_m);
            assert!(n >= 0 && (n as usize) < c.distances_m.len());
            assert!((c.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(c.sigma_m <= CandidateParams::default().min_sigma_m + 1e-12);
            // Noiseless: the likelihood weighting is (nearly) certain of the truth.
            assert!(c.weights[n as usize] > 0.99, "{:?}", c.weights);
            // 100 MHz: the main lobe spans several wavelengths (thesis: ~9).
            assert!(c.distances_m.len() >= 5, "{}", c.distances_m.len());
            let spacing = c.distances_m.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
            assert!((spacing - c.spacing_m).abs() < 1e-3);
        }
    }

    #[test]
    fn noise_level_is_estimated() {
        let f = subcarriers();
        let mut h = channel(&f, 2.0, 1.0);
        // Deterministic pseudo-noise of rms 0.2 per subcarrier.
        for (k, v) in h.iter_mut().enumerate() {
            let t = k as f64 * 1.7;
            *v += Complex::new(t.sin(), (2.3 * t).cos()) * 0.2;
        }
        let c = distance_candidates(&f, &h, 0.5, 12.0, &CandidateParams { min_sigma_m: 0.0, ..Default::default() }).unwrap();
        // Amplitude (thesis) weights are nearly flat over 100 MHz; likelihood weights are not.
        let amplitude =
            distance_candidates(&f, &h, 0.5, 12.0, &CandidateParams { weighting: CandidateWeighting::Amplitude, ..Default::default() })
                .unwrap();
        let spread = |w: &[f64]| w.iter().cloned().fold(0.0, f64::max) / w.iter().cloned().fold(1.0, f64::min);
        assert!(spread(&amplitude.weights) < 2.5, "{:?}", amplitude.weights);
        assert!(spread(&c.weights) > 100.0, "{:?}", c.weights);
        // σφ ≈ 0.2/√(2·20) rad → σ_d ≈ 0.032 · λ/2π ≈ 1.7 mm.
        assert!(c.sigma_m > 0.0008 && c.sigma_m < 0.004, "{}", c.sigma_m);
    }

    #[test]
    fn rejects_empty_and_non_finite() {
        let f = subcarriers();
        let mut h = channel(&f, 2.0, 1.0);
        assert!(distance_candidates(&f, &vec![Complex::new(0.0, 0.0); 20], 0.5, 12.0, &Default::default()).is_none());
        h[3] = Complex::new(f64::NAN, 0.0);
        assert!(distance_candidates(&f, &h, 0.5, 12.0, &Default::default()).is_none());
        assert!(distance_candidates(&f, &channel(&f, 2.0, 1.0), 3.0, 1.0, &Default::default()).is_none());
    }
}
