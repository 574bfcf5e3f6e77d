//! Apparent range under known reflectors: the distance a monostatic
//! reader's phase reports when walls or scatterers add paths.
//!
//! With the direct one-way path of length d (amplitude 1/d) and reflected
//! paths of length L_p (amplitude Γ_p / L_p; an image source for a plane,
//! antenna → scatterer → tag for a point), the round-trip channel is
//! h = (Σ_p a_p e^{−j k d_p})², k = 2π f / c (reciprocity: the same paths
//! out and back). Relative to the direct path,
//!
//! `S = 1 + Σ_p Γ_p (d / L_p) e^{−j k (L_p − d)}`,
//!
//! and the phase is `s · 2k (d − arg S / k)`: the reading reports the
//! **apparent range** `d_app = d − arg(S) / k` (m). A wall with Γ = 0.3
//! behind the work area moves it by up to asin(Γ d / L) / k, 8–15 mm at
//! 915 MHz, a ripple
//! that changes with position on a scale of λ/2 and with the carrier:
//! invisible to a single-path model, which follows it as a bias of about a
//! centimetre (docs/glac.md, "Known reflectors").
//!
//! With one reflector `arg S` has no 2π jump: |Γ d / L| < 1 keeps Re S > 0
//! (a plane's image is always farther than the antenna). Several strong
//! reflectors can turn Re S negative, and the apparent range then jumps by
//! a wavelength where arg S crosses π: a multiple of the candidate
//! spacing, which candidate selection tolerates. Where the paths cancel
//! (S ≈ 0: a reflector of Γ = −1 at the antenna) the phase is undefined,
//! and the direct range is returned instead of NaN.

use nalgebra::Vector3;

use super::StateVector;
use crate::scene::Reflector;

/// One reflected path of one antenna, fixed by the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectedPath {
    /// Where the path's last leg to the tag starts (m): the antenna's
    /// mirror image in a plane, or a point scatterer.
    pub source: Vector3<f64>,
    /// Length of the path before `source` (m): 0 for an image, the
    /// antenna-scatterer distance for a point.
    pub lead_m: f64,
    /// Amplitude reflection coefficient Γ (signed, |Γ| ≤ 1).
    pub coefficient: f64,
    /// A plane's point and unit normal, and the side the antenna is on
    /// (sign of (a − q)·n): a plane reflects only between points on the
    /// same side.
    pub plane: Option<(Vector3<f64>, Vector3<f64>, f64)>,
}

/// The reflected paths that `reflectors` give antenna position `a` (m). A
/// plane through the antenna itself gives no path (its image coincides).
pub fn reflected_paths(a: &Vector3<f64>, reflectors: &[Reflector]) -> Vec<ReflectedPath> {
    reflectors
        .iter()
        .filter_map(|r| match *r {
            Reflector::Plane { point, normal, coefficient } => {
                let side = (a - point).dot(&normal);
                (side.abs() > 1e-9).then(|| ReflectedPath {
                    source: a - 2.0 * side * normal,
                    lead_m: 0.0,
                    coefficient,
                    plane: Some((point, normal, side.signum())),
                })
            }
            Reflector::Point { position, coefficient } => {
                Some(ReflectedPath { source: position, lead_m: (position - a).norm(), coefficient, plane: None })
            }
        })
        .collect()
}

/// Apparent range `d_app = d − arg(S)/k` (m) from antenna `a` (m) to the
/// tag at position `p` (m) under `paths`, at wavenumber `k = 2π f / c`
/// (rad/m), and with `gradient` its gradient ∂d_app/∂p = u − ∂arg S/∂p / k:
/// for each path t = Γ (d/L) e^{−jk(L−d)},
/// ∂t/∂p = t · [(u/d − w/L) + j k (u − w)], u and w the unit vectors from
/// the antenna and from the path's source to the tag, and
/// ∂arg S = (Re S ∂Im S − Im S ∂Re S) / |S|². Without paths this is the
/// distance and u. For `locate`, which has positions, not states.
pub fn apparent_range_at(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    paths: &[ReflectedPath],
    wavenumber: f64,
    gradient: bool,
) -> (f64, Option<Vector3<f64>>) {
    let direct = p - a;
    let d = direct.norm().max(1e-9);
    let u = direct / d;
    // S = re + j im and, on request, its gradient.
    let (mut re, mut im) = (1.0, 0.0);
    let (mut d_re, mut d_im) = (Vector3::zeros(), Vector3::zeros());
    for path in paths {
        if let Some((q, n, side)) = path.plane {
            if (p - q).dot(&n) * side <= 0.0 {
                continue;
            }
        }
        let leg = p - path.source;
        let leg_length = leg.norm().max(1e-9);
        let length = path.lead_m + leg_length;
        let magnitude = path.coefficient * d / length;
        let (sin, cos) = (-wavenumber * (length - d)).sin_cos();
        let (tr, ti) = (magnitude * cos, magnitude * sin);
        re += tr;
        im += ti;
        if gradient {
            let w = leg / leg_length;
            let alpha = u / d - w / length;
            let beta = (u - w) * wavenumber;
            d_re += alpha * tr - beta * ti;
            d_im += beta * tr + alpha * ti;
        }
    }
    if re * re + im * im < 1e-12 {
        // The paths cancel: no phase to speak of (module docs).
        return (d, gradient.then_some(u));
    }
    let apparent = d - im.atan2(re) / wavenumber;
    if !gradient {
        return (apparent, None);
    }
    let d_arg = (d_im * re - d_re * im) / (re * re + im * im);
    (apparent, Some(u - d_arg / wavenumber))
}

/// [`apparent_range_at`] for the tag of state `x`; with `jacobian`, also
/// H = ∂d_app/∂x = [(∂d_app/∂p)ᵀ, 0, 0, 0]. `axes == 2` zeroes the z
/// entry, as [`super::range`] does. Without paths this is `range`.
pub fn apparent_range(
    x: &StateVector,
    a: &Vector3<f64>,
    paths: &[ReflectedPath],
    wavenumber: f64,
    axes: usize,
    jacobian: bool,
) -> (f64, Option<StateVector>) {
    let (apparent, gradient) = apparent_range_at(&Vector3::new(x[0], x[1], x[2]), a, paths, wavenumber, jacobian);
    let h = gradient.map(|g| {
        let mut h = StateVector::zeros();
        for i in 0..axes {
            h[i] = g[i];
        }
        h
    });
    (apparent, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SPEED_OF_LIGHT;

    fn wall() -> Vec<Reflector> {
        vec![
            Reflector::Plane { point: Vector3::new(1.6, 0.0, 0.0), normal: Vector3::new(-1.0, 0.0, 0.0), coefficient: 0.3 },
            Reflector::Point { position: Vector3::new(0.4, 1.5, 0.2), coefficient: -0.2 },
        ]
    }

    fn k() -> f64 {
        2.0 * std::f64::consts::PI * 915.25e6 / SPEED_OF_LIGHT
    }

    /// Finite-difference check of H (central differences, GTSAM-style
    /// numericalDerivative).
    #[test]
    fn jacobian_matches_finite_differences() {
        let a = Vector3::new(0.8, 0.8, 0.0);
        let paths = reflected_paths(&a, &wall());
        assert_eq!(paths.len(), 2);
        for step in 0..40 {
            let s = step as f64;
            let x = StateVector::from_iterator([0.1 + 0.031 * s, 0.3 - 0.017 * s, 0.7 + 0.01 * s, 0.1, -0.2, 0.05]);
            let (_, h) = apparent_range(&x, &a, &paths, k(), 3, true);
            let h = h.unwrap();
            for i in 0..6 {
                let eps = 1e-7;
                let (mut xp, mut xm) = (x, x);
                xp[i] += eps;
                xm[i] -= eps;
                let num = (apparent_range(&xp, &a, &paths, k(), 3, false).0 - apparent_range(&xm, &a, &paths, k(), 3, false).0) / (2.0 * eps);
                assert!((num - h[i]).abs() < 1e-6, "step {step} component {i}: {num} vs {}", h[i]);
            }
        }
    }

    /// The apparent range is the phase of the summed paths, computed here
    /// independently from complex path sums (the simulator's form).
    #[test]
    fn matches_the_phase_of_the_summed_paths() {
        let a = Vector3::new(0.0, 0.2, 0.3);
        let reflectors = wall();
        let paths = reflected_paths(&a, &reflectors);
        for step in 0..25 {
            let p = Vector3::new(0.2 + 0.05 * step as f64, 0.9 - 0.02 * step as f64, 0.6);
            let x = StateVector::from_iterator([p.x, p.y, p.z, 0.0, 0.0, 0.0]);
            let (re_sum, im_sum) = {
                let d = (p - a).norm();
                let mut sum = (d.recip() * (-k() * d).cos(), d.recip() * (-k() * d).sin());
                // The wall's image and the scatterer, summed as they are.
                let image = Vector3::new(3.2 - a.x, a.y, a.z);
                let l_wall = (p - image).norm();
                let l_point = (Vector3::new(0.4, 1.5, 0.2) - a).norm() + (p - Vector3::new(0.4, 1.5, 0.2)).norm();
                for (l, g) in [(l_wall, 0.3), (l_point, -0.2)] {
                    sum.0 += g / l * (-k() * l).cos();
                    sum.1 += g / l * (-k() * l).sin();
                }
                sum
            };
            // Round trip: arg h = 2 arg(one-way sum); phase = −arg h = 2k d_app (mod 2π).
            let phase = -2.0 * im_sum.atan2(re_sum);
            let (d_app, _) = apparent_range(&x, &a, &paths, k(), 3, false);
            let difference = crate::angle::wrap_signed(phase - 2.0 * k() * d_app, std::f64::consts::TAU);
            assert!(difference.abs() < 1e-9, "{difference}");
        }
    }

    #[test]
    fn no_paths_is_the_plain_range() {
        let a = Vector3::new(0.3, 0.0, 0.0);
        let x = StateVector::from_iterator([0.5, 0.6, 0.7, 0.0, 0.0, 0.0]);
        let (d, h) = apparent_range(&x, &a, &[], k(), 3, true);
        let (r, hr) = super::super::range(&x, &a, 3, true);
        assert!((d - r).abs() < 1e-12);
        assert!((h.unwrap() - hr.unwrap()).norm() < 1e-12);
    }

    /// A tag behind the wall (on the other side from the antenna) sees no reflection from it.
    #[test]
    fn a_plane_reflects_only_on_the_antennas_side() {
        let a = Vector3::new(0.0, 0.0, 0.0);
        let paths = reflected_paths(&a, &wall()[..1]);
        let x = StateVector::from_iterator([1.7, 0.2, 0.3, 0.0, 0.0, 0.0]);
        let (d, _) = apparent_range(&x, &a, &paths, k(), 3, false);
        assert!((d - Vector3::<f64>::new(1.7, 0.2, 0.3).norm()).abs() < 1e-12);
        let x = StateVector::from_iterator([1.2, 0.2, 0.3, 0.0, 0.0, 0.0]);
        let (d, _) = apparent_range(&x, &a, &paths, k(), 3, false);
        let excess = (d - Vector3::<f64>::new(1.2, 0.2, 0.3).norm()).abs();
        assert!(excess > 1e-4 && excess < 0.02, "{excess}");
    }

    /// A Γ = −1 scatterer at the antenna cancels the direct path for every
    /// tag: the range stays finite (the direct one) instead of NaN.
    #[test]
    fn paths_that_cancel_give_the_direct_range_not_nan() {
        let a = Vector3::new(0.2, 0.1, 0.0);
        let paths = reflected_paths(&a, &[Reflector::Point { position: a, coefficient: -1.0 }]);
        let x = StateVector::from_iterator([0.9, 0.6, 0.7, 0.0, 0.0, 0.0]);
        let (d, h) = apparent_range(&x, &a, &paths, k(), 3, true);
        let (r, hr) = super::super::range(&x, &a, 3, true);
        assert!((d - r).abs() < 1e-12, "{d} {r}");
        assert!((h.unwrap() - hr.unwrap()).norm() < 1e-12);
    }
}
