use std::sync::Arc;

use num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};

use super::{KnownSymbol, OfdmConfig};
use crate::error::Result;

/// The demodulation of one symbol as a linear map from its `N` time
/// samples to the channel on the active subcarriers,
/// `H(f) = FFT(y)(k_f) / (√N X(k_f))` (thesis ch. 4.2).
///
/// Why a separate, double-precision transform: the map is linear, so the
/// channel summed over any run of symbols is the transform of the samples
/// summed over that run. The real-time path therefore sums raw samples
/// (`estimate::SymbolSums`) and transforms a few dozen sums per reply
/// instead of 1500 symbols; and a projection `Σ_f v̄_f H_n(f)` of every
/// symbol is one dot product with the time-domain filter
/// [`ChannelTransform::projection_filter`], no FFT at all.
pub struct ChannelTransform {
    n: usize,
    fft: Arc<dyn Fft<f64>>,
    scratch: Vec<Complex64>,
    buffer: Vec<Complex64>,
    /// FFT bin of each active subcarrier, ascending frequency.
    bins: Vec<usize>,
    /// `1 / (√N X[k])` per active subcarrier.
    inverse: Vec<Complex64>,
    /// `e^{−j2π k_f t/N} / (√N X(k_f))`, `N × (N − 1)` row-major by `t`:
    /// the demodulation as a matrix, for [`Self::projection_filter`]
    /// (computed once: 380 `sin_cos` per call cost ~8 µs per antenna).
    kernel: Vec<Complex64>,
}

impl ChannelTransform {
    pub fn new(config: &OfdmConfig, symbol: &KnownSymbol) -> Result<Self> {
        let (bins, inverse) = config.demodulation_factors(symbol)?;
        let n = config.subcarriers;
        let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
        let scratch = vec![Complex64::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        let kernel = (0..n)
            .flat_map(|t| {
                bins.iter().zip(&inverse).map(move |(&k, inv)| {
                    // (k t) mod N keeps the angle exact for any symbol length.
                    inv * Complex64::from_polar(1.0, -std::f64::consts::TAU * ((k * t) % n) as f64 / n as f64)
                })
            })
            .collect();
        Ok(Self { n, fft, scratch, buffer: vec![Complex64::new(0.0, 0.0); n], bins, inverse, kernel })
    }

    /// Samples per symbol `N`.
    pub fn symbol_len(&self) -> usize {
        self.n
    }

    /// Active subcarriers `N − 1`.
    pub fn subcarriers(&self) -> usize {
        self.bins.len()
    }

    /// `H(f)` of the time-domain vector `y` (`N` values) into `out`
    /// (`N − 1` values, ascending frequency).
    pub fn apply(&mut self, y: &[Complex64], out: &mut [Complex64]) {
        self.buffer.copy_from_slice(y);
        self.fft.process_with_scratch(&mut self.buffer, &mut self.scratch);
        for ((h, &k), inv) in out.iter_mut().zip(&self.bins).zip(&self.inverse) {
            *h = self.buffer[k] * inv;
        }
    }

    /// The time-domain filter `w` with `Σ_t w(t) y(t) = Σ_f conj(v_f) H(f)`
    /// for every symbol `y`: `w(t) = Σ_f conj(v_f) e^{−j2π k_f t/N} / (√N X(k_f))`.
    pub fn projection_filter(&self, v: &[Complex64]) -> Vec<Complex32> {
        let f_count = self.bins.len();
        self.kernel
            .chunks_exact(f_count)
            .map(|row| {
                let w: Complex64 = v.iter().zip(row).map(|(v, e)| v.conj() * e).sum();
                Complex32::new(w.re as f32, w.im as f32)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ofdm::{ChannelMatrix, Demodulator};

    #[test]
    fn agrees_with_the_demodulator_and_the_filter_with_the_projection() {
        let config = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(20, 5).unwrap();
        let samples: Vec<Complex32> =
            (0..60).map(|i| Complex32::new((0.3 * i as f32).sin() * 40.0, (0.17 * i as f32).cos() * 25.0)).collect();
        let mut demodulator = Demodulator::new(&config, &symbol).unwrap();
        let mut h = ChannelMatrix::default();
        demodulator.demodulate(&samples, 0, &mut h).unwrap();
        let mut transform = ChannelTransform::new(&config, &symbol).unwrap();
        let mut out = vec![Complex64::new(0.0, 0.0); 19];
        let v: Vec<Complex64> = (0..19).map(|f| Complex64::from_polar(1.0 / 19f64.sqrt(), 0.4 * f as f64)).collect();
        let w = transform.projection_filter(&v);
        for s in 0..3 {
            let y: Vec<Complex64> = samples[s * 20..(s + 1) * 20].iter().map(|v| Complex64::new(v.re as f64, v.im as f64)).collect();
            transform.apply(&y, &mut out);
            for f in 0..19 {
                assert!((out[f] - h.at(s, f)).norm() < 1e-4 * (1.0 + out[f].norm()), "{s} {f}");
            }
            let direct: Complex64 = v.iter().zip(&out).map(|(v, h)| v.conj() * h).sum();
            let filtered: Complex64 = w.iter().zip(&y).map(|(w, y)| Complex64::new(w.re as f64, w.im as f64) * y).sum();
            assert!((direct - filtered).norm() < 1e-4 * (1.0 + direct.norm()), "{direct} {filtered}");
        }
    }
}
