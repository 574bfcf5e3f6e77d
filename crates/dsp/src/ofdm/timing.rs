use num_complex::{Complex32, Complex64};

use super::KnownSymbol;
use crate::error::{Error, Result};

/// Where the received symbols start in a window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymbolTiming {
    /// First sample (0 … N−1) of the first whole received symbol: the lag of
    /// the correlation peak.
    pub first_sample: usize,
    /// The peak lag refined by a parabola through its neighbours, samples
    /// (a diagnostic of the hardware delay; may be slightly negative or
    /// ≥ N − 1 near the wrap).
    pub delay_samples: f64,
    /// Peak magnitude over the mean magnitude of all lags (≥ 1; large for a
    /// clean timing, ~1 for noise).
    pub peak_to_mean: f64,
    /// Whole symbol periods folded into the correlation.
    pub blocks: usize,
}

/// Finds the first sample of the first whole OFDM symbol in a window
/// (thesis ch. 4.3, bullet 3: "a time-domain correlation that allows us to
/// detect the beginning (i.e., first sample) of the first OFDM symbol").
///
/// Because the helper repeats one symbol back to back, the window is
/// periodic with period `N`: the samples are first folded modulo `N`
/// (summing every whole, finite block, which averages the noise down by the
/// number of blocks), then circularly correlated with the known symbol,
/// `c[m] = Σ_n a[(n + m) mod N] x*[n]`. With `|X| = 1` this is the
/// channel's (band-limited) impulse response, so the peak is the dominant
/// path — the tx → rx leakage, because the antennas are co-located — plus
/// the hardware delay. Cost `O(len + N²)`.
///
/// Errors: [`Error::TooShort`] without one whole symbol period,
/// [`Error::NonFinite`] when every period has a non-finite sample.
pub fn symbol_timing(samples: &[Complex32], symbol: &KnownSymbol) -> Result<SymbolTiming> {
    let n = symbol.len();
    if samples.len() < n {
        return Err(Error::TooShort { what: "symbol timing (samples)", needed: n, got: samples.len() });
    }
    let mut folded = vec![Complex64::new(0.0, 0.0); n];
    let mut blocks = 0;
    for block in samples.chunks_exact(n) {
        if block.iter().all(|s| s.re.is_finite() && s.im.is_finite()) {
            for (a, s) in folded.iter_mut().zip(block) {
                *a += Complex64::new(s.re as f64, s.im as f64);
            }
            blocks += 1;
        }
    }
    if blocks == 0 {
        return Err(Error::NonFinite("every symbol period of the window has a non-finite sample".into()));
    }
    let magnitude: Vec<f64> =
        (0..n).map(|m| (0..n).map(|i| folded[(i + m) % n] * symbol.time[i].conj()).sum::<Complex64>().norm()).collect();
    let (peak_lag, &peak) =
        magnitude
            .iter()
            .enumerate()
            .fold((0, &f64::NEG_INFINITY), |best, (i, v)| if *v > *best.1 { (i, v) } else { best });
    let mean = magnitude.iter().sum::<f64>() / n as f64;
    let (before, after) = (magnitude[(peak_lag + n - 1) % n], magnitude[(peak_lag + 1) % n]);
    let curvature = before - 2.0 * peak + after;
    let offset = if curvature < 0.0 { 0.5 * (before - after) / curvature } else { 0.0 };
    Ok(SymbolTiming {
        first_sample: peak_lag,
        delay_samples: peak_lag as f64 + offset.clamp(-0.5, 0.5),
        peak_to_mean: if mean > 0.0 { peak / mean } else { 1.0 },
        blocks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_shift_of_a_periodic_symbol_with_a_partial_first_block() {
        let symbol = KnownSymbol::generate(20, 11).unwrap();
        for shift in [0usize, 1, 7, 19] {
            // The window starts `20 − shift` samples into a symbol, so the
            // first whole symbol begins at sample `shift`.
            let samples: Vec<Complex32> = (0..20 * 30 + 3)
                .map(|i| symbol.time[(i + 20 - shift) % 20] * Complex64::from_polar(0.01, 1.0))
                .map(|v| Complex32::new(v.re as f32, v.im as f32))
                .collect();
            let t = symbol_timing(&samples, &symbol).unwrap();
            assert_eq!(t.first_sample, shift);
            assert!(t.peak_to_mean > 5.0 && t.blocks == 30);
            assert!((t.delay_samples - shift as f64).abs() < 0.5);
        }
    }

    #[test]
    fn bad_windows_are_errors() {
        let symbol = KnownSymbol::generate(8, 1).unwrap();
        let short = vec![Complex32::new(1.0, 0.0); 5];
        assert!(matches!(symbol_timing(&short, &symbol), Err(Error::TooShort { .. })));
        let nan = vec![Complex32::new(f32::NAN, 0.0); 40];
        assert!(matches!(symbol_timing(&nan, &symbol), Err(Error::NonFinite(_))));
    }
}
