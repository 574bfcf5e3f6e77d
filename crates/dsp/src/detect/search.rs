use super::correlate::{normalised_correlation, FeatureSums, Template};
use crate::error::{Error, Result};

/// Detection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectionOptions {
    /// Threshold on the combined normalised correlation, in (0, 1]: a reply
    /// is declared when `√(mean_a ρ_a²)` reaches it (thesis ch. 4.3 (a):
    /// "when D rises above a threshold", here made amplitude-free).
    pub threshold: f64,
    /// Fractional BLF tolerance searched around the nominal BLF, in
    /// [0, 0.5): Gen2 tags may backscatter several per cent off the
    /// commanded rate.
    pub blf_tolerance: f64,
}

impl Default for DetectionOptions {
    fn default() -> Self {
        Self { threshold: 0.5, blf_tolerance: 0.05 }
    }
}

/// Where the preamble is and how fast the tag switches.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Start of the template's first chip, in symbols from the first whole
    /// symbol of the window (fractional).
    pub start_symbol: f64,
    /// Estimated chip length (half a BLF period), symbols.
    pub chip_symbols: f64,
    /// Estimated true BLF over nominal BLF.
    pub blf_scale: f64,
    /// Combined score `√(mean_a ρ_a²)` ∈ [0, 1].
    pub score: f64,
    /// Signed normalised correlation of each feature (antenna) at the best
    /// alignment.
    pub correlations: Vec<f64>,
    /// Half the final BLF grid step, as a fraction: how far the true BLF may
    /// be from `blf_scale`; edge elimination widens its guard by it.
    pub scale_uncertainty: f64,
}

fn score<F: AsRef<FeatureSums>>(features: &[F], template: &Template, start: f64, chip: f64) -> f64 {
    let sum: f64 = features.iter().map(|f| normalised_correlation(f.as_ref(), template, start, chip).powi(2)).sum();
    (sum / features.len() as f64).sqrt()
}

/// Searches `(Δ, BLF)` for the best normalised preamble correlation over all
/// antennas' features, then applies the threshold (thesis ch. 4.3 (a)).
///
/// The alignment is parametrised by the template's centre and the BLF
/// scale (true BLF / nominal): with the centre fixed, a scale error moves
/// both ends by half as much as with the start fixed, and centre and scale
/// errors hardly trade off. Two stages over the whole template (a prefix
/// would not do: the FM0 TRext and Miller pilots are periodic, so a short
/// prefix matches at every subcarrier period):
/// 1. scales `1 ± i/(2K)` within the tolerance (between grid points the
///    template's ends drift by at most 1/8 chip) and centres every eighth of
///    a chip;
/// 2. [`refine_detection`] around the best point with a quarter of that
///    scale step.
///
/// Cost `O(R · K · centres · scales)` with `scales ≈ 4 K · tolerance`: small
/// for FM0 (K = 12: 3 scales at ±5 %), growing as `K²` for long Miller
/// preambles (M = 8: K = 160). Only alignments where the whole template
/// lies inside the window count. Errors: [`Error::BadConfig`] for bad
/// options, [`Error::TooShort`] when the preamble cannot fit,
/// [`Error::NoPreamble`] below the threshold.
pub fn detect_preamble<F: AsRef<FeatureSums>>(
    features: &[F],
    template: &Template,
    nominal_chip_symbols: f64,
    options: &DetectionOptions,
) -> Result<Detection> {
    if !(options.threshold > 0.0 && options.threshold <= 1.0) {
        return Err(Error::BadConfig(format!("threshold must be in (0, 1], got {}", options.threshold)));
    }
    if !(options.blf_tolerance >= 0.0 && options.blf_tolerance < 0.5) {
        return Err(Error::BadConfig(format!("blf_tolerance must be in [0, 0.5), got {}", options.blf_tolerance)));
    }
    if !(nominal_chip_symbols.is_finite() && nominal_chip_symbols > 0.0) {
        return Err(Error::BadConfig(format!("chip length must be positive, got {nominal_chip_symbols}")));
    }
    if features.is_empty() {
        return Err(Error::Shape("no detection feature given".into()));
    }
    let symbols = features.iter().map(|f| f.as_ref().len()).min().unwrap_or(0);
    let grid = CoarseGrid::new(symbols, template.len(), nominal_chip_symbols, options.blf_tolerance);
    let mut summed = vec![0.0; grid.len()];
    for feature in features {
        grid.add_scores(feature.as_ref(), template, &mut summed);
    }
    detect_on_grid(features, template, nominal_chip_symbols, options, &grid, &summed)
}

/// Stage 1 of [`detect_preamble`]: the alignments searched, scales
/// `1 ± i/(2K)` within the tolerance × centres every eighth of a chip, for
/// features of `symbols` values. The combined score is a sum over antennas
/// of `ρ_a²`, so each antenna's share ([`CoarseGrid::add_scores`]) can be
/// computed apart — by that antenna's worker in the real-time runtime —
/// and summed before [`detect_on_grid`].
#[derive(Debug, Clone, PartialEq)]
pub struct CoarseGrid {
    /// Feature length the grid was made for, symbols.
    pub symbols: usize,
    /// Template length, chips.
    pub template_len: usize,
    /// Nominal chip length, symbols.
    pub nominal_chip_symbols: f64,
    /// (centre, scale) of each alignment, symbols and true/nominal BLF.
    pub points: Vec<(f64, f64)>,
    /// Stage 2's scale step (a quarter of stage 1's).
    pub fine_scale_step: f64,
    /// Symbols needed for the shortest alignment.
    pub needed: usize,
}

impl CoarseGrid {
    pub fn new(symbols: usize, template_len: usize, nominal_chip_symbols: f64, blf_tolerance: f64) -> Self {
        let k = template_len as f64;
        let step1 = 1.0 / (2.0 * k);
        let reach = (blf_tolerance / step1).floor() as i64;
        let centre_step = (nominal_chip_symbols / 8.0).max(0.25);
        let mut points = Vec::new();
        let length = symbols as f64;
        for i in -reach..=reach {
            let scale = 1.0 + i as f64 * step1;
            let half = k * nominal_chip_symbols / scale / 2.0;
            if 2.0 * half > length {
                continue;
            }
            let centres = ((length - 2.0 * half) / centre_step).floor() as usize;
            points.extend((0..=centres).map(|c| (half + c as f64 * centre_step, scale)));
        }
        let needed = (k * nominal_chip_symbols / (1.0 + blf_tolerance)).ceil() as usize;
        Self { symbols, template_len, nominal_chip_symbols, points, fine_scale_step: step1 / 4.0, needed }
    }

    /// Alignments searched.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether no alignment fits in the window.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Adds one antenna's `ρ²` at every alignment to `summed` (−∞ where
    /// the template leaves this feature).
    pub fn add_scores(&self, feature: &FeatureSums, template: &Template, summed: &mut [f64]) {
        let symbols = feature.len().min(self.symbols) as f64;
        for (out, &(centre, scale)) in summed.iter_mut().zip(&self.points) {
            let chip = self.nominal_chip_symbols / scale;
            let start = centre - template.len() as f64 * chip / 2.0;
            if start < 0.0 || start + template.len() as f64 * chip > symbols + 1e-9 {
                *out = f64::NEG_INFINITY;
            } else {
                *out += normalised_correlation(feature, template, start, chip).powi(2);
            }
        }
    }
}

/// Stages 2 and 3 of [`detect_preamble`] given the antennas' summed
/// stage-1 scores on `grid` ([`CoarseGrid::add_scores`] over every feature
/// in `features`): the best alignment, refined, then the threshold.
pub fn detect_on_grid<F: AsRef<FeatureSums>>(
    features: &[F],
    template: &Template,
    nominal_chip_symbols: f64,
    options: &DetectionOptions,
    grid: &CoarseGrid,
    summed: &[f64],
) -> Result<Detection> {
    let k = template.len() as f64;
    let mut best: Option<(f64, f64, f64)> = None; // (score, centre, scale)
    for (&s, &(centre, scale)) in summed.iter().zip(&grid.points) {
        if best.is_none_or(|b| s > b.0) {
            best = Some((s, centre, scale));
        }
    }
    let Some((_, centre, scale)) = best else {
        return Err(Error::TooShort { what: "preamble search (symbols in the window)", needed: grid.needed, got: grid.symbols });
    };

    // Stage 2: finer around the coarse point.
    let start = centre - k * nominal_chip_symbols / scale / 2.0;
    let detection = refine_detection(features, template, nominal_chip_symbols, start, scale, grid.fine_scale_step);
    if detection.score < options.threshold {
        return Err(Error::NoPreamble { score: detection.score, threshold: options.threshold });
    }
    Ok(detection)
}

/// The combined score with the template centred at `centre` (symbols) at
/// BLF scale `scale`; −∞ where the template leaves the window.
fn centred_score<F: AsRef<FeatureSums>>(
    features: &[F],
    template: &Template,
    nominal: f64,
    centre: f64,
    scale: f64,
    symbols: f64,
) -> f64 {
    let chip = nominal / scale;
    let start = centre - template.len() as f64 * chip / 2.0;
    if start < 0.0 || start + template.len() as f64 * chip > symbols + 1e-9 {
        return f64::NEG_INFINITY;
    }
    score(features, template, start, chip)
}

/// Refines an alignment `(start, scale)` of `template`, with the template's
/// centre and the scale as coordinates: centres within an eighth of a chip
/// at `min(½ symbol, chip/16)`, then a grid of scales
/// `scale + i · scale_step` (`i ∈ −4..=4`: a whole coarse cell either side
/// when called with a quarter of the coarse step) × centres within three
/// steps. Returns the best as a [`Detection`] with
/// `scale_uncertainty = scale_step / 2` (no threshold).
///
/// Used as the second stage of [`detect_preamble`] and, with the preamble
/// extended by the decided payload chips (more transitions over a longer
/// span), to pin the BLF down for the payload.
pub fn refine_detection<F: AsRef<FeatureSums>>(
    features: &[F],
    template: &Template,
    nominal_chip_symbols: f64,
    start: f64,
    scale: f64,
    scale_step: f64,
) -> Detection {
    let symbols = features.iter().map(|f| f.as_ref().len()).min().unwrap_or(0) as f64;
    let k = template.len() as f64;
    let eval =
        |centre: f64, scale: f64| centred_score(features, template, nominal_chip_symbols, centre, scale, symbols);
    let chip = nominal_chip_symbols / scale;
    let step = (chip / 16.0).min(0.5);
    let mut best = (eval(start + k * chip / 2.0, scale), start + k * chip / 2.0, scale);
    let sweep_centres = |best: &mut (f64, f64, f64), reach: i64| {
        let (_, centre, scale) = *best;
        for l in -reach..=reach {
            let s = eval(centre + l as f64 * step, scale);
            if s > best.0 {
                *best = (s, centre + l as f64 * step, scale);
            }
        }
    };
    sweep_centres(&mut best, ((chip / 8.0) / step).ceil() as i64);
    // Then scale and centre jointly on a small grid: with noise a one
    // coordinate at a time ascent can stall on a ridge.
    let (_, centre, base) = best;
    for i in -4i64..=4 {
        let candidate = base + i as f64 * scale_step;
        if candidate <= 0.0 {
            continue;
        }
        for l in -3i64..=3 {
            let s = eval(centre + l as f64 * step, candidate);
            if s > best.0 {
                best = (s, centre + l as f64 * step, candidate);
            }
        }
    }
    let (top, centre, scale) = best;
    let chip = nominal_chip_symbols / scale;
    let start = centre - k * chip / 2.0;
    Detection {
        start_symbol: start,
        chip_symbols: chip,
        blf_scale: scale,
        score: top.max(0.0),
        correlations: features.iter().map(|f| normalised_correlation(f.as_ref(), template, start, chip)).collect(),
        scale_uncertainty: scale_step / 2.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A feature: level·gain + bias between `offset` and the end of the
    /// chips, deterministic pseudo-noise of amplitude `noise`.
    fn feature(levels: &[u8], chip: f64, offset: f64, len: usize, gain: f64, noise: f64, seed: u64) -> Vec<f64> {
        let mut state = seed;
        (0..len)
            .map(|n| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * 3f64.sqrt();
                let x = (n as f64 + 0.5 - offset) / chip;
                let level = if x >= 0.0 && x < levels.len() as f64 { levels[x as usize] as f64 } else { 0.0 };
                5.0 + gain * level + noise * r
            })
            .collect()
    }

    fn fm0_template() -> Template {
        Template::new(crate::backscatter::preamble_chips(crate::backscatter::Encoding::Fm0, false).unwrap()).unwrap()
    }

    #[test]
    fn finds_start_and_blf_with_noise_and_any_amplitude() {
        let template = fm0_template();
        let mut reply = template.levels.clone();
        reply.extend([0, 1, 1, 0, 0, 1, 0, 1, 1, 0]);
        for (gain, scale, offset) in [(1.0f64, 1.0, 100.0), (-3e-3, 1.03, 57.3), (40.0, 0.97, 210.8)] {
            let true_chip = 62.5 / scale;
            let noise = 0.5 * gain.abs(); // per-symbol SNR 6 dB
            let u = feature(&reply, true_chip, offset, 1500, gain, noise, 9);
            let sums = FeatureSums::new(&u).unwrap();
            let d = detect_preamble(&[sums], &template, 62.5, &DetectionOptions::default()).unwrap();
            assert!((d.start_symbol - offset).abs() < 2.0, "start {} vs {offset}", d.start_symbol);
            assert!((d.blf_scale - scale).abs() < 0.006, "scale {} vs {scale}", d.blf_scale);
            // Expected ρ = √(S/(S+N)): template variance 35/144 against noise 1/4 → 0.70.
            assert!(d.score > 0.6, "{}", d.score);
            assert_eq!(d.correlations[0] > 0.0, gain > 0.0);
        }
    }

    #[test]
    fn noise_alone_is_no_preamble_and_a_short_window_is_too_short() {
        let template = fm0_template();
        let u = feature(&[0], 62.5, 1e9, 1500, 1.0, 1.0, 4);
        let sums = FeatureSums::new(&u).unwrap();
        let e =
            detect_preamble(std::slice::from_ref(&sums), &template, 62.5, &DetectionOptions::default()).unwrap_err();
        assert!(matches!(e, Error::NoPreamble { score, .. } if score < 0.3), "{e}");
        let short = FeatureSums::new(&u[..600]).unwrap();
        let e = detect_preamble(&[short], &template, 62.5, &DetectionOptions::default()).unwrap_err();
        assert!(matches!(e, Error::TooShort { .. }), "{e}");
        let bad = DetectionOptions { threshold: 0.0, ..Default::default() };
        assert!(matches!(detect_preamble(&[sums], &template, 62.5, &bad), Err(Error::BadConfig(_))));
    }

    #[test]
    fn antennas_combine() {
        // Two antennas of opposite feature sign, one silent: still found.
        let template = fm0_template();
        let a = FeatureSums::new(&feature(&template.levels, 20.0, 33.0, 400, 1.0, 0.3, 1)).unwrap();
        let b = FeatureSums::new(&feature(&template.levels, 20.0, 33.0, 400, -2.0, 0.6, 2)).unwrap();
        let c = FeatureSums::new(&feature(&[0], 20.0, 1e9, 400, 1.0, 1.0, 3)).unwrap();
        let d = detect_preamble(&[a, b, c], &template, 20.0, &DetectionOptions::default()).unwrap();
        assert!((d.start_symbol - 33.0).abs() < 1.0);
        assert!(d.correlations[0] > 0.8 && d.correlations[1] < -0.8 && d.correlations[2].abs() < 0.3);
    }
}
