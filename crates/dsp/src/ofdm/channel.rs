use num_complex::Complex64;

/// Per-symbol channel estimates `H(f, n)` of one rx antenna in one window.
///
/// Row-major: `data[n · subcarriers + f]` is symbol `n`, active subcarrier
/// `f` (ascending frequency). `valid[n]` is false for a symbol that had a
/// non-finite sample; its row holds NaN and every later step skips it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChannelMatrix {
    /// Number of OFDM symbols (rows).
    pub symbols: usize,
    /// Number of active subcarriers (columns), `N − 1`.
    pub subcarriers: usize,
    /// `H(f, n)`, unitless (received / transmitted), row-major.
    pub data: Vec<Complex64>,
    /// Whether symbol `n` was demodulated from finite samples.
    pub valid: Vec<bool>,
}

impl ChannelMatrix {
    /// A matrix of `symbols × subcarriers` zeros, all symbols valid.
    pub fn new(symbols: usize, subcarriers: usize) -> Self {
        Self {
            symbols,
            subcarriers,
            data: vec![Complex64::new(0.0, 0.0); symbols * subcarriers],
            valid: vec![true; symbols],
        }
    }

    /// Reshape in place, reusing the allocation (contents unspecified).
    pub fn resize(&mut self, symbols: usize, subcarriers: usize) {
        self.symbols = symbols;
        self.subcarriers = subcarriers;
        self.data.resize(symbols * subcarriers, Complex64::new(0.0, 0.0));
        self.valid.resize(symbols, true);
    }

    /// The row of symbol `n` (all subcarriers).
    #[inline]
    pub fn row(&self, n: usize) -> &[Complex64] {
        &self.data[n * self.subcarriers..(n + 1) * self.subcarriers]
    }

    /// The mutable row of symbol `n`.
    #[inline]
    pub fn row_mut(&mut self, n: usize) -> &mut [Complex64] {
        &mut self.data[n * self.subcarriers..(n + 1) * self.subcarriers]
    }

    /// Number of valid symbols.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }
}
