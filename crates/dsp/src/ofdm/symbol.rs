use num_complex::Complex64;
use rustfft::FftPlanner;

use crate::error::{Error, Result};

/// The known OFDM symbol `X(f)` that the helper transmits back to back.
///
/// Thesis ch. 4.2–4.3: the receiver estimates `H(f) = Y(f) / X(f)`; the DC
/// bin carries nothing (it is the least robust to noise and leaves the
/// ADC's dynamic range to the signal). Every active bin has `|X| = 1`, so
/// every subcarrier gets the same power and the division never amplifies
/// noise.
#[derive(Debug, Clone, PartialEq)]
pub struct KnownSymbol {
    /// `X[k]`, FFT order (`k = 0 … N−1`, bin 0 = DC = 0), unit magnitude
    /// elsewhere.
    pub frequency: Vec<Complex64>,
    /// `x[n] = (1/√N) Σ_k X[k] e^{j2πkn/N}`: the unitary inverse FFT, one
    /// symbol of baseband samples (unitless, mean power `(N−1)/N`).
    pub time: Vec<Complex64>,
}

/// SplitMix64: a tiny, fixed pseudo-random generator, so that a seed gives
/// the same symbol on every platform and every version of this crate
/// (independent of `rand`'s algorithm choices).
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl KnownSymbol {
    /// A symbol of `subcarriers` bins with uniformly random phases drawn
    /// from `seed` (deterministic), DC dropped. Needs `subcarriers ≥ 2`.
    pub fn generate(subcarriers: usize, seed: u64) -> Result<Self> {
        if subcarriers < 2 {
            return Err(Error::BadConfig(format!("a symbol needs at least 2 bins, got {subcarriers}")));
        }
        let mut state = seed;
        let frequency = (0..subcarriers)
            .map(|k| {
                let draw = splitmix64(&mut state);
                if k == 0 {
                    return Complex64::new(0.0, 0.0);
                }
                // 53 random bits → a phase in [0, 2π).
                let u = (draw >> 11) as f64 / (1u64 << 53) as f64;
                Complex64::from_polar(1.0, std::f64::consts::TAU * u)
            })
            .collect();
        Self::from_frequency(frequency)
    }

    /// A symbol from given bin values (FFT order), e.g. read from a
    /// recording's metadata. The DC bin must be 0 and every other bin
    /// finite with magnitude within 1e-6 of 1.
    pub fn from_frequency(frequency: Vec<Complex64>) -> Result<Self> {
        let n = frequency.len();
        if n < 2 {
            return Err(Error::BadConfig(format!("a symbol needs at least 2 bins, got {n}")));
        }
        if frequency[0].norm() > 1e-9 {
            return Err(Error::BadConfig(format!(
                "the DC bin of the symbol must be 0 (dropped), got {}",
                frequency[0]
            )));
        }
        if let Some(k) = (1..n).find(|&k| !frequency[k].is_finite() || (frequency[k].norm() - 1.0).abs() > 1e-6) {
            return Err(Error::BadConfig(format!(
                "symbol bin {k} must be finite with unit magnitude, got {}",
                frequency[k]
            )));
        }
        let mut time = frequency.clone();
        FftPlanner::<f64>::new().plan_fft_inverse(n).process(&mut time);
        let scale = 1.0 / (n as f64).sqrt();
        time.iter_mut().for_each(|v| *v *= scale);
        Ok(Self { frequency, time })
    }

    /// `N`, the number of bins (= samples per symbol).
    pub fn len(&self) -> usize {
        self.frequency.len()
    }

    /// Always false: a symbol has at least two bins.
    pub fn is_empty(&self) -> bool {
        self.frequency.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generation_is_deterministic_unit_magnitude_and_dc_free() {
        let a = KnownSymbol::generate(20, 7).unwrap();
        let b = KnownSymbol::generate(20, 7).unwrap();
        let c = KnownSymbol::generate(20, 8).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.frequency, c.frequency);
        assert_eq!(a.frequency[0], Complex64::new(0.0, 0.0));
        assert!(a.frequency[1..].iter().all(|x| (x.norm() - 1.0).abs() < 1e-12));
        // Parseval with the unitary transform: Σ|x|² = Σ|X|² = N − 1.
        let energy: f64 = a.time.iter().map(|v| v.norm_sqr()).sum();
        assert!((energy - 19.0).abs() < 1e-9);
        // No DC in time: the samples sum to zero.
        let dc: Complex64 = a.time.iter().sum();
        assert!(dc.norm() < 1e-9);
    }

    #[test]
    fn invalid_bins_are_rejected() {
        let mut x = KnownSymbol::generate(8, 1).unwrap().frequency;
        x[0] = Complex64::new(1.0, 0.0);
        assert!(matches!(KnownSymbol::from_frequency(x.clone()), Err(Error::BadConfig(_))));
        x[0] = Complex64::new(0.0, 0.0);
        x[3] = Complex64::new(0.5, 0.0);
        assert!(matches!(KnownSymbol::from_frequency(x.clone()), Err(Error::BadConfig(_))));
        x[3] = Complex64::new(f64::NAN, 0.0);
        assert!(KnownSymbol::from_frequency(x).is_err());
        assert!(KnownSymbol::generate(1, 0).is_err());
    }
}
