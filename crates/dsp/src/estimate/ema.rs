use num_complex::Complex64;

use crate::error::{Error, Result};

/// Exponential moving average of a tag's channel across replies (thesis
/// ch. 4.3, last bullet: "an EMA on the channel estimates ... more robust
/// channel estimates and higher accuracy without sacrificing frame rate").
///
/// `state ← (1 − α) state + α h`. For white noise the variance falls to
/// `α / (2 − α)` of one reply's (α = 0.3: −7.5 dB); the price is a lag of
/// about `(1 − α)/α` replies, i.e. a position bias of speed × lag (at 300
/// replies/s and α = 0.3: 50 cm/s × 7.8 ms ≈ 4 mm), so α = 1 (off) suits a
/// tracker that fuses over time itself.
///
/// Polarity: before averaging, `h` is negated if `Re Σ h · conj(state) < 0`
/// (a reply decoded with the opposite waveform polarity). Between replies
/// of a tracked tag (a few ms) the channel turns by far less than 90°, so a
/// genuine channel never trips this. Non-finite entries of `h` leave the
/// state of their (rx, subcarrier) unchanged.
#[derive(Debug, Clone, PartialEq)]
pub struct Ema {
    alpha: f64,
    state: Vec<Complex64>,
    updates: usize,
    flips: usize,
}

impl Ema {
    /// An empty average with smoothing factor `alpha ∈ (0, 1]` (1: no
    /// smoothing).
    pub fn new(alpha: f64) -> Result<Self> {
        if !(alpha > 0.0 && alpha <= 1.0) {
            return Err(Error::BadConfig(format!("EMA alpha must be in (0, 1], got {alpha}")));
        }
        Ok(Self { alpha, state: Vec::new(), updates: 0, flips: 0 })
    }

    /// Adds one reply's channel (any fixed length, e.g. rx × subcarriers)
    /// and returns the smoothed state. The first update sets the length.
    pub fn update(&mut self, h: &[Complex64]) -> Result<&[Complex64]> {
        if self.updates == 0 {
            self.state = h.to_vec();
            self.updates = 1;
            return Ok(&self.state);
        }
        if h.len() != self.state.len() {
            return Err(Error::Shape(format!("EMA holds {} values, update has {}", self.state.len(), h.len())));
        }
        let overlap: f64 = h
            .iter()
            .zip(&self.state)
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .map(|(a, b)| (a * b.conj()).re)
            .sum();
        let sign = if overlap < 0.0 {
            self.flips += 1;
            -1.0
        } else {
            1.0
        };
        for (s, v) in self.state.iter_mut().zip(h) {
            if !v.is_finite() {
                continue;
            }
            *s = if s.is_finite() { *s * (1.0 - self.alpha) + v * (sign * self.alpha) } else { v * sign };
        }
        self.updates += 1;
        Ok(&self.state)
    }

    /// The smoothed channel (empty before the first update).
    pub fn state(&self) -> &[Complex64] {
        &self.state
    }

    /// Replies averaged so far.
    pub fn updates(&self) -> usize {
        self.updates
    }

    /// Updates that were negated to match the running polarity.
    pub fn flips(&self) -> usize {
        self.flips
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_aligns_polarity_and_keeps_gaps() {
        let mut ema = Ema::new(0.5).unwrap();
        let a = [Complex64::new(2.0, 0.0), Complex64::new(0.0, 2.0)];
        assert_eq!(ema.update(&a).unwrap(), &a);
        let b = [Complex64::new(4.0, 0.0), Complex64::new(f64::NAN, 0.0)];
        let s = ema.update(&b).unwrap().to_vec();
        assert_eq!(s, vec![Complex64::new(3.0, 0.0), Complex64::new(0.0, 2.0)]);
        // A negated reply is flipped back before averaging.
        let c = [Complex64::new(-3.0, 0.0), Complex64::new(0.0, -2.0)];
        assert_eq!(ema.update(&c).unwrap(), &[Complex64::new(3.0, 0.0), Complex64::new(0.0, 2.0)]);
        assert_eq!((ema.updates(), ema.flips()), (3, 1));
        assert!(ema.update(&a[..1]).is_err());
        assert!(Ema::new(0.0).is_err() && Ema::new(1.5).is_err());
    }

    #[test]
    fn noise_variance_falls_as_predicted() {
        // Deterministic ±1 noise sequence on a constant channel.
        let alpha = 0.2;
        let mut ema = Ema::new(alpha).unwrap();
        let mut state = 12345u64;
        let mut squares = 0.0;
        let count = 20000;
        for i in 0..count + 100 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let noise = if (state >> 33) & 1 == 1 { 1.0 } else { -1.0 };
            let out = ema.update(&[Complex64::new(10.0 + noise, 0.0)]).unwrap()[0];
            if i >= 100 {
                squares += (out.re - 10.0).powi(2);
            }
        }
        let variance = squares / count as f64;
        assert!((variance / (alpha / (2.0 - alpha)) - 1.0).abs() < 0.1, "{variance}");
    }
}
