use num_complex::Complex64;

use super::{SymbolState, SymbolSums};
use crate::ofdm::ChannelTransform;
use crate::error::{Error, Result};
use crate::ofdm::{widen, ChannelMatrix};

/// One antenna's tag channel from one reply.
#[derive(Debug, Clone, PartialEq)]
pub struct TagChannel {
    /// `Ĥ_tag(f) = mean(H | High) − mean(H | Low)` per active subcarrier
    /// (ascending frequency), unitless (uncalibrated).
    pub h: Vec<Complex64>,
    /// Variance of `Ĥ_tag(f)` (complex, `E|Ĥ − H|²`): the pooled
    /// within-state scatter times `1/M + 1/L`.
    pub variance: Vec<f64>,
    /// `(mean(H | High) + mean(H | Low)) / 2`: the decision midpoint for
    /// reading further chips.
    pub midpoint: Vec<Complex64>,
    /// Symbols averaged in the reflective state (`M`).
    pub high: usize,
    /// Symbols averaged in the non-reflective state (`L`).
    pub low: usize,
}

/// The tag's channel per subcarrier (thesis ch. 4.3 (c)):
/// `Ĥ(f) = (1/M) Σ H(f | reflective) − (1/L) Σ H(f | non-reflective)`.
///
/// The direct tx → rx path and static clutter are the same in both states
/// and cancel; what remains is the channel of the paths that touch the tag,
/// scaled by the tag's differential reflection coefficient and the hardware
/// response (removed by [`super::Calibration`]). Only one reply's symbols
/// are averaged (one-shot estimation). `states` has one entry per symbol of
/// `h`. Errors: [`Error::Shape`], [`Error::NoCleanSymbols`] when a state has
/// no symbol.
pub fn tag_channel(h: &ChannelMatrix, states: &[SymbolState]) -> Result<TagChannel> {
    if states.len() != h.symbols {
        return Err(Error::Shape(format!("{} states for {} symbols", states.len(), h.symbols)));
    }
    let f_count = h.subcarriers;
    let zero = Complex64::new(0.0, 0.0);
    let (mut sum_high, mut sum_low) = (vec![zero; f_count], vec![zero; f_count]);
    let (mut high, mut low) = (0usize, 0usize);
    for (n, state) in states.iter().enumerate() {
        let (sum, count) = match state {
            SymbolState::High => (&mut sum_high, &mut high),
            SymbolState::Low => (&mut sum_low, &mut low),
            _ => continue,
        };
        if !h.valid[n] {
            continue;
        }
        sum.iter_mut().zip(h.row(n)).for_each(|(s, &v)| *s += widen(v));
        *count += 1;
    }
    if high == 0 || low == 0 {
        return Err(Error::NoCleanSymbols { high, low });
    }
    let mean_high: Vec<Complex64> = sum_high.iter().map(|s| s / high as f64).collect();
    let mean_low: Vec<Complex64> = sum_low.iter().map(|s| s / low as f64).collect();
    // Pooled within-state scatter per subcarrier (second pass: numerically
    // clean even when the leakage is 60 dB above the tag).
    let mut scatter = vec![0.0; f_count];
    for (n, state) in states.iter().enumerate() {
        let mean = match state {
            SymbolState::High if h.valid[n] => &mean_high,
            SymbolState::Low if h.valid[n] => &mean_low,
            _ => continue,
        };
        scatter.iter_mut().zip(h.row(n)).zip(mean).for_each(|((s, &v), m)| *s += (widen(v) - m).norm_sqr());
    }
    let dof = (high + low) as f64 - 2.0;
    let factor = 1.0 / high as f64 + 1.0 / low as f64;
    Ok(TagChannel {
        h: mean_high.iter().zip(&mean_low).map(|(a, b)| a - b).collect(),
        variance: scatter.iter().map(|s| if dof > 0.0 { s / dof * factor } else { f64::INFINITY }).collect(),
        midpoint: mean_high.iter().zip(&mean_low).map(|(a, b)| (a + b) * 0.5).collect(),
        high,
        low,
    })
}

/// [`tag_channel`] from an antenna's time-domain [`SymbolSums`]: the
/// samples are summed per state (each maximal run of one state is a prefix
/// difference) and only the two state means are demodulated, by linearity
/// of the demodulation (`transform`). `O(symbols + runs × N)`.
///
/// The variance is the noise of the white-noise model, pooled over the
/// band: by Parseval the within-state scatter of the samples,
/// `Σ‖x − x̄‖²`, is the scatter of `H` summed over all `N` bins (the
/// unitary FFT, `|X| = 1`), so each subcarrier gets `scatter / N` (the
/// direct [`tag_channel`] estimates it per subcarrier instead). Errors as
/// [`tag_channel`].
pub fn tag_channel_from_sums(
    sums: &SymbolSums,
    states: &[SymbolState],
    transform: &mut ChannelTransform,
) -> Result<TagChannel> {
    if states.len() != sums.symbols {
        return Err(Error::Shape(format!("{} states for {} symbols", states.len(), sums.symbols)));
    }
    let n = sums.n;
    let zero = Complex64::new(0.0, 0.0);
    let (mut sum_high, mut sum_low) = (vec![zero; n], vec![zero; n]);
    let (mut energy_high, mut energy_low) = (0.0, 0.0);
    let (mut high, mut low) = (0usize, 0usize);
    let mut s = 0;
    while s < states.len() {
        let state = states[s];
        let mut end = s + 1;
        while end < states.len() && states[end] == state {
            end += 1;
        }
        match state {
            SymbolState::High => high += sums.add_interval(s, end, &mut sum_high, Some(&mut energy_high)),
            SymbolState::Low => low += sums.add_interval(s, end, &mut sum_low, Some(&mut energy_low)),
            _ => {}
        }
        s = end;
    }
    if high == 0 || low == 0 {
        return Err(Error::NoCleanSymbols { high, low });
    }
    let (nh, nl) = (high as f64, low as f64);
    let norm = |v: &[Complex64]| v.iter().map(|x| x.norm_sqr()).sum::<f64>();
    let scatter = ((energy_high - norm(&sum_high) / nh) + (energy_low - norm(&sum_low) / nl)).max(0.0);
    let difference: Vec<Complex64> = sum_high.iter().zip(&sum_low).map(|(a, b)| a / nh - b / nl).collect();
    let middle: Vec<Complex64> =
        sum_high.iter().zip(&sum_low).zip(&sums.reference).map(|((a, b), r)| r + (a / nh + b / nl) * 0.5).collect();
    let f_count = transform.subcarriers();
    let mut h = vec![zero; f_count];
    let mut midpoint = vec![zero; f_count];
    transform.apply(&difference, &mut h);
    transform.apply(&middle, &mut midpoint);
    let dof = nh + nl - 2.0;
    let factor = 1.0 / nh + 1.0 / nl;
    let per_bin = if dof > 0.0 { scatter / n as f64 / dof * factor } else { f64::INFINITY };
    Ok(TagChannel { h, variance: vec![per_bin; f_count], midpoint, high, low })
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex32;

    #[test]
    fn recovers_a_known_channel_exactly_without_noise() {
        let s: Vec<Complex64> = (0..5).map(|f| Complex64::from_polar(1e3, f as f64)).collect();
        let t: Vec<Complex64> = (0..5).map(|f| Complex64::from_polar(1e-2, -0.7 * f as f64)).collect();
        let states: Vec<SymbolState> = (0..50)
            .map(|n| match n % 10 {
                0 => SymbolState::Edge,
                1..=4 => SymbolState::High,
                _ => SymbolState::Low,
            })
            .collect();
        let mut h = ChannelMatrix::new(50, 5);
        for (n, state) in states.iter().enumerate() {
            let on = *state == SymbolState::High;
            for (f, value) in h.row_mut(n).iter_mut().enumerate() {
                // Edge symbols hold garbage: they must not be used.
                let v = if *state == SymbolState::Edge {
                    Complex64::new(9e9, 0.0)
                } else {
                    s[f] + if on { t[f] } else { zero() }
                };
                *value = Complex32::new(v.re as f32, v.im as f32);
            }
        }
        let estimate = tag_channel(&h, &states).unwrap();
        assert_eq!((estimate.high, estimate.low), (20, 25));
        // Exact up to the matrix's single-precision rounding of S + T
        // (|S| = 1e3: an ulp is 6e-5).
        for ((h, t), v) in estimate.h.iter().zip(&t).zip(&estimate.variance) {
            assert!((h - t).norm() < 2e-4, "{h} vs {t}");
            assert!(*v < 1e-8);
        }
    }

    fn zero() -> Complex64 {
        Complex64::new(0.0, 0.0)
    }

    #[test]
    fn sums_give_the_direct_estimate_with_60_db_of_leakage() {
        use crate::estimate::SymbolSums;
        use crate::ofdm::{ChannelTransform, Demodulator, KnownSymbol, OfdmConfig};
        // Leakage 1e3 per sample, a tag of 1, noise 0.3 (pseudo-random), one
        // invalid symbol, runs of both states broken by edges.
        let config = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(20, 2).unwrap();
        let mut state = 7u64;
        let mut noise = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6
        };
        let symbols = 400;
        let states: Vec<SymbolState> = (0..symbols)
            .map(|n| match (n / 13) % 4 {
                _ if n == 77 => SymbolState::Invalid,
                _ if n % 13 == 0 => SymbolState::Edge,
                0 | 1 => SymbolState::High,
                2 => SymbolState::Low,
                _ => SymbolState::Outside,
            })
            .collect();
        let window: Vec<Complex32> = (0..symbols * 20)
            .map(|i| {
                let (n, t) = (i / 20, i % 20);
                let on = if states[n] == SymbolState::High { 1.0 } else { 0.0 };
                let v = Complex64::from_polar(1e3, 0.7 * t as f64) + Complex64::from_polar(on, -0.4 * t as f64)
                    + Complex64::new(noise(), noise());
                if n == 77 { Complex32::new(f32::NAN, 0.0) } else { Complex32::new(v.re as f32, v.im as f32) }
            })
            .collect();
        let mut h = ChannelMatrix::default();
        Demodulator::new(&config, &symbol).unwrap().demodulate(&window, 0, &mut h).unwrap();
        let direct = tag_channel(&h, &states).unwrap();
        let mut sums = SymbolSums::default();
        sums.reset(&window, 0, 20).unwrap();
        let mut transform = ChannelTransform::new(&config, &symbol).unwrap();
        let fast = tag_channel_from_sums(&sums, &states, &mut transform).unwrap();
        assert_eq!((fast.high, fast.low), (direct.high, direct.low));
        let pooled = direct.variance.iter().sum::<f64>() / direct.variance.len() as f64;
        for f in 0..19 {
            assert!((fast.h[f] - direct.h[f]).norm() < 1e-3, "{f}: {} vs {}", fast.h[f], direct.h[f]);
            assert!((fast.midpoint[f] - direct.midpoint[f]).norm() < 1e-2 * (1.0 + direct.midpoint[f].norm() * 1e-3), "{f}");
            // White noise: the pooled variance is every subcarrier's, within its scatter.
            assert!((fast.variance[f] / pooled - 1.0).abs() < 0.15, "{f}: {} vs {pooled}", fast.variance[f]);
        }
        assert!(matches!(tag_channel_from_sums(&sums, &states[1..], &mut transform), Err(Error::Shape(_))));
    }

    #[test]
    fn a_missing_state_is_an_error() {
        let h = ChannelMatrix::new(3, 2);
        let e = tag_channel(&h, &[SymbolState::High, SymbolState::Edge, SymbolState::High]).unwrap_err();
        assert_eq!(e, Error::NoCleanSymbols { high: 2, low: 0 });
        assert!(matches!(tag_channel(&h, &[SymbolState::High]), Err(Error::Shape(_))));
    }
}
