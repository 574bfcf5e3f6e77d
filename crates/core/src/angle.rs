//! Angle wrapping: the one shared function for every phase in the crate.

use std::f64::consts::{PI, TAU};

/// Wraps `angle` (radians) into `[0, period)`.
///
/// Idempotent: `wrap(wrap(a, p), p) == wrap(a, p)`. `rem_euclid` can return
/// `period` itself for tiny negative inputs (rounding), so that case is
/// folded back to 0 to keep the half-open interval.
#[inline]
pub fn wrap(angle: f64, period: f64) -> f64 {
    let w = angle.rem_euclid(period);
    if w >= period {
        0.0
    } else {
        w
    }
}

/// Wraps `angle` (radians) into `[-period/2, period/2)`: the signed
/// difference between two phases.
#[inline]
pub fn wrap_signed(angle: f64, period: f64) -> f64 {
    wrap(angle + 0.5 * period, period) - 0.5 * period
}

/// Wraps an angle to `(-pi, pi]`, rad (docs/marvel.md section 1: one shared
/// function for every angle of the pipeline, the LoRa DSP's too, which
/// re-exports it). Idempotent; non-finite input stays non-finite.
#[inline]
pub fn wrap_angle(angle: f64) -> f64 {
    let w = angle - TAU * (angle / TAU).round();
    // round() leaves w in [-pi, pi]; map -pi (and rounding spill) into range.
    if w <= -PI {
        w + TAU
    } else if w > PI {
        w - TAU
    } else {
        w
    }
}

/// 2π, the phase period of most readers (radians).
pub const TWO_PI: f64 = 2.0 * PI;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_is_in_range_and_idempotent() {
        for i in -2000..2000 {
            let x = i as f64 * 0.0137 - 0.5;
            let w = wrap_angle(x);
            assert!(w > -PI && w <= PI, "{x} -> {w}");
            assert_eq!(wrap_angle(w), w);
            assert!(((x - w) / TAU - ((x - w) / TAU).round()).abs() < 1e-9);
        }
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert_eq!(wrap_angle(3.0 * PI), PI);
        assert!(wrap_angle(f64::NAN).is_nan());
    }

    #[test]
    fn wrap_is_in_range_and_idempotent() {
        for i in -1000..1000 {
            let a = i as f64 * 0.0137 - 3e-17;
            for p in [TWO_PI, PI] {
                let w = wrap(a, p);
                assert!((0.0..p).contains(&w), "{a} -> {w}");
                assert_eq!(wrap(w, p), w);
                let s = wrap_signed(a, p);
                assert!((-0.5 * p..0.5 * p).contains(&s));
                assert!((wrap(s, p) - w).abs() < 1e-12 || (wrap(s, p) - w).abs() > p - 1e-12);
            }
        }
        assert_eq!(wrap(-1e-18, TWO_PI), 0.0);
    }
}
