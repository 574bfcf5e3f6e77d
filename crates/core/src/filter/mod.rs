//! Filters as pure step functions on (x, P): no tracker state here.
//!
//! Contract: `predict` applies a motion model's transition; `update_*`
//! fold one measurement in and return the innovation statistics that a
//! tracker needs for likelihoods and gating. Covariances stay symmetric
//! positive semi-definite (property-tested). [`PackedCovariance`] stores
//! one compactly between steps.

mod ekf;
pub mod imm;
mod packed;
pub mod particle;

pub use packed::{pack_pair, unpack_pair, PackedCovariance};
pub use ekf::{apply_scalar, innovation, log_gaussian, predict, update_position, update_scalar, ScalarUpdate};
