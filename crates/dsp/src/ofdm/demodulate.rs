use std::sync::Arc;

use num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

use super::{ChannelMatrix, KnownSymbol, OfdmConfig};
use crate::error::{Error, Result};

/// Per-symbol OFDM demodulation: `H(f, n) = FFT(y_n)(f) / X(f)` (thesis
/// ch. 4.2, Fig. 4-1).
///
/// Planned once; every call reuses the FFT plan and the sample and scratch
/// buffers (the helper runs this at ≥ 300 replies/s × 4 rx). All whole
/// symbols of a window are transformed in one batched rustfft call, in
/// `f32` like the samples: twice the SIMD width of `f64` and no
/// conversion pass; the rounding (~1e-7 of the leakage, i.e. ~1e-4 of a
/// tag 60 dB weaker, per symbol) is far below the per-symbol noise, and
/// everything after the FFT is `f64`.
pub struct Demodulator {
    n: usize,
    fft: Arc<dyn Fft<f32>>,
    buffer: Vec<Complex32>,
    scratch: Vec<Complex32>,
    /// FFT bin of each active subcarrier, ascending frequency.
    bins: Vec<usize>,
    /// `1 / (√N X[k])` per active subcarrier: the unitary scaling and the
    /// division by the known symbol in one multiplication.
    inverse: Vec<Complex32>,
}

impl Demodulator {
    /// A demodulator for `config` and its known symbol (`symbol.len()` must
    /// equal `config.subcarriers`).
    pub fn new(config: &OfdmConfig, symbol: &KnownSymbol) -> Result<Self> {
        let (bins, inverse) = config.demodulation_factors(symbol)?;
        let n = config.subcarriers;
        let fft = FftPlanner::<f32>::new().plan_fft_forward(n);
        let scratch = vec![Complex32::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        let inverse = inverse.iter().map(|v| Complex32::new(v.re as f32, v.im as f32)).collect();
        Ok(Self { n, fft, buffer: Vec::new(), scratch, bins, inverse })
    }

    /// Samples per symbol `N`.
    pub fn symbol_len(&self) -> usize {
        self.n
    }

    /// Demodulates every whole symbol of `samples` starting at sample
    /// `first_sample` into `out` (resized: `⌊(len − first)/N⌋` symbols × `N − 1`
    /// subcarriers). A symbol with a non-finite sample is marked invalid
    /// (NaN row). Errors: [`Error::TooShort`] without one whole symbol,
    /// [`Error::NonFinite`] when no symbol is valid.
    pub fn demodulate(&mut self, samples: &[Complex32], first_sample: usize, out: &mut ChannelMatrix) -> Result<()> {
        let n = self.n;
        let available = samples.len().saturating_sub(first_sample);
        let symbols = available / n;
        if symbols == 0 {
            return Err(Error::TooShort {
                what: "demodulation (samples from the first symbol)",
                needed: n,
                got: available,
            });
        }
        let f_count = self.bins.len();
        out.resize(symbols, f_count);
        self.buffer.clear();
        self.buffer.extend_from_slice(&samples[first_sample..first_sample + symbols * n]);
        for (j, chunk) in self.buffer.chunks_exact_mut(n).enumerate() {
            // x·0 is 0 for finite x and NaN for NaN or ±∞: one vectorisable sum.
            let finite = chunk.iter().map(|v| v.re * 0.0 + v.im * 0.0).sum::<f32>() == 0.0;
            out.valid[j] = finite;
            if !finite {
                // Zeros keep the batched FFT clean; the row is set to NaN below.
                chunk.iter_mut().for_each(|v| *v = Complex32::new(0.0, 0.0));
            }
        }
        self.fft.process_with_scratch(&mut self.buffer, &mut self.scratch);
        let nan = Complex32::new(f32::NAN, f32::NAN);
        for ((spectrum, row), &valid) in self.buffer.chunks_exact(n).zip(out.data.chunks_exact_mut(f_count)).zip(&out.valid) {
            if valid {
                for ((h, &k), &inv) in row.iter_mut().zip(&self.bins).zip(&self.inverse) {
                    *h = spectrum[k] * inv;
                }
            } else {
                row.iter_mut().for_each(|h| *h = nan);
            }
        }
        if !out.valid.iter().any(|&v| v) {
            return Err(Error::NonFinite(format!("all {symbols} symbols of the window have non-finite samples")));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;

    fn periodic(symbol: &KnownSymbol, channel: &[Complex64], len: usize, shift: usize) -> Vec<Complex32> {
        // y = IFFT(X · H) repeated: the steady state of back-to-back symbols.
        let n = symbol.len();
        let mut spectrum: Vec<Complex64> = symbol.frequency.iter().zip(channel).map(|(x, h)| x * h).collect();
        FftPlanner::<f64>::new().plan_fft_inverse(n).process(&mut spectrum);
        let scale = 1.0 / (n as f64).sqrt();
        (0..len).map(|i| spectrum[(i + shift) % n] * scale).map(|v| Complex32::new(v.re as f32, v.im as f32)).collect()
    }

    #[test]
    fn fft_round_trip_recovers_the_channel() {
        let config = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(20, 3).unwrap();
        // A channel with a known value on every bin (FFT order).
        let channel: Vec<Complex64> =
            (0..20).map(|k| Complex64::from_polar(0.5 + 0.02 * k as f64, 0.3 * k as f64)).collect();
        let samples = periodic(&symbol, &channel, 20 * 7 + 5, 0);
        let mut demodulator = Demodulator::new(&config, &symbol).unwrap();
        let mut h = ChannelMatrix::default();
        demodulator.demodulate(&samples, 0, &mut h).unwrap();
        assert_eq!((h.symbols, h.subcarriers), (7, 19));
        for j in 0..7 {
            for (f, &k) in config.active_bins().iter().enumerate() {
                assert!((h.at(j, f) - channel[k]).norm() < 1e-5, "symbol {j} bin {k}");
            }
        }
    }

    #[test]
    fn a_non_finite_symbol_is_marked_and_an_all_nan_window_is_an_error() {
        let config = OfdmConfig::new(100e6, 8, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(8, 3).unwrap();
        let mut samples = periodic(&symbol, &[Complex64::new(1.0, 0.0); 8], 8 * 4, 0);
        samples[9] = Complex32::new(f32::NAN, 0.0);
        let mut demodulator = Demodulator::new(&config, &symbol).unwrap();
        let mut h = ChannelMatrix::default();
        demodulator.demodulate(&samples, 0, &mut h).unwrap();
        assert_eq!(h.valid, vec![true, false, true, true]);
        assert!(h.row(1).iter().all(|v| v.re.is_nan()));
        assert!((h.at(2, 0) - Complex64::new(1.0, 0.0)).norm() < 1e-5);
        let all_nan = vec![Complex32::new(f32::NAN, f32::NAN); 32];
        assert!(matches!(demodulator.demodulate(&all_nan, 0, &mut h), Err(Error::NonFinite(_))));
        assert!(matches!(demodulator.demodulate(&samples[..7], 0, &mut h), Err(Error::TooShort { .. })));
        assert!(matches!(demodulator.demodulate(&samples, 30, &mut h), Err(Error::TooShort { .. })));
    }

    #[test]
    fn symbol_size_must_match() {
        let config = OfdmConfig::new(100e6, 8, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(10, 3).unwrap();
        assert!(matches!(Demodulator::new(&config, &symbol), Err(Error::Shape(_))));
    }
}
