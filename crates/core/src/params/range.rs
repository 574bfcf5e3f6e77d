//! The allowed range of a numeric parameter, written once and shown in
//! messages and the docs in the same notation that [`Range::from_str`]
//! reads (so a table written outside Rust, Marvel's in Python, can give
//! its ranges as text).

use std::fmt;
use std::str::FromStr;

/// One end of a [`Range`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// Any finite value on this side. Infinity is only accepted where a
    /// bound says so (`Inclusive(f64::INFINITY)`): most parameters would
    /// silently break on it.
    Unbounded,
    /// The value itself is allowed.
    Inclusive(f64),
    /// Values up to, not including, this one.
    Exclusive(f64),
}

/// The values a numeric parameter accepts (in its unit). NaN never is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub low: Bound,
    pub high: Bound,
}

impl Range {
    /// Every finite value.
    pub const ANY: Range = Range { low: Bound::Unbounded, high: Bound::Unbounded };
    /// `> 0`, finite.
    pub const POSITIVE: Range = Range { low: Bound::Exclusive(0.0), high: Bound::Unbounded };
    /// `>= 0`, finite.
    pub const NON_NEGATIVE: Range = Range { low: Bound::Inclusive(0.0), high: Bound::Unbounded };
    /// `[0, 1]`: a probability or a fraction.
    pub const UNIT: Range = Range { low: Bound::Inclusive(0.0), high: Bound::Inclusive(1.0) };

    /// `>= low`, finite.
    pub const fn at_least(low: f64) -> Range {
        Range { low: Bound::Inclusive(low), high: Bound::Unbounded }
    }

    /// `[low, high]`.
    pub const fn closed(low: f64, high: f64) -> Range {
        Range { low: Bound::Inclusive(low), high: Bound::Inclusive(high) }
    }

    /// Whether `x` is allowed.
    pub fn contains(&self, x: f64) -> bool {
        if x.is_nan() {
            return false;
        }
        let above = match self.low {
            Bound::Unbounded => x.is_finite() || x > 0.0,
            Bound::Inclusive(a) => x >= a,
            Bound::Exclusive(a) => x > a,
        };
        let below = match self.high {
            Bound::Unbounded => x.is_finite() || x < 0.0,
            Bound::Inclusive(b) => x <= b,
            Bound::Exclusive(b) => x < b,
        };
        above && below
    }

    /// The tighter of this range and `>= low` (unsigned integer fields).
    pub fn with_floor(self, low: f64) -> Range {
        let raised = match self.low {
            Bound::Unbounded => true,
            Bound::Inclusive(a) => a < low,
            Bound::Exclusive(a) => a < low,
        };
        if raised {
            Range { low: Bound::Inclusive(low), ..self }
        } else {
            self
        }
    }

    /// Whether every finite value is allowed (nothing worth printing).
    pub fn is_any(&self) -> bool {
        *self == Range::ANY
    }
}

/// A number as the tables show it: `0.02`, `1e-6`, `200000`, `inf`.
pub fn format_number(x: f64) -> String {
    if x.is_infinite() {
        return if x > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let magnitude = x.abs();
    if magnitude != 0.0 && !(1e-4..1e7).contains(&magnitude) {
        return format!("{x:e}");
    }
    format!("{x}")
}

impl fmt::Display for Range {
    /// `any`, `> 0`, `>= 1`, `<= 5`, `[0, 1]`, `(0, 1)`, `(0, inf]`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use Bound::*;
        let n = format_number;
        match (self.low, self.high) {
            (Unbounded, Unbounded) => write!(f, "any"),
            (Inclusive(a), Unbounded) => write!(f, ">= {}", n(a)),
            (Exclusive(a), Unbounded) => write!(f, "> {}", n(a)),
            (Unbounded, Inclusive(b)) => write!(f, "<= {}", n(b)),
            (Unbounded, Exclusive(b)) => write!(f, "< {}", n(b)),
            (low, high) => {
                let (open, a) = match low {
                    Inclusive(a) => ('[', n(a)),
                    Exclusive(a) => ('(', n(a)),
                    Unbounded => ('(', "-inf".into()),
                };
                let (close, b) = match high {
                    Inclusive(b) => (']', n(b)),
                    Exclusive(b) => (')', n(b)),
                    Unbounded => (')', "inf".into()),
                };
                write!(f, "{open}{a}, {b}{close}")
            }
        }
    }
}

impl FromStr for Range {
    type Err = String;

    /// Reads what `Display` writes.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let text = text.trim();
        let number = |s: &str| -> Result<f64, String> {
            let x: f64 = s.trim().parse().map_err(|_| format!("range {text:?}: {s:?} is not a number"))?;
            if x.is_nan() {
                return Err(format!("range {text:?}: NaN is not a bound"));
            }
            Ok(x)
        };
        if text.is_empty() || text == "any" {
            return Ok(Range::ANY);
        }
        for (prefix, make) in [
            (">=", (|x| Range { low: Bound::Inclusive(x), high: Bound::Unbounded }) as fn(f64) -> Range),
            ("<=", |x| Range { low: Bound::Unbounded, high: Bound::Inclusive(x) }),
            (">", |x| Range { low: Bound::Exclusive(x), high: Bound::Unbounded }),
            ("<", |x| Range { low: Bound::Unbounded, high: Bound::Exclusive(x) }),
        ] {
            if let Some(rest) = text.strip_prefix(prefix) {
                return Ok(make(number(rest)?));
            }
        }
        let (Some(open), Some(close)) = (text.chars().next(), text.chars().last()) else {
            return Err(format!("range {text:?}: expected e.g. '> 0', '>= 1' or '[0, 1]'"));
        };
        let inner = &text[open.len_utf8()..text.len() - close.len_utf8()];
        let Some((a, b)) = inner.split_once(',') else {
            return Err(format!("range {text:?}: expected two bounds separated by a comma"));
        };
        let bound = |x: f64, inclusive: bool| {
            if x.is_infinite() && !inclusive {
                Bound::Unbounded
            } else if inclusive {
                Bound::Inclusive(x)
            } else {
                Bound::Exclusive(x)
            }
        };
        let low = match open {
            '[' => bound(number(a)?, true),
            '(' => bound(number(a)?, false),
            _ => return Err(format!("range {text:?}: must open with '[' or '('")),
        };
        let high = match close {
            ']' => bound(number(b)?, true),
            ')' => bound(number(b)?, false),
            _ => return Err(format!("range {text:?}: must close with ']' or ')'")),
        };
        Ok(Range { low, high })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_and_parse_round_trip() {
        for range in [
            Range::ANY,
            Range::POSITIVE,
            Range::NON_NEGATIVE,
            Range::UNIT,
            Range::at_least(1.0),
            Range { low: Bound::Exclusive(0.0), high: Bound::Exclusive(1.0) },
            Range { low: Bound::Exclusive(0.0), high: Bound::Inclusive(f64::INFINITY) },
            Range { low: Bound::Unbounded, high: Bound::Inclusive(5.0) },
            Range::closed(0.0, 0.5),
        ] {
            let text = range.to_string();
            assert_eq!(text.parse::<Range>().unwrap(), range, "{text}");
        }
        assert_eq!(Range::POSITIVE.to_string(), "> 0");
        assert_eq!(Range::UNIT.to_string(), "[0, 1]");
        assert!("between 1 and 2".parse::<Range>().is_err());
        assert!("[0; 1]".parse::<Range>().is_err());
    }

    #[test]
    fn infinity_only_where_a_bound_allows_it() {
        assert!(!Range::POSITIVE.contains(f64::INFINITY));
        assert!(!Range::ANY.contains(f64::NEG_INFINITY));
        assert!(!Range::ANY.contains(f64::NAN));
        let or_inf: Range = "(0, inf]".parse().unwrap();
        assert!(or_inf.contains(f64::INFINITY) && or_inf.contains(1.0) && !or_inf.contains(0.0));
        assert!(Range::UNIT.contains(0.0) && Range::UNIT.contains(1.0) && !Range::UNIT.contains(1.0 + 1e-12));
    }

    #[test]
    fn numbers_are_shown_compactly() {
        assert_eq!(format_number(0.02), "0.02");
        assert_eq!(format_number(1e-6), "1e-6");
        assert_eq!(format_number(200000.0), "200000");
        assert_eq!(format_number(f64::INFINITY), "inf");
    }
}
