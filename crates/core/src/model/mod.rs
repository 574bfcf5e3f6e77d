//! Motion and measurement models: pure functions.
//!
//! Contract: a motion model returns the transition `F` and process noise
//! `Q` for a time step; a measurement model returns the predicted value
//! and, on request, its Jacobian `H` with respect to the state. Every
//! Jacobian has a finite-difference test. [`wideband`] turns a helper's
//! wideband channel into distance candidates (TurboTrack eq. 5.1).
//!
//! The state is always `x = [px, py, pz, vx, vy, vz]ᵀ` (m, m/s): a 2D
//! tracker keeps z and vz fixed by giving them zero covariance and zero
//! process noise, and the no-velocity variant keeps v = 0 the same way, so
//! every tracker shares one fixed-size 6×6 filter.

mod motion;
mod multipath;
mod range;
pub mod wideband;

pub use motion::{MotionModel, Transition};
pub use multipath::{apparent_range, apparent_range_at, reflected_paths, ReflectedPath};
pub use range::range;

/// State dimension: position and velocity in 3D.
pub const STATE: usize = 6;

pub type StateVector = nalgebra::SVector<f64, STATE>;
pub type StateMatrix = nalgebra::SMatrix<f64, STATE, STATE>;
