//! Errors as values: every fallible public function returns [`Error`].

use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// A scene that no tracker can use (no antennas, bad dimensions...).
    #[error("invalid scene: {0}")]
    Scene(String),
    /// A parameter outside its domain.
    #[error("invalid parameter '{name}': {reason}")]
    Parameter { name: String, reason: String },
    /// A tracking method name that is not registered.
    #[error("unknown method '{0}' (known: {1})")]
    UnknownMethod(String, String),
    /// A measurement that names an antenna the scene does not define.
    #[error("measurement names antenna index {0}, scene has {1} antennas")]
    Antenna(usize, usize),
}

pub type Result<T> = std::result::Result<T, Error>;
