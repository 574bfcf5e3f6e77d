use nalgebra::Vector3;

use super::StateVector;

/// Range from antenna `a` to the tag: h(x) = |p − a| (m), GLAC eq. 4.
///
/// With `jacobian`, also returns H = ∂h/∂x = [uᵀ, 0, 0, 0] where
/// u = (p − a)/|p − a| is the unit line of sight; velocity does not enter a
/// single range (GLAC's C_k). `axes == 2` zeroes the z entry (the tag is
/// held on its plane).
#[inline]
pub fn range(x: &StateVector, a: &Vector3<f64>, axes: usize, jacobian: bool) -> (f64, Option<StateVector>) {
    let diff = Vector3::new(x[0] - a.x, x[1] - a.y, x[2] - a.z);
    let r = diff.norm();
    if !jacobian {
        return (r, None);
    }
    let inv = 1.0 / r.max(1e-9);
    let mut h = StateVector::zeros();
    for i in 0..axes {
        h[i] = diff[i] * inv;
    }
    (r, Some(h))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Finite-difference check of H (central differences, GTSAM-style
    /// numericalDerivative).
    #[test]
    fn jacobian_matches_finite_differences() {
        let a = Vector3::new(0.8, 0.8, 0.0);
        for k in 0..20 {
            let x = StateVector::from_iterator([
                0.1 + 0.05 * k as f64,
                0.3 - 0.02 * k as f64,
                0.7,
                0.1,
                -0.2,
                0.05,
            ]);
            let (_, h) = range(&x, &a, 3, true);
            let h = h.unwrap();
            for i in 0..6 {
                let eps = 1e-6;
                let mut xp = x;
                let mut xm = x;
                xp[i] += eps;
                xm[i] -= eps;
                let num = (range(&xp, &a, 3, false).0 - range(&xm, &a, 3, false).0) / (2.0 * eps);
                assert!((num - h[i]).abs() < 1e-7, "component {i}: {num} vs {}", h[i]);
            }
        }
    }
}
