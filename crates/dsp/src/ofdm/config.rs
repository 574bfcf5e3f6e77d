use num_complex::Complex64;

use crate::error::{Error, Result};

/// The helper's OFDM parameters and the tag's backscatter link frequency.
///
/// Thesis ch. 4.2: an OFDM symbol of `N` samples at `B` samples/s must fit
/// inside one tag state, i.e. `T_symbol = N / B < 1 / (2 BLF)`, so
/// `N < B / (2 BLF)` (100 MHz and 500 kHz allow N < 100; the implementation,
/// ch. 6, uses N = 20, B = 100 MHz, BLF = 40 kHz).
#[derive(Debug, Clone, PartialEq)]
pub struct OfdmConfig {
    /// Bandwidth `B` = complex baseband sample rate, Hz.
    pub bandwidth_hz: f64,
    /// `N`: FFT size = samples per OFDM symbol; `N − 1` subcarriers carry
    /// energy (DC dropped).
    pub subcarriers: usize,
    /// RF centre frequency (the DC bin), Hz.
    pub centre_hz: f64,
    /// Nominal backscatter link frequency the reader asked for, Hz.
    pub blf_hz: f64,
}

impl OfdmConfig {
    /// A validated configuration. Fails with [`Error::BadConfig`] when a
    /// value is non-finite or out of domain (`B > 0`, `N ≥ 2`,
    /// `centre_hz > B / 2` so every subcarrier is a positive RF frequency,
    /// `BLF > 0`) or when the design rule `N < B / (2 BLF)` is broken.
    pub fn new(bandwidth_hz: f64, subcarriers: usize, centre_hz: f64, blf_hz: f64) -> Result<Self> {
        let config = Self { bandwidth_hz, subcarriers, centre_hz, blf_hz };
        config.validate()?;
        Ok(config)
    }

    /// Checks the domain and the design rule (see [`OfdmConfig::new`]).
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::BadConfig(m));
        if !(self.bandwidth_hz.is_finite() && self.bandwidth_hz > 0.0) {
            return bad(format!("bandwidth_hz must be a positive number, got {}", self.bandwidth_hz));
        }
        if !(self.blf_hz.is_finite() && self.blf_hz > 0.0) {
            return bad(format!("blf_hz must be a positive number, got {}", self.blf_hz));
        }
        if self.subcarriers < 2 {
            return bad(format!("subcarriers must be at least 2 (one is the dropped DC), got {}", self.subcarriers));
        }
        if !(self.centre_hz.is_finite() && self.centre_hz > self.bandwidth_hz / 2.0) {
            return bad(format!(
                "centre_hz must exceed half the bandwidth ({} Hz), got {}",
                self.bandwidth_hz / 2.0,
                self.centre_hz
            ));
        }
        let limit = self.bandwidth_hz / (2.0 * self.blf_hz);
        if (self.subcarriers as f64) >= limit {
            return bad(format!(
                "design rule N < B/(2 BLF) broken (thesis ch. 4.2): N = {} but B/(2 BLF) = {:.3} for B = {} Hz, \
                 BLF = {} Hz; a symbol of N/B = {:.3} us would straddle a tag state of 1/(2 BLF) = {:.3} us \
                 (largest N allowed: {})",
                self.subcarriers,
                limit,
                self.bandwidth_hz,
                self.blf_hz,
                1e6 * self.symbol_duration_s(),
                1e6 / (2.0 * self.blf_hz),
                Self::max_subcarriers(self.bandwidth_hz, self.blf_hz)
            ));
        }
        Ok(())
    }

    /// The largest `N` with `N < B / (2 BLF)` (0 if none), for messages and
    /// for choosing a design.
    pub fn max_subcarriers(bandwidth_hz: f64, blf_hz: f64) -> usize {
        let limit = bandwidth_hz / (2.0 * blf_hz);
        if !(limit.is_finite() && limit > 1.0) {
            return 0;
        }
        let n = limit.ceil() as usize - 1;
        // ceil(limit) − 1 < limit always holds; guard float edge cases.
        if (n as f64) < limit {
            n
        } else {
            n.saturating_sub(1)
        }
    }

    /// OFDM symbol duration `N / B`, seconds.
    pub fn symbol_duration_s(&self) -> f64 {
        self.subcarriers as f64 / self.bandwidth_hz
    }

    /// Duration of one tag chip (half a BLF period, the shortest constant
    /// tag state of FM0 and Miller) in OFDM symbols: `B / (2 BLF N)`.
    /// The design rule makes it > 1.
    pub fn chip_symbols(&self) -> f64 {
        self.bandwidth_hz / (2.0 * self.blf_hz * self.subcarriers as f64)
    }

    /// Number of active subcarriers, `N − 1` (DC dropped).
    pub fn active_count(&self) -> usize {
        self.subcarriers - 1
    }

    /// Signed bin numbers `k'` of the active subcarriers in ascending
    /// frequency: `−⌊N/2⌋ … ⌈N/2⌉ − 1` without 0 (for even `N` the Nyquist
    /// bin `−N/2` is kept; only DC is dropped, ch. 4.3).
    pub fn signed_bins(&self) -> Vec<i64> {
        let n = self.subcarriers as i64;
        (-(n / 2)..(n - n / 2)).filter(|&k| k != 0).collect()
    }

    /// FFT bin index (`k' mod N`) of each active subcarrier, ascending
    /// frequency.
    pub fn active_bins(&self) -> Vec<usize> {
        let n = self.subcarriers as i64;
        self.signed_bins().into_iter().map(|k| k.rem_euclid(n) as usize).collect()
    }

    /// What demodulation divides by: the active bins (ascending frequency)
    /// and `1 / (√N X[k])` for each — the unitary FFT's scaling and the
    /// known symbol in one factor. Errors when `symbol` does not have `N`
    /// bins or the configuration is invalid.
    pub fn demodulation_factors(&self, symbol: &super::KnownSymbol) -> Result<(Vec<usize>, Vec<Complex64>)> {
        self.validate()?;
        let n = self.subcarriers;
        if symbol.len() != n {
            return Err(Error::Shape(format!("symbol has {} bins, configuration has N = {n}", symbol.len())));
        }
        let bins = self.active_bins();
        let scale = 1.0 / (n as f64).sqrt();
        let inverse = bins.iter().map(|&k| scale / symbol.frequency[k]).collect();
        Ok((bins, inverse))
    }

    /// RF frequency of each active subcarrier, `centre + k' B / N`, Hz,
    /// ascending.
    pub fn subcarrier_frequencies(&self) -> Vec<f64> {
        let spacing = self.bandwidth_hz / self.subcarriers as f64;
        self.signed_bins().into_iter().map(|k| self.centre_hz + k as f64 * spacing).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_configuration_is_accepted() {
        let c = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
        assert!((c.chip_symbols() - 62.5).abs() < 1e-12);
        assert_eq!(c.active_count(), 19);
        assert!((c.symbol_duration_s() - 0.2e-6).abs() < 1e-18);
    }

    #[test]
    fn design_rule_is_enforced_with_a_clear_error() {
        // Thesis example: 100 MHz and 500 kHz allow N < 100.
        assert!(OfdmConfig::new(100e6, 99, 915e6, 500e3).is_ok());
        let e = OfdmConfig::new(100e6, 100, 915e6, 500e3).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, Error::BadConfig(_)));
        assert!(text.contains("N < B/(2 BLF)") && text.contains("largest N allowed: 99"), "{text}");
        assert_eq!(OfdmConfig::max_subcarriers(100e6, 500e3), 99);
        assert_eq!(OfdmConfig::max_subcarriers(100e6, 40e3), 1249);
    }

    #[test]
    fn out_of_domain_values_are_rejected() {
        for (b, n, fc, blf) in [
            (f64::NAN, 20, 915e6, 40e3),
            (-1.0, 20, 915e6, 40e3),
            (100e6, 1, 915e6, 40e3),
            (100e6, 20, 10e6, 40e3),
            (100e6, 20, 915e6, 0.0),
            (100e6, 20, f64::INFINITY, 40e3),
        ] {
            assert!(matches!(OfdmConfig::new(b, n, fc, blf), Err(Error::BadConfig(_))), "{b} {n} {fc} {blf}");
        }
    }

    #[test]
    fn subcarriers_are_ascending_without_dc() {
        let even = OfdmConfig::new(100e6, 8, 915e6, 40e3).unwrap();
        assert_eq!(even.signed_bins(), vec![-4, -3, -2, -1, 1, 2, 3]);
        assert_eq!(even.active_bins(), vec![4, 5, 6, 7, 1, 2, 3]);
        let f = even.subcarrier_frequencies();
        assert!((f[0] - (915e6 - 50e6)).abs() < 1e-3 && (f[6] - (915e6 + 37.5e6)).abs() < 1e-3);
        assert!(f.windows(2).all(|w| w[1] > w[0]) && !f.contains(&915e6));
        let odd = OfdmConfig::new(100e6, 5, 915e6, 40e3).unwrap();
        assert_eq!(odd.signed_bins(), vec![-2, -1, 1, 2]);
    }
}
