//! Range from channel phases at arbitrary frequencies (docs/marvel.md
//! section 7, step 4; paper sec. III-C "Range estimation", eq. 4).
//!
//! A path of round-trip length `2 r` gives the phase `theta_i = -2 pi f_i
//! 2r/c0 + const` at frequency `f_i` (eq. 4). The delay profile over
//! candidate ranges `r` (m),
//!
//! `P(r) = |sum_i w_i exp(i (theta_i + 4 pi f_i r / c0))|`,
//!
//! is the inverse-FFT-style transform of the phases for non-uniform
//! frequencies: each path adds a lobe at its range. Phases from different
//! *groups* (e.g. different antennas, whose calibration or tag phases differ
//! by an unknown constant) cannot be added coherently; groups are combined
//! by summing their power profiles, normalised so that a single clean path
//! gives 1:
//!
//! `P^2(r) = sum_g |sum_{i in g} w_i exp(i (theta_i + 4 pi f_i r/c0))|^2
//!           / sum_g (sum_{i in g} w_i)^2`.
//!
//! The range is the *first path*: the earliest local maximum whose power is
//! at least `threshold` times the global maximum (the paper's "fixed energy
//! threshold over this profile to identify the closest path"), found on a
//! grid of `resolution/8` and refined by golden-section search.
//! "Range" is half the round-trip path, m.

use std::f64::consts::PI;

use num_complex::Complex64;

use crate::error::{Error, Result};
use crate::SPEED_OF_LIGHT;

/// Phases measured coherently (one unknown common offset), rad, at their
/// frequencies, Hz, with profile weights (amplitudes, >= 0) and optional
/// per-phase standard deviations (rad; for the uncertainty only).
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseGroup {
    pub frequencies_hz: Vec<f64>,
    pub phases_rad: Vec<f64>,
    pub weights: Vec<f64>,
    /// Empty, or one value per phase.
    pub sigmas_rad: Vec<f64>,
}

impl PhaseGroup {
    /// Validates lengths, finiteness and non-negative weights.
    pub fn new(
        frequencies_hz: Vec<f64>,
        phases_rad: Vec<f64>,
        weights: Vec<f64>,
        sigmas_rad: Vec<f64>,
    ) -> Result<Self> {
        let n = frequencies_hz.len();
        if phases_rad.len() != n || weights.len() != n || !(sigmas_rad.is_empty() || sigmas_rad.len() == n) {
            return Err(Error::Shape(format!(
                "phase group: {n} frequencies, {} phases, {} weights, {} sigmas",
                phases_rad.len(),
                weights.len(),
                sigmas_rad.len()
            )));
        }
        if frequencies_hz.iter().chain(&phases_rad).chain(&weights).chain(&sigmas_rad).any(|x| !x.is_finite()) {
            return Err(Error::NonFinite("phase group".into()));
        }
        if weights.iter().any(|&w| w < 0.0) {
            return Err(Error::BadConfig("phase group weights must be >= 0".into()));
        }
        Ok(Self { frequencies_hz, phases_rad, weights, sigmas_rad })
    }

    /// Unit weights, no sigmas.
    pub fn uniform(frequencies_hz: Vec<f64>, phases_rad: Vec<f64>) -> Result<Self> {
        let n = frequencies_hz.len();
        Self::new(frequencies_hz, phases_rad, vec![1.0; n], Vec::new())
    }

    fn span_hz(&self) -> f64 {
        let lo = self.frequencies_hz.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self.frequencies_hz.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi > lo {
            hi - lo
        } else {
            0.0
        }
    }
}

/// Candidate ranges and the first-path rule.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeConfig {
    /// Candidate ranges `[min_m, max_m]`, m.
    pub min_m: f64,
    pub max_m: f64,
    /// Grid step, m; `None`: an eighth of the resolution `c0 / (2 span)`.
    pub step_m: Option<f64>,
    /// First-path threshold as a fraction of the global maximum of the
    /// *power* profile `P^2` (0 < threshold <= 1; 1 = the global maximum).
    pub threshold: f64,
    /// Golden-section tolerance, m.
    pub tolerance_m: f64,
    /// Which of the peaks above the threshold is the range.
    pub select: RangeSelect,
}

/// How [`estimate_range`] chooses among the profile's peaks that pass the
/// threshold.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RangeSelect {
    /// The earliest (the paper's first path).
    #[default]
    FirstPath,
    /// The one nearest to a prior range (m), e.g. the chirp-timing range
    /// when the profile is a periodic fringe.
    NearestTo(f64),
}

impl Default for RangeConfig {
    fn default() -> Self {
        Self {
            min_m: 0.0,
            max_m: 100.0,
            step_m: None,
            threshold: 0.5,
            tolerance_m: 1e-4,
            select: RangeSelect::FirstPath,
        }
    }
}

/// The range estimate of [`estimate_range`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeEstimate {
    /// The selected peak (the first path by default), m.
    pub range_m: f64,
    /// Range of the global maximum, m (differs from `range_m` when an
    /// earlier, weaker path passes the threshold).
    pub peak_range_m: f64,
    /// Normalised profile power `P^2` at `range_m` and at the global maximum
    /// (0..1; 1 = all phases perfectly aligned).
    pub power: f64,
    pub peak_power: f64,
    /// Power of the strongest other local maximum over the global maximum
    /// (0..1): near 1 the profile is ambiguous (e.g. the fringe of two
    /// widely spaced channels, period `c0 / (2 df)`).
    pub ambiguity: f64,
    /// Standard deviation from the phase sigmas (weighted least-squares
    /// slope of phase against frequency with one intercept per group:
    /// `var(r) = (c0/4pi)^2 / sum (f_i - fbar_g)^2 / sigma_i^2`), m; `None`
    /// without sigmas.
    pub sigma_m: Option<f64>,
    /// Resolution `c0 / (2 span)` of the widest group, m.
    pub resolution_m: f64,
}

/// Normalised power profile `P^2(r)` (0..1) of the groups at range `r` (m).
pub fn profile_power(groups: &[PhaseGroup], r: f64) -> f64 {
    let k = 4.0 * PI * r / SPEED_OF_LIGHT;
    let (mut num, mut den) = (0.0, 0.0);
    for g in groups {
        let mut s = Complex64::new(0.0, 0.0);
        let mut wsum = 0.0;
        for ((f, th), w) in g.frequencies_hz.iter().zip(&g.phases_rad).zip(&g.weights) {
            // Reduce f r modulo the cycle before the trig call: 4 pi f r / c0
            // is thousands of radians at 900 MHz and 100 m.
            let x = (th + k * f) % (2.0 * PI);
            s += Complex64::from_polar(*w, x);
            wsum += w;
        }
        num += s.norm_sqr();
        den += wsum * wsum;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// `P^2` at each range in `ranges_m` (see [`profile_power`]).
pub fn delay_profile(groups: &[PhaseGroup], ranges_m: &[f64]) -> Vec<f64> {
    ranges_m.iter().map(|&r| profile_power(groups, r)).collect()
}

/// First-path range from the groups' phases (see the module doc).
///
/// Errors: [`Error::TooShort`] when no group spans two frequencies (a
/// single frequency carries no range), [`Error::BadConfig`] for an empty or
/// inverted range interval, a bad threshold or a grid of more than 10^6
/// points.
pub fn estimate_range(groups: &[PhaseGroup], config: &RangeConfig) -> Result<RangeEstimate> {
    let span = groups.iter().map(PhaseGroup::span_hz).fold(0.0, f64::max);
    if span.is_nan() || span <= 0.0 {
        return Err(Error::TooShort { what: "range: distinct frequencies in a group", needed: 2, got: 1 });
    }
    if !(config.min_m.is_finite() && config.max_m.is_finite() && config.max_m > config.min_m) {
        return Err(Error::BadConfig(format!("range interval [{}, {}] m", config.min_m, config.max_m)));
    }
    if !(config.threshold > 0.0 && config.threshold <= 1.0) {
        return Err(Error::BadConfig(format!("first-path threshold must be in (0, 1], got {}", config.threshold)));
    }
    let resolution_m = SPEED_OF_LIGHT / (2.0 * span);
    let step = config.step_m.unwrap_or(resolution_m / 8.0);
    let points = ((config.max_m - config.min_m) / step).ceil() as usize + 1;
    if step.is_nan() || step <= 0.0 || points > 1_000_000 {
        return Err(Error::BadConfig(format!("range grid step {step} m gives {points} points")));
    }
    let points = points.max(3);
    let step = (config.max_m - config.min_m) / (points - 1) as f64;
    let grid: Vec<f64> = (0..points).map(|i| config.min_m + step * i as f64).collect();
    let power = delay_profile(groups, &grid);

    // Interior local maxima, each refined inside its two neighbours' span.
    let mut peaks: Vec<(f64, f64)> = Vec::new();
    for i in 1..points - 1 {
        if power[i] >= power[i - 1] && power[i] > power[i + 1] {
            peaks.push(golden_max(groups, grid[i - 1], grid[i + 1], config.tolerance_m));
        }
    }
    if peaks.is_empty() {
        // Monotone over the window: the edge sample is all there is.
        let i = if power[0] >= power[points - 1] { 0 } else { points - 1 };
        peaks.push((grid[i], power[i]));
    }
    let (peak_range_m, peak_power) = peaks.iter().copied().fold((0.0, -1.0), |b, p| if p.1 > b.1 { p } else { b });
    let passing = peaks.iter().copied().filter(|p| p.1 >= config.threshold * peak_power);
    let chosen = match config.select {
        RangeSelect::FirstPath => passing.min_by(|a, b| a.0.total_cmp(&b.0)),
        RangeSelect::NearestTo(prior) => passing.min_by(|a, b| (a.0 - prior).abs().total_cmp(&(b.0 - prior).abs())),
    };
    let (range_m, first_power) = chosen.unwrap_or((peak_range_m, peak_power));
    let second = peaks.iter().filter(|p| p.0 != peak_range_m).map(|p| p.1).fold(0.0, f64::max);
    let ambiguity = if peak_power > 0.0 { second / peak_power } else { 1.0 };

    // Uncertainty: LS slope of phase vs frequency, one intercept per group.
    let mut information = 0.0;
    let mut any_sigma = false;
    for g in groups.iter().filter(|g| !g.sigmas_rad.is_empty()) {
        any_sigma = true;
        let w: Vec<f64> = g.sigmas_rad.iter().map(|s| if *s > 0.0 { 1.0 / (s * s) } else { 0.0 }).collect();
        let wsum: f64 = w.iter().sum();
        if wsum <= 0.0 {
            continue;
        }
        let fbar = g.frequencies_hz.iter().zip(&w).map(|(f, w)| f * w).sum::<f64>() / wsum;
        information += g.frequencies_hz.iter().zip(&w).map(|(f, w)| w * (f - fbar).powi(2)).sum::<f64>();
    }
    let sigma_m = (any_sigma && information > 0.0).then(|| SPEED_OF_LIGHT / (4.0 * PI) / information.sqrt());
    Ok(RangeEstimate { range_m, peak_range_m, power: first_power, peak_power, ambiguity, sigma_m, resolution_m })
}

/// Each group's own range minus `range_m` (m): the peak of the group's
/// profile nearest to `range_m` within one resolution `c0 / (2 span)` of it
/// (a two-frequency group's profile repeats with that period, so the
/// nearest peak is within half of it); `None` for a group spanning no
/// frequency. One entry per group, in order. The scatter of these deviations is a consistency measure of
/// the combined range (multipath reaches each group through its own fades).
pub fn group_deviations_m(groups: &[PhaseGroup], range_m: f64) -> Vec<Option<f64>> {
    groups
        .iter()
        .map(|g| {
            let span = g.span_hz();
            if !(span > 0.0 && range_m.is_finite()) {
                return None;
            }
            let resolution = SPEED_OF_LIGHT / (2.0 * span);
            let config = RangeConfig {
                min_m: range_m - resolution,
                max_m: range_m + resolution,
                select: RangeSelect::NearestTo(range_m),
                ..RangeConfig::default()
            };
            estimate_range(std::slice::from_ref(g), &config).ok().map(|e| e.range_m - range_m)
        })
        .collect()
}

/// Golden-section maximum of `P^2` on `[a, b]`: `(r, P^2(r))`.
fn golden_max(groups: &[PhaseGroup], mut a: f64, mut b: f64, tolerance: f64) -> (f64, f64) {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - ratio * (b - a);
    let mut d = a + ratio * (b - a);
    let (mut fc, mut fd) = (profile_power(groups, c), profile_power(groups, d));
    for _ in 0..200 {
        if (b - a).abs() <= tolerance {
            break;
        }
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - ratio * (b - a);
            fc = profile_power(groups, c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + ratio * (b - a);
            fd = profile_power(groups, d);
        }
    }
    let r = 0.5 * (a + b);
    (r, profile_power(groups, r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The channel of paths `(range m, complex reflection)` at `freqs` (eq. 4
    /// with multipath), `h = sum_p g_p exp(-i 4 pi f r_p / c0)`, as
    /// `(arg h + offset, |h|)`.
    fn channel(freqs: &[f64], paths: &[(f64, Complex64)], offset: f64) -> (Vec<f64>, Vec<f64>) {
        freqs
            .iter()
            .map(|f| {
                let h: Complex64 =
                    paths.iter().map(|(r, g)| g * Complex64::from_polar(1.0, -4.0 * PI * f * r / SPEED_OF_LIGHT)).sum();
                (h.arg() + offset, h.norm())
            })
            .unzip()
    }

    fn phases(freqs: &[f64], paths: &[(f64, Complex64)], offset: f64) -> Vec<f64> {
        channel(freqs, paths, offset).0
    }

    /// Magnitude-weighted group: the profile is then the linear transform
    /// of the complex channel, in which every path keeps its own lobe.
    fn weighted(freqs: &[f64], paths: &[(f64, Complex64)]) -> PhaseGroup {
        let (th, w) = channel(freqs, paths, 0.0);
        PhaseGroup::new(freqs.to_vec(), th, w, Vec::new()).unwrap()
    }

    /// 13 LoRa channels (sec. III-C), uniform: unambiguous over
    /// c0 / (2 x 2.16 MHz) = 69 m, resolution c0 / (2 x 25.9 MHz) = 5.8 m.
    fn all_channels() -> Vec<f64> {
        (0..13).map(|i| 902.1e6 + 2.16e6 * i as f64 + 0.5e6).collect()
    }

    #[test]
    fn group_deviations_are_each_groups_own_range_within_its_fringe() {
        // Two-frequency groups at 902.6 / 928.5 MHz (fringe 5.79 m): one at
        // 10.00 m, one at 10.40 m, one at 10.00 m + 2 fringes - 0.2 m.
        let freqs = vec![902.6e6, 928.52e6];
        let fringe = SPEED_OF_LIGHT / (2.0 * (freqs[1] - freqs[0]));
        let group = |r: f64| {
            let th: Vec<f64> = freqs.iter().map(|f| (-4.0 * PI * f * r / SPEED_OF_LIGHT) % (2.0 * PI) + 0.7).collect();
            PhaseGroup::uniform(freqs.clone(), th).unwrap()
        };
        let groups = [group(10.0), group(10.4), group(10.0 + 2.0 * fringe - 0.2)];
        let d = group_deviations_m(&groups, 10.0);
        assert_eq!(d.len(), 3);
        for (got, want) in d.iter().zip([0.0, 0.4, -0.2]) {
            assert!((got.unwrap() - want).abs() < 1e-3, "{d:?}");
        }
        // A single frequency carries no range.
        let single = PhaseGroup::uniform(vec![902.6e6], vec![0.1]).unwrap();
        assert_eq!(group_deviations_m(&[single], 10.0), vec![None]);
    }

    #[test]
    fn recovers_a_single_path_per_group_offsets_and_noise() {
        let freqs = all_channels();
        let mut rng = StdRng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.1).unwrap();
        let config = RangeConfig { max_m: 60.0, ..Default::default() };
        for &r in &[3.0, 17.35, 41.2] {
            let groups: Vec<PhaseGroup> = (0..3)
                .map(|a| {
                    let mut th = phases(&freqs, &[(r, Complex64::new(1.0, 0.0))], 0.7 * a as f64);
                    th.iter_mut().for_each(|x| *x += noise.sample(&mut rng));
                    PhaseGroup::new(freqs.clone(), th, vec![1.0; 13], vec![0.1; 13]).unwrap()
                })
                .collect();
            let e = estimate_range(&groups, &config).unwrap();
            let sigma = e.sigma_m.unwrap();
            assert!((e.range_m - r).abs() < 5.0 * sigma, "{r}: {e:?}");
            assert!(e.peak_power > 0.9 && e.ambiguity < 0.5, "{e:?}");
        }
    }

    #[test]
    fn picks_the_first_path_before_a_stronger_later_one() {
        let freqs = all_channels();
        let config = RangeConfig { max_m: 60.0, threshold: 0.3, ..Default::default() };
        // Direct path at 12 m (weaker), reflection at 30 m (stronger).
        let paths = [(12.0, Complex64::new(0.6, 0.0)), (30.0, Complex64::from_polar(1.0, 1.0))];
        let g = weighted(&freqs, &paths);
        let e = estimate_range(&[g], &config).unwrap();
        assert!((e.range_m - 12.0).abs() < 0.3, "{e:?}");
        assert!((e.peak_range_m - 30.0).abs() < 0.3, "{e:?}");
        // A weaker later path leaves the direct one as both first and peak.
        let paths = [(12.0, Complex64::new(1.0, 0.0)), (30.0, Complex64::from_polar(0.4, 2.0))];
        let g = weighted(&freqs, &paths);
        let e = estimate_range(&[g], &config).unwrap();
        assert!((e.range_m - 12.0).abs() < 0.3 && (e.peak_range_m - 12.0).abs() < 0.3, "{e:?}");
    }

    #[test]
    fn two_channel_fringe_is_reported_ambiguous_and_bad_input_errors() {
        let freqs = vec![902.6e6, 928.5e6];
        let g = PhaseGroup::uniform(freqs.clone(), phases(&freqs, &[(20.0, Complex64::new(1.0, 0.0))], 0.0)).unwrap();
        let e =
            estimate_range(std::slice::from_ref(&g), &RangeConfig { min_m: 17.5, max_m: 22.5, ..Default::default() })
                .unwrap();
        assert!((e.range_m - 20.0).abs() < 1e-3, "{e:?}");
        let wide = estimate_range(std::slice::from_ref(&g), &RangeConfig::default()).unwrap();
        assert!(wide.ambiguity > 0.99, "{wide:?}");
        // The fringe nearest to a coarse prior (2 m off) is the right one.
        let near = RangeConfig { min_m: 10.0, max_m: 30.0, select: RangeSelect::NearestTo(22.0), ..Default::default() };
        assert!((estimate_range(std::slice::from_ref(&g), &near).unwrap().range_m - 20.0).abs() < 1e-3);
        let single = PhaseGroup::uniform(vec![915e6], vec![0.0]).unwrap();
        assert_eq!(estimate_range(&[single], &RangeConfig::default()).unwrap_err().kind(), "too-short");
        assert!(estimate_range(
            std::slice::from_ref(&g),
            &RangeConfig { min_m: 5.0, max_m: 5.0, ..Default::default() }
        )
        .is_err());
        assert!(PhaseGroup::new(vec![1.0], vec![0.0, 1.0], vec![1.0], vec![]).is_err());
    }
}
