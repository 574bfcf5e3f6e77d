//! Errors as values: every fallible public function returns [`Error`].
//! Nothing in this crate panics on input data.

use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// A configuration that violates a design rule or is out of domain
    /// (e.g. `N ≥ B / (2 BLF)`, ch. 4.2).
    #[error("invalid configuration: {0}")]
    BadConfig(String),
    /// Arrays whose sizes do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// Not enough samples or symbols for the step to work.
    #[error("too short: {what} needs at least {needed}, got {got}")]
    TooShort { what: &'static str, needed: usize, got: usize },
    /// Input with NaN or infinite values where finite ones are required.
    #[error("non-finite input: {0}")]
    NonFinite(String),
    /// No tag reply: the best normalised preamble correlation stayed below
    /// the threshold.
    #[error("no preamble detected: best normalised correlation {score:.3} < threshold {threshold:.3}")]
    NoPreamble { score: f64, threshold: f64 },
    /// After edge-flip elimination a tag state has no clean symbol left.
    #[error("no clean symbols: {high} in the reflective and {low} in the non-reflective state")]
    NoCleanSymbols { high: usize, low: usize },
    /// A calibration that cannot be formed or applied (zero or non-finite
    /// measured channel, mismatched antennas or subcarriers).
    #[error("invalid calibration: {0}")]
    BadCalibration(String),
}

impl Error {
    /// A short stable name of the error kind, for counted skips in reports
    /// (`"no-preamble"`, `"non-finite"`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            Error::BadConfig(_) => "bad-config",
            Error::Shape(_) => "shape",
            Error::TooShort { .. } => "too-short",
            Error::NonFinite(_) => "non-finite",
            Error::NoPreamble { .. } => "no-preamble",
            Error::NoCleanSymbols { .. } => "no-clean-symbols",
            Error::BadCalibration(_) => "bad-calibration",
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;
