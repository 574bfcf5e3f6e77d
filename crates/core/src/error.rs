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
    /// A parameter name that the method's table does not have; `close`
    /// holds the likely intended names, `known` all of them.
    #[error("unknown parameter '{name}' for method '{method}' ({})", unknown_hint(close, known))]
    UnknownParameter { name: String, method: String, close: Vec<String>, known: Vec<String> },
    /// A registered method whose estimator is not in the core (Marvel's
    /// factor graph is in Python, `scattertrack.fusion`).
    #[error("method '{0}' is estimated in Python (scattertrack.fusion), not by the Rust core")]
    NotInCore(String),
    /// A measurement that names an antenna the scene does not define.
    #[error("measurement names antenna index {0}, scene has {1} antennas")]
    Antenna(usize, usize),
}

/// "did you mean a, b?" when there are close matches, else the known names.
fn unknown_hint(close: &[String], known: &[String]) -> String {
    if close.is_empty() {
        format!("known: {}", known.join(", "))
    } else {
        format!("did you mean {}?", close.join(", "))
    }
}

pub type Result<T> = std::result::Result<T, Error>;
