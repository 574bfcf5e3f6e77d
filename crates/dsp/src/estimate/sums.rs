use num_complex::Complex64;

use num_complex::Complex32;

use crate::ofdm::{widen, ChannelMatrix};

/// Prefix sums over the symbols of one antenna's per-symbol channels
/// `H(f, n)`, so that the sum over any run of symbols costs
/// `O(subcarriers × STRIDE)` instead of `O(run × subcarriers)`.
///
/// Why: after detection every later step — the tag channel per state
/// (thesis ch. 4.3 (c)), its variance, each payload chip's decision — sums
/// `H` over runs of symbols (chips minus their edge guards). A reply has
/// ~1500 symbols but only a few dozen runs, so one pass building these
/// sums (done by the antenna's worker in the real-time runtime) replaces
/// several passes over the whole matrix on the fusion thread. Prefixes are
/// kept every [`SymbolSums::STRIDE`] symbols (the rest of a run is summed
/// from the matrix): a prefix per symbol would write 1.5 times the
/// matrix's size, and that memory traffic cost more than it saved.
///
/// Numerics: the sums are of `x_n = H(·, n) − r` with `r` the first valid
/// row, which removes the tx → rx leakage (up to 60 dB above the tag), so
/// second moments `Σ|x|² − |Σx|²/m` do not cancel catastrophically.
/// Invalid symbols add nothing and are not counted. The methods take the
/// matrix the sums were built from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SymbolSums {
    /// Symbols covered (rows of the matrix).
    pub symbols: usize,
    /// Active subcarriers.
    pub subcarriers: usize,
    /// `r(f)`: the first valid row (zeros without one).
    pub reference: Vec<Complex64>,
    /// `(⌊symbols / STRIDE⌋ + 1) × subcarriers`: `Σ_{m < j·STRIDE, valid} x_m(f)`.
    pub sum: Vec<Complex64>,
    /// The same for `|x_m(f)|²`.
    pub sum_sq: Vec<f64>,
    /// `symbols + 1`: valid symbols before `n`.
    pub count: Vec<u32>,
    /// Running sums while rows are pushed.
    acc: Vec<Complex64>,
    acc_sq: Vec<f64>,
}

impl SymbolSums {
    /// Symbols between stored prefixes.
    pub const STRIDE: usize = 8;

    /// The sums of `h` (buffers reused).
    pub fn reset(&mut self, h: &ChannelMatrix) {
        self.begin(h.symbols, h.subcarriers);
        for (row, &valid) in h.data.chunks_exact(h.subcarriers.max(1)).zip(&h.valid) {
            self.push_row(row, valid);
        }
        self.finish();
    }

    /// Starts sums over `symbols` rows of `subcarriers` values, to be given
    /// in order with [`SymbolSums::push_row`] (e.g. by the demodulator as it
    /// writes each row, while the row is in cache) and closed with
    /// [`SymbolSums::finish`].
    pub fn begin(&mut self, symbols: usize, subcarriers: usize) {
        self.symbols = symbols;
        self.subcarriers = subcarriers;
        let zero = Complex64::new(0.0, 0.0);
        self.reference.clear();
        let blocks = symbols / Self::STRIDE + 1;
        self.sum.clear();
        self.sum.reserve(blocks * subcarriers);
        self.sum_sq.clear();
        self.sum_sq.reserve(blocks * subcarriers);
        self.count.clear();
        self.count.reserve(symbols + 1);
        self.count.push(0);
        self.acc.clear();
        self.acc.resize(subcarriers, zero);
        self.acc_sq.clear();
        self.acc_sq.resize(subcarriers, 0.0);
    }

    /// Adds the next row (symbol `count.len() − 1`).
    #[inline]
    pub fn push_row(&mut self, row: &[Complex32], valid: bool) {
        let n = self.count.len() - 1;
        if n % Self::STRIDE == 0 {
            self.sum.extend_from_slice(&self.acc);
            self.sum_sq.extend_from_slice(&self.acc_sq);
        }
        let mut count = self.count[n];
        if valid {
            if self.reference.is_empty() {
                // The first valid row is the reference: it adds x = 0.
                self.reference.extend(row.iter().map(|&v| widen(v)));
            }
            for ((a, q), (&v, r)) in self.acc.iter_mut().zip(self.acc_sq.iter_mut()).zip(row.iter().zip(&self.reference)) {
                let x = widen(v) - r;
                *a += x;
                *q += x.norm_sqr();
            }
            count += 1;
        }
        self.count.push(count);
    }

    /// Closes the sums after the last row.
    pub fn finish(&mut self) {
        if self.symbols % Self::STRIDE == 0 {
            self.sum.extend_from_slice(&self.acc);
            self.sum_sq.extend_from_slice(&self.acc_sq);
        }
        if self.reference.is_empty() {
            self.reference.resize(self.subcarriers, Complex64::new(0.0, 0.0));
        }
    }

    /// Keeps the first `symbols` symbols (no-op when already shorter).
    pub fn truncate(&mut self, symbols: usize) {
        if symbols < self.symbols {
            self.symbols = symbols;
            let blocks = symbols / Self::STRIDE + 1;
            self.sum.truncate(blocks * self.subcarriers);
            self.sum_sq.truncate(blocks * self.subcarriers);
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

    /// Adds `Σ_{n ∈ from..to, valid} x_n(f)` to `sum` and, when given,
    /// `Σ |x_n(f)|²` to `sum_sq`; returns the number of valid symbols.
    /// `h` is the matrix the sums were built from.
    pub fn add_interval(&self, h: &ChannelMatrix, from: usize, to: usize, sum: &mut [Complex64], mut sum_sq: Option<&mut [f64]>) -> usize {
        let (a, b) = (from.min(self.symbols), to.min(self.symbols));
        if b <= a {
            return 0;
        }
        let stride = Self::STRIDE;
        let (first_block, last_block) = (a.div_ceil(stride), b / stride);
        if last_block <= first_block {
            self.add_rows(h, a, b, sum, sum_sq);
        } else {
            self.add_rows(h, a, first_block * stride, sum, sum_sq.as_deref_mut());
            let f = self.subcarriers;
            let (lo, hi) = (first_block * f, last_block * f);
            sum.iter_mut().zip(self.sum[lo..lo + f].iter().zip(&self.sum[hi..hi + f])).for_each(|(s, (l, h))| *s += h - l);
            if let Some(sq) = sum_sq.as_deref_mut() {
                let pairs = self.sum_sq[lo..lo + f].iter().zip(&self.sum_sq[hi..hi + f]);
                sq.iter_mut().zip(pairs).for_each(|(s, (l, h))| *s += h - l);
            }
            self.add_rows(h, last_block * stride, b, sum, sum_sq);
        }
        (self.count[b] - self.count[a]) as usize
    }

    fn add_rows(&self, h: &ChannelMatrix, a: usize, b: usize, sum: &mut [Complex64], mut sum_sq: Option<&mut [f64]>) {
        for n in (a..b).filter(|&n| h.valid[n]) {
            for (i, (&v, r)) in h.row(n).iter().zip(&self.reference).enumerate() {
                let x = widen(v) - r;
                sum[i] += x;
                if let Some(sq) = sum_sq.as_deref_mut() {
                    sq[i] += x.norm_sqr();
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_match_direct_sums_and_skip_invalid_symbols() {
        let mut h = ChannelMatrix::new(9, 3);
        for n in 0..9 {
            for f in 0..3 {
                h.row_mut(n)[f] = Complex32::new(1e3 + n as f32 * 0.1 + f as f32, (n * f) as f32 * 0.01);
            }
        }
        h.valid[0] = false;
        h.valid[5] = false;
        h.row_mut(0).iter_mut().for_each(|v| *v = Complex32::new(f32::NAN, f32::NAN));
        let mut sums = SymbolSums::default();
        sums.reset(&h);
        assert_eq!(sums.reference, h.row(1).iter().map(|&v| widen(v)).collect::<Vec<_>>());
        let mut s = vec![Complex64::new(0.0, 0.0); 3];
        let mut q = vec![0.0; 3];
        let m = sums.add_interval(&h, 0, 7, &mut s, Some(&mut q));
        assert_eq!(m, 5);
        for f in 0..3 {
            let direct: Complex64 = [1, 2, 3, 4, 6].iter().map(|&n| h.at(n, f) - sums.reference[f]).sum();
            let direct_sq: f64 = [1, 2, 3, 4, 6].iter().map(|&n| (h.at(n, f) - sums.reference[f]).norm_sqr()).sum();
            assert!((s[f] - direct).norm() < 1e-9 && (q[f] - direct_sq).abs() < 1e-9);
        }
        assert_eq!(sums.count_in(4, 100), 4);
        // Every interval, against direct sums (runs within, across and over blocks).
        let long = {
            let mut m = ChannelMatrix::new(45, 2);
            for n in 0..45 {
                m.row_mut(n)[0] = Complex32::new(n as f32, 1.0);
                m.row_mut(n)[1] = Complex32::new(-2.0 * n as f32, 0.5 * n as f32);
            }
            m.valid[17] = false;
            m
        };
        let mut sums_long = SymbolSums::default();
        sums_long.reset(&long);
        for a in 0..46 {
            for b in a..46 {
                let mut s = vec![Complex64::new(0.0, 0.0); 2];
                let mut q = vec![0.0; 2];
                let m = sums_long.add_interval(&long, a, b, &mut s, Some(&mut q));
                let rows: Vec<usize> = (a..b.min(45)).filter(|&n| long.valid[n]).collect();
                assert_eq!(m, rows.len());
                for f in 0..2 {
                    let d: Complex64 = rows.iter().map(|&n| long.at(n, f) - sums_long.reference[f]).sum();
                    let dq: f64 = rows.iter().map(|&n| (long.at(n, f) - sums_long.reference[f]).norm_sqr()).sum();
                    assert!((s[f] - d).norm() < 1e-9 && (q[f] - dq).abs() < 1e-9, "{a}..{b}");
                }
            }
        }
        sums.truncate(4);
        assert_eq!((sums.symbols, sums.count_in(0, 9)), (4, 3));
    }
}
