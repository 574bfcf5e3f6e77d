//! Distances and the intersections of the loci that a phase defines:
//! spheres (monostatic, 3D), circles (monostatic, tag in a plane),
//! ellipsoids and ellipses (bistatic helper: tx → tag → rx), and a
//! least-squares multilateration that refines a rough fix; and the scene
//! geometry check (twin positions a layout cannot tell apart).
//!
//! Contract: pure functions on `nalgebra` vectors, metres in and out; a
//! degenerate configuration returns no point rather than a NaN.

pub mod ambiguity;
mod circle;
mod ellipsoid;
mod multilateration;
mod sphere;
pub mod twins;

pub use ambiguity::{analyse_scene, joint_frequencies, twin_positions, twin_search, AmbiguityOptions, AmbiguityReport, TwinFamily};
pub use circle::circle_intersections;
pub use ellipsoid::{bistatic_distance, bistatic_intersections};
pub use multilateration::{multilaterate, Multilateration};
pub use sphere::sphere_intersections;
pub use twins::{Twin, TwinSearch, TwinTolerance};

use nalgebra::Vector3;

/// Euclidean distance |p − a| (m).
#[inline]
pub fn distance(p: &Vector3<f64>, a: &Vector3<f64>) -> f64 {
    (p - a).norm()
}
