//! Reply detection (thesis ch. 4.3 (a), "Robust Packet Detection").
//!
//! Contract:
//! - A *detection feature* is one real number per OFDM symbol that follows
//!   the tag state. [`combined_magnitude`] is the paper's
//!   `H_combined(n) = Σ_f |H(f, n)|` (incoherent averaging over subcarriers,
//!   which all see the same backscatter modulation). [`combined_projection`]
//!   combines the subcarriers coherently instead (see its doc for why this
//!   is the default: with a strong tx → rx leakage the magnitude changes of
//!   different subcarriers can cancel in the paper's sum).
//! - [`FeatureSums`] holds running sums so that the correlation over any
//!   (fractional) span costs O(chips), not O(symbols).
//! - [`normalised_correlation`] is the paper's `D(Δ) = Σ_n p*(n) H_combined(n + Δ)`
//!   made a Pearson correlation coefficient in [−1, 1], so one threshold
//!   works whatever the tag's distance or the receiver gain.
//! - [`detect_preamble`] searches start `Δ` and the tag's true BLF (Gen2
//!   tags may miss the commanded BLF by several per cent) jointly over all
//!   rx antennas and applies the threshold → [`Detection`] or
//!   [`crate::Error::NoPreamble`].
//!
//! Feature values that are NaN (symbols with non-finite samples) count as
//! "no information": they are set to the feature's mean.

mod combine;
mod correlate;
mod search;

pub use combine::{combined_magnitude, combined_projection, combined_projection_from_sums, moving_average};
pub use correlate::{normalised_correlation, FeatureSums, Template};
pub use search::{detect_on_grid, detect_preamble, refine_detection, CoarseGrid, Detection, DetectionOptions};

use crate::error::{Error, Result};

/// Which per-symbol detection feature to correlate with the preamble.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feature {
    /// The paper's `Σ_f |H(f, n)|` (ch. 4.3 (a)).
    CombinedMagnitude,
    /// Coherent projection on the dominant direction of change
    /// ([`combined_projection`]); the default.
    Projection,
}

impl Feature {
    /// Parses `"magnitude"` or `"projection"`.
    pub fn parse(name: &str) -> Result<Self> {
        match name.trim().to_ascii_lowercase().as_str() {
            "magnitude" | "combined-magnitude" => Ok(Feature::CombinedMagnitude),
            "projection" => Ok(Feature::Projection),
            other => Err(Error::BadConfig(format!("unknown detection feature '{other}' (magnitude, projection)"))),
        }
    }

    /// The canonical name.
    pub fn name(&self) -> &'static str {
        match self {
            Feature::CombinedMagnitude => "magnitude",
            Feature::Projection => "projection",
        }
    }
}
