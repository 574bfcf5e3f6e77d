use num_complex::{Complex32, Complex64};

/// A single-precision value widened to double.
#[inline]
pub fn widen(v: Complex32) -> Complex64 {
    Complex64::new(v.re as f64, v.im as f64)
}

/// Complex samples as interleaved floats `[re₀, im₀, re₁, im₁, …]`, for
/// loops that vectorise over real lanes.
#[inline]
pub fn as_floats(samples: &[Complex32]) -> &[f32] {
    // SAFETY: `Complex<f32>` is `#[repr(C)]` { re, im } (num-complex
    // documents this layout), so n complex values are 2n contiguous f32
    // with at least f32's alignment; the borrow keeps the lifetime.
    unsafe { std::slice::from_raw_parts(samples.as_ptr().cast::<f32>(), 2 * samples.len()) }
}

/// Double-precision complex values as interleaved floats (see [`as_floats`]).
#[inline]
pub fn as_doubles(values: &[Complex64]) -> &[f64] {
    // SAFETY: as in `as_floats`: `Complex<f64>` is `#[repr(C)]` { re, im }.
    unsafe { std::slice::from_raw_parts(values.as_ptr().cast::<f64>(), 2 * values.len()) }
}

/// [`as_doubles`], mutable.
#[inline]
pub fn as_doubles_mut(values: &mut [Complex64]) -> &mut [f64] {
    // SAFETY: as in `as_floats`; the exclusive borrow is handed on.
    unsafe { std::slice::from_raw_parts_mut(values.as_mut_ptr().cast::<f64>(), 2 * values.len()) }
}

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
    /// `H(f, n)`, unitless (received / transmitted), row-major. Single
    /// precision like the samples and the FFT: per-symbol values are far
    /// noisier than its rounding, and every sum over symbols is taken in
    /// `f64` (half the memory traffic of a double matrix, twice the SIMD
    /// width).
    pub data: Vec<Complex32>,
    /// Whether symbol `n` was demodulated from finite samples.
    pub valid: Vec<bool>,
}

impl ChannelMatrix {
    /// A matrix of `symbols × subcarriers` zeros, all symbols valid.
    pub fn new(symbols: usize, subcarriers: usize) -> Self {
        Self {
            symbols,
            subcarriers,
            data: vec![Complex32::new(0.0, 0.0); symbols * subcarriers],
            valid: vec![true; symbols],
        }
    }

    /// Reshape in place, reusing the allocation (contents unspecified).
    pub fn resize(&mut self, symbols: usize, subcarriers: usize) {
        self.symbols = symbols;
        self.subcarriers = subcarriers;
        self.data.resize(symbols * subcarriers, Complex32::new(0.0, 0.0));
        self.valid.resize(symbols, true);
    }

    /// The row of symbol `n` (all subcarriers).
    #[inline]
    pub fn row(&self, n: usize) -> &[Complex32] {
        &self.data[n * self.subcarriers..(n + 1) * self.subcarriers]
    }

    /// The mutable row of symbol `n`.
    #[inline]
    pub fn row_mut(&mut self, n: usize) -> &mut [Complex32] {
        &mut self.data[n * self.subcarriers..(n + 1) * self.subcarriers]
    }

    /// Entry `(n, f)` widened to `f64`.
    #[inline]
    pub fn at(&self, n: usize, f: usize) -> Complex64 {
        widen(self.data[n * self.subcarriers + f])
    }

    /// Number of valid symbols.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }
}
