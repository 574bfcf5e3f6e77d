use nalgebra::{Matrix3, Vector3};

use crate::model::{StateMatrix, StateVector, Transition};

/// Prediction (GLAC eqs. 5–6): x ← F x, P ← F P Fᵀ + Q.
#[inline]
pub fn predict(x: &mut StateVector, p: &mut StateMatrix, transition: &Transition) {
    transition.propagate(x, p);
}

/// Innovation statistics of one scalar update.
#[derive(Debug, Clone, Copy)]
pub struct ScalarUpdate {
    /// Innovation ν = z − h(x⁻) (measurement units).
    pub innovation: f64,
    /// Innovation variance S = H P⁻ Hᵀ + R.
    pub variance: f64,
}

/// The innovation of a scalar measurement without applying it: lets a
/// tracker gate first (GLAC's 3σ recovery) and update only if accepted.
#[inline]
pub fn innovation(p: &StateMatrix, z: f64, h: f64, jacobian: &StateVector, r: f64) -> (ScalarUpdate, StateVector) {
    let b = p * jacobian;
    let s = jacobian.dot(&b) + r;
    (ScalarUpdate { innovation: z - h, variance: s }, b)
}

/// Scalar EKF update (GLAC eqs. 7–8) with measurement `z`, prediction
/// `h = h(x⁻)`, Jacobian `H` (as a vector) and noise variance `R`.
///
/// With b = P Hᵀ and S = H b + R: K = b / S, x ← x + K ν and
/// P ← P − b bᵀ / S. For the optimal gain this symmetric rank-one
/// downdate equals the Joseph form exactly, and being written as a
/// symmetric outer product it keeps P symmetric to the last bit.
#[inline]
pub fn update_scalar(
    x: &mut StateVector,
    p: &mut StateMatrix,
    z: f64,
    h: f64,
    jacobian: &StateVector,
    r: f64,
) -> ScalarUpdate {
    let (u, b) = innovation(p, z, h, jacobian, r);
    apply_scalar(x, p, &u, &b);
    u
}

/// Applies an update computed by [`innovation`].
#[inline]
pub fn apply_scalar(x: &mut StateVector, p: &mut StateMatrix, u: &ScalarUpdate, b: &StateVector) {
    let inv_s = 1.0 / u.variance;
    *x += b * (u.innovation * inv_s);
    p.ger(-inv_s, b, b, 1.0);
}

/// Linear update with a direct position measurement `z` (m), H = [I 0],
/// covariance `r` (m²): the synchronous 4-read variant (GLAC sec. 5.2.2,
/// scheme 3), where four reads are first trilaterated into a position.
/// Joseph form here: K is optimal only up to the trilateration's
/// linearisation, and this update runs once per four reads, so the extra
/// cost buys guaranteed PSD. Returns (ν, S) as 3-vectors/matrices.
pub fn update_position(
    x: &mut StateVector,
    p: &mut StateMatrix,
    z: &Vector3<f64>,
    r: &Matrix3<f64>,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let nu = z - Vector3::new(x[0], x[1], x[2]);
    let s: Matrix3<f64> = p.fixed_view::<3, 3>(0, 0).into_owned() + r;
    let s_inv = s.try_inverse()?;
    let pht = p.fixed_view::<6, 3>(0, 0).into_owned();
    let k = pht * s_inv;
    *x += k * nu;
    let mut i_kh = StateMatrix::identity();
    i_kh.fixed_view_mut::<6, 3>(0, 0).sub_assign(&k);
    *p = i_kh * *p * i_kh.transpose() + k * r * k.transpose();
    Some((nu, s))
}

use std::ops::SubAssign;

/// log N(ν; 0, S) for a scalar Gaussian.
#[inline]
pub fn log_gaussian(innovation: f64, variance: f64) -> f64 {
    -0.5 * (innovation * innovation / variance + (2.0 * std::f64::consts::PI * variance).ln())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{range, MotionModel};

    fn is_psd(p: &StateMatrix) -> bool {
        let sym = (p - p.transpose()).norm() <= 1e-12 * p.norm().max(1.0);
        let scale = p.symmetric_eigenvalues().amax();
        sym && p.symmetric_eigenvalues().iter().all(|&e| e > -1e-10 * scale)
    }

    /// Property: many random predict/update cycles keep P symmetric PSD.
    #[test]
    fn covariance_stays_psd() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % 10_000) as f64 / 10_000.0
        };
        let anchors = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.8, 0.0), Vector3::new(0.8, 0.8, 0.0)];
        let model = MotionModel::ConstantVelocity { q: 0.5 };
        let mut x = StateVector::from_iterator([0.4, 0.4, 0.6, 0.1, 0.0, 0.0]);
        let mut p = StateMatrix::identity() * 1e-4;
        for k in 0..5000 {
            predict(&mut x, &mut p, &model.transition(0.01 + 0.05 * rnd(), 3));
            let a = anchors[k % 3];
            let (h, jac) = range(&x, &a, 3, true);
            update_scalar(&mut x, &mut p, h + 0.003 * (rnd() - 0.5), h, &jac.unwrap(), 1e-6 + 1e-5 * rnd());
            assert!(is_psd(&p), "step {k}: eigenvalues {:?}", p.symmetric_eigenvalues());
        }
    }

    #[test]
    fn scalar_update_matches_textbook() {
        let mut x = StateVector::from_iterator([0.4, 0.4, 0.6, 0.1, 0.0, 0.0]);
        let a = StateMatrix::from_fn(|r, c| ((r * 5 + c * 2) % 7) as f64 * 0.01);
        let mut p = a * a.transpose() + StateMatrix::identity() * 1e-3;
        let (x0, p0) = (x, p);
        let hv = StateVector::from_iterator([0.6, 0.0, 0.8, 0.0, 0.0, 0.0]);
        update_scalar(&mut x, &mut p, 1.01, 1.0, &hv, 1e-4);
        let s = (hv.transpose() * p0 * hv)[(0, 0)] + 1e-4;
        let k = p0 * hv / s;
        let x_ref = x0 + k * 0.01;
        let i_kh = StateMatrix::identity() - k * hv.transpose();
        let p_joseph = i_kh * p0 * i_kh.transpose() + k * 1e-4 * k.transpose();
        assert!((x - x_ref).norm() < 1e-12);
        assert!((p - p_joseph).norm() < 1e-12);
    }
}
