//! Floats as `track.csv` writes them: 6 decimals, exactly as Python's
//! `"%.6f"` (the decimal expansion of the binary value, correctly rounded,
//! ties to even), `nan` for NaN.
//!
//! The general formatter (`{:.6}`, exact big-number arithmetic) was about
//! a tenth of `scattertrack track`'s CPU on 10,000 tags. Most values are
//! metres and seconds well below 10⁹, for which x·10⁶ is an integer-range
//! f64 whose rounding is unambiguous unless it lies within its own
//! rounding error of a tie: then the integer is printed directly; the rest
//! (near-ties, huge values, infinities) go to the general formatter.

use std::fmt::Write;

/// Appends `x` with 6 decimals (see the module).
#[inline]
pub fn push(out: &mut String, x: f64) {
    if x.is_nan() {
        out.push_str("nan");
        return;
    }
    let a = x.abs();
    if a < 1e9 {
        // y = fl(a·10⁶) < 10¹⁵ < 2⁵³, within y·2⁻⁵³ of the exact product;
        // its fraction is exact (y − ⌊y⌋ needs no rounding at this size).
        let y = a * 1e6;
        let fraction = y - y.floor();
        if (fraction - 0.5).abs() > y * 2.3e-16 {
            let n = y.round() as u64;
            if x.is_sign_negative() {
                out.push('-'); // "%.6f" keeps the sign of -0.0 and of -1e-9
            }
            push_digits(out, n / 1_000_000, 1);
            out.push('.');
            push_digits(out, n % 1_000_000, 6);
            return;
        }
    }
    let _ = write!(out, "{x:.6}");
}

/// Appends `n` in decimal with at least `width` digits (zeros in front).
fn push_digits(out: &mut String, mut n: u64, width: usize) {
    let mut digits = [b'0'; 20];
    let mut k = digits.len();
    while n > 0 || digits.len() - k < width {
        k -= 1;
        digits[k] = b'0' + (n % 10) as u8;
        n /= 10;
    }
    out.push_str(std::str::from_utf8(&digits[k..]).expect("ASCII digits"));
}
