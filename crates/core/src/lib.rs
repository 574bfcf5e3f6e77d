//! scattertrack-core: estimators for RF backscatter tag tracking.
//! No Python and no I/O here; the bindings in `python/` are thin wrappers.
//!
//! Map of the crate:
//! - [`angle`]: the one phase-wrapping function.
//! - [`scene`]: antennas, phase model, calibration, region.
//! - [`geometry`]: distances, sphere/circle intersections, multilateration.
//! - [`model`]: motion models (F, Q) and measurement models (h, H).
//! - [`filter`]: EKF predict/update as pure functions on (x, P).
//! - [`track`]: the [`track::Tracker`] interface and one file per method
//!   (GLAC and its variants).
//! - [`params`]: typed parameter tables (name, type, range, unit, default)
//!   read by the bindings, the CLI and the docs.
//! - [`engine`]: many tags, reorder window, latency statistics.
//! - [`prefetch`]: cache hints for the next tag's state (the one `unsafe`).
//!
//! Units are SI everywhere (m, s, rad, Hz); numbers are `f64`.

pub mod angle;
pub mod engine;
pub mod error;
pub mod filter;
pub mod geometry;
pub mod locate;
pub mod model;
pub mod params;
pub mod prefetch;
pub mod scene;
pub mod track;

pub use error::{Error, Result};
