use num_complex::{Complex32, Complex64};

use crate::error::{Error, Result};
use crate::ofdm::{as_doubles, as_doubles_mut, as_floats, widen};

/// `Σ values` in f64, folded to eight f32 lanes first (vectorises; a
/// scalar widening sum of the 2N per-float lanes at every stride cost a
/// sixth of [`SymbolSums::reset`]).
fn lane_sum(values: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let chunks = values.chunks_exact(8);
    let rest: f64 = chunks.remainder().iter().map(|&v| v as f64).sum();
    for c in chunks {
        for l in 0..8 {
            lanes[l] += c[l];
        }
    }
    lanes.iter().map(|&v| v as f64).sum::<f64>() + rest
}

/// Whether every value is finite: `x·0` is 0 for finite `x` and NaN for
/// NaN or ±∞, summed in eight independent lanes (vectorises).
fn finite(y: &[f32]) -> bool {
    let mut lanes = [0.0f32; 8];
    let chunks = y.chunks_exact(8);
    let rest = chunks.remainder().iter().map(|v| v * 0.0).sum::<f32>();
    for c in chunks {
        for l in 0..8 {
            lanes[l] += c[l] * 0.0;
        }
    }
    lanes.iter().sum::<f32>() + rest == 0.0
}

/// One antenna's whole symbols in the time domain, with prefix sums over
/// symbols, so that the sum of any run of symbols costs `O(N × STRIDE)`
/// instead of `O(run × N)`.
///
/// Why time domain: demodulation (`H = FFT(y) / (√N X)`) is linear, so the
/// channel summed over a run of symbols is the demodulated *sum* of the
/// run's samples ([`crate::ofdm::ChannelTransform`]). After detection every
/// step — the tag channel per state (thesis ch. 4.3 (c)), each payload
/// chip's decision — needs only such sums, and a reply has ~1500 symbols
/// but a few dozen runs (chips minus their edge guards): summing raw
/// samples once and transforming a few sums replaces 1500 FFTs per
/// antenna. Prefixes are kept every [`SymbolSums::STRIDE`] symbols (a
/// prefix per symbol would write more memory than it saves); the rest of a
/// run is summed from the samples.
///
/// Numerics: the sums are of `x_n = y_n − r` with `r` the first valid
/// symbol, which removes the periodic tx → rx leakage (up to 60 dB above
/// the tag), so second moments `Σ‖x‖² − ‖Σx‖²/m` do not cancel
/// catastrophically; within a stride they are accumulated in `f32` (the
/// samples' precision), across strides in `f64`. Invalid symbols (a
/// non-finite sample) add nothing and are not counted.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SymbolSums {
    /// Whole symbols covered.
    pub symbols: usize,
    /// Samples per symbol `N`.
    pub n: usize,
    /// The symbols' samples, `symbols × N` (zeros for invalid symbols).
    pub samples: Vec<Complex32>,
    /// Whether symbol `s` had only finite samples.
    pub valid: Vec<bool>,
    /// `r`: the first valid symbol (zeros without one).
    pub reference: Vec<Complex64>,
    /// `(⌊symbols / STRIDE⌋ + 1) × N`: `Σ_{m < j·STRIDE, valid} x_m`.
    pub sum: Vec<Complex64>,
    /// `⌊symbols / STRIDE⌋ + 1`: `Σ_{m < j·STRIDE, valid} ‖x_m‖²`.
    pub energy: Vec<f64>,
    /// `symbols + 1`: valid symbols before `s`.
    pub count: Vec<u32>,
}

impl SymbolSums {
    /// Symbols between stored prefixes.
    pub const STRIDE: usize = 8;

    /// The whole symbols of `window` from `first_sample` on, `n` samples
    /// each (buffers reused). Errors: [`Error::TooShort`] without a whole
    /// symbol, [`Error::NonFinite`] when no symbol is finite.
    pub fn reset(&mut self, window: &[Complex32], first_sample: usize, n: usize) -> Result<()> {
        let available = window.len().saturating_sub(first_sample);
        let symbols = available.checked_div(n).unwrap_or(0);
        if symbols == 0 {
            return Err(Error::TooShort { what: "demodulation (samples from the first symbol)", needed: n, got: available });
        }
        self.symbols = symbols;
        self.n = n;
        let window = &window[first_sample..first_sample + symbols * n];
        let Some(first) = window.chunks_exact(n).position(|y| finite(as_floats(y))) else {
            return Err(Error::NonFinite(format!("all {symbols} symbols of the window have non-finite samples")));
        };
        let reference32: Vec<Complex32> = window[first * n..(first + 1) * n].to_vec();
        self.reference.clear();
        self.reference.extend(reference32.iter().map(|&v| widen(v)));
        let reference = as_floats(&reference32);

        let blocks = symbols / Self::STRIDE + 1;
        let zero = Complex64::new(0.0, 0.0);
        self.samples.clear();
        self.samples.reserve(symbols * n);
        self.valid.clear();
        self.valid.reserve(symbols);
        self.sum.clear();
        self.sum.reserve(blocks * n);
        self.energy.clear();
        self.energy.reserve(blocks);
        self.count.clear();
        self.count.reserve(symbols + 1);
        let mut total = vec![zero; n];
        let mut total_energy = 0.0f64;
        // Per-float accumulators within a stride, over the interleaved
        // [re, im, …] samples: independent lanes, so the loop vectorises in
        // full width (a scalar energy sum would chain every add).
        let mut block = vec![0.0f32; 2 * n];
        let mut block_energy = vec![0.0f32; 2 * n];
        let mut count = 0u32;
        // One pass over the window: copy, validity, sums (separate passes
        // and complex-valued lanes cost 50 µs per antenna of the thesis
        // set-up, a third of its job).
        for (s, y) in window.chunks_exact(n).enumerate() {
            if s % Self::STRIDE == 0 {
                for (t, b) in total.iter_mut().zip(block.chunks_exact(2)) {
                    *t += Complex64::new(b[0] as f64, b[1] as f64);
                }
                block.iter_mut().for_each(|b| *b = 0.0);
                total_energy += lane_sum(&block_energy);
                block_energy.iter_mut().for_each(|e| *e = 0.0);
                self.sum.extend_from_slice(&total);
                self.energy.push(total_energy);
            }
            self.count.push(count);
            let y = as_floats(y);
            let ok = finite(y);
            self.valid.push(ok);
            if ok {
                for (((b, e), &v), r) in block.iter_mut().zip(block_energy.iter_mut()).zip(y).zip(reference) {
                    let x = v - r;
                    *b += x;
                    *e += x * x;
                }
                count += 1;
            }
        }
        // The samples (zeros for invalid symbols): one copy, then clear the few invalid ones.
        self.samples.extend_from_slice(window);
        for (y, _) in self.samples.chunks_exact_mut(n).zip(&self.valid).filter(|(_, &ok)| !ok) {
            y.iter_mut().for_each(|v| *v = Complex32::new(0.0, 0.0));
        }
        if symbols % Self::STRIDE == 0 {
            for (t, b) in total.iter_mut().zip(block.chunks_exact(2)) {
                *t += Complex64::new(b[0] as f64, b[1] as f64);
            }
            self.sum.extend_from_slice(&total);
            self.energy.push(total_energy + lane_sum(&block_energy));
        }
        self.count.push(count);
        Ok(())
    }

    /// Symbol `s`'s samples.
    #[inline]
    pub fn row(&self, s: usize) -> &[Complex32] {
        &self.samples[s * self.n..(s + 1) * self.n]
    }

    /// Keeps the first `symbols` symbols (no-op when already shorter).
    pub fn truncate(&mut self, symbols: usize) {
        if symbols < self.symbols {
            self.symbols = symbols;
            let blocks = symbols / Self::STRIDE + 1;
            self.samples.truncate(symbols * self.n);
            self.valid.truncate(symbols);
            self.sum.truncate(blocks * self.n);
            self.energy.truncate(blocks);
            self.count.truncate(symbols + 1);
        }
    }

    /// Valid symbols in `from..to` (clamped to the span).
    #[inline]
    pub fn count_in(&self, from: usize, to: usize) -> usize {
        let (a, b) = (from.min(self.symbols), to.min(self.symbols));
        if b <= a {
            0
        } else {
            (self.count[b] - self.count[a]) as usize
        }
    }

    /// Adds `Σ_{s ∈ from..to, valid} x_s` (`N` values) to `sum` and, when
    /// given, `Σ ‖x_s‖²` to `energy`; returns the number of valid symbols.
    pub fn add_interval(&self, from: usize, to: usize, sum: &mut [Complex64], mut energy: Option<&mut f64>) -> usize {
        let (a, b) = (from.min(self.symbols), to.min(self.symbols));
        if b <= a {
            return 0;
        }
        let stride = Self::STRIDE;
        let (first_block, last_block) = (a.div_ceil(stride), b / stride);
        if last_block <= first_block {
            self.add_rows(a, b, sum, energy);
        } else {
            self.add_rows(a, first_block * stride, sum, energy.as_deref_mut());
            let n = self.n;
            let (lo, hi) = (first_block * n, last_block * n);
            sum.iter_mut().zip(self.sum[lo..lo + n].iter().zip(&self.sum[hi..hi + n])).for_each(|(s, (l, h))| *s += h - l);
            if let Some(e) = energy.as_deref_mut() {
                *e += self.energy[last_block] - self.energy[first_block];
            }
            self.add_rows(last_block * stride, b, sum, energy);
        }
        (self.count[b] - self.count[a]) as usize
    }

    /// Rows `a..b` one by one, over interleaved real lanes: the complex
    /// loop with its optional energy inside did not vectorise and was a
    /// third of the fusion stage.
    fn add_rows(&self, a: usize, b: usize, sum: &mut [Complex64], energy: Option<&mut f64>) {
        let total = as_doubles_mut(sum);
        let reference = as_doubles(&self.reference);
        let mut lanes = [0.0f64; 8];
        let mut rest = 0.0f64;
        for s in (a..b).filter(|&s| self.valid[s]) {
            let y = as_floats(self.row(s));
            for ((o, &v), &r) in total.iter_mut().zip(y).zip(reference) {
                *o += v as f64 - r;
            }
            if energy.is_some() {
                let (yc, rc) = (y.chunks_exact(8), reference.chunks_exact(8));
                rest += yc.remainder().iter().zip(rc.remainder()).map(|(&v, &r)| (v as f64 - r).powi(2)).sum::<f64>();
                for (y8, r8) in yc.zip(rc) {
                    for l in 0..8 {
                        let x = y8[l] as f64 - r8[l];
                        lanes[l] += x * x;
                    }
                }
            }
        }
        if let Some(e) = energy {
            *e += lanes.iter().sum::<f64>() + rest;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(symbols: usize, n: usize) -> Vec<Complex32> {
        (0..symbols * n + 3)
            .map(|i| Complex32::new(1e3 + (i % n) as f32 + 0.01 * (i / n) as f32, ((i * 7) % 11) as f32 * 0.1))
            .collect()
    }

    #[test]
    fn intervals_match_direct_sums_and_skip_invalid_symbols() {
        let n = 4;
        let mut w = window(45, n);
        // Symbols 0 and 17 hold a non-finite sample (the window starts at 2).
        w[3] = Complex32::new(f32::NAN, 0.0);
        w[2 + 17 * n + 1] = Complex32::new(0.0, f32::INFINITY);
        let mut sums = SymbolSums::default();
        sums.reset(&w, 2, n).unwrap();
        assert_eq!(sums.symbols, 45);
        assert!(!sums.valid[0] && !sums.valid[17] && sums.valid[1]);
        assert_eq!(sums.reference, sums.row(1).iter().map(|&v| widen(v)).collect::<Vec<_>>());
        for a in 0..46 {
            for b in a..46 {
                let mut s = vec![Complex64::new(0.0, 0.0); n];
                let mut e = 0.0;
                let m = sums.add_interval(a, b, &mut s, Some(&mut e));
                let rows: Vec<usize> = (a..b.min(45)).filter(|&k| sums.valid[k]).collect();
                assert_eq!(m, rows.len());
                let mut direct_e = 0.0;
                for t in 0..n {
                    let d: Complex64 = rows.iter().map(|&k| widen(w[2 + k * n + t]) - sums.reference[t]).sum();
                    direct_e += rows.iter().map(|&k| (widen(w[2 + k * n + t]) - sums.reference[t]).norm_sqr()).sum::<f64>();
                    assert!((s[t] - d).norm() < 1e-6 * (1.0 + d.norm()), "{a}..{b}");
                }
                assert!((e - direct_e).abs() < 1e-4 * (1.0 + direct_e), "{a}..{b}: {e} vs {direct_e}");
            }
        }
        sums.truncate(4);
        assert_eq!((sums.symbols, sums.count_in(0, 9)), (4, 3));
    }

    #[test]
    fn too_short_and_all_non_finite_windows_are_errors() {
        let mut sums = SymbolSums::default();
        assert!(matches!(sums.reset(&window(1, 8)[..7], 0, 8), Err(Error::TooShort { .. })));
        let nan = vec![Complex32::new(f32::NAN, 0.0); 32];
        assert!(matches!(sums.reset(&nan, 0, 8), Err(Error::NonFinite(_))));
    }
}
