use nalgebra::{Matrix3, Vector3};

/// Result of [`multilaterate`].
#[derive(Debug, Clone, Copy)]
pub struct Multilateration {
    /// Least-squares position, metres.
    pub position: Vector3<f64>,
    /// Root-mean-square range residual at the solution, metres.
    pub rms_residual: f64,
    /// Gauss–Newton normal matrix JᵀJ at the solution (unitless); the
    /// position covariance is σ_d² (JᵀJ)⁻¹ for range noise σ_d. In 2D the
    /// z row and column are zero except a unit diagonal.
    pub normal: Matrix3<f64>,
}

/// Refines `initial` (m) to minimise Σ (|p − aᵢ| − dᵢ)² by Gauss–Newton.
///
/// `dimensions == 2` keeps z fixed at `initial.z` (tag in a plane). The
/// Jacobian row of a range is the unit vector (p − a)/|p − a|. Returns
/// `None` when the geometry is singular (too few ranges or all ranges along
/// one direction).
pub fn multilaterate(
    anchors: &[Vector3<f64>],
    distances: &[f64],
    initial: Vector3<f64>,
    dimensions: usize,
    iterations: usize,
) -> Option<Multilateration> {
    debug_assert_eq!(anchors.len(), distances.len());
    let mut p = initial;
    let mut normal = Matrix3::zeros();
    for _ in 0..iterations.max(1) {
        let mut jtj = Matrix3::<f64>::zeros();
        let mut jtr = Vector3::<f64>::zeros();
        for (a, &d) in anchors.iter().zip(distances) {
            let diff = p - a;
            let r = diff.norm().max(1e-9);
            let mut u = diff / r;
            if dimensions == 2 {
                u.z = 0.0;
            }
            jtj += u * u.transpose();
            jtr += u * (d - r);
        }
        if dimensions == 2 {
            jtj[(2, 2)] = 1.0;
        }
        normal = jtj;
        let step = jtj.try_inverse()? * jtr;
        p += step;
        if step.norm() < 1e-7 {
            break;
        }
    }
    let sum: f64 = anchors.iter().zip(distances).map(|(a, d)| ((p - a).norm() - d).powi(2)).sum();
    Some(Multilateration { position: p, rms_residual: (sum / anchors.len() as f64).sqrt(), normal })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_from_a_nearby_guess() {
        let anchors = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, 0.3, 0.0),
            Vector3::new(0.0, 0.8, 0.0),
            Vector3::new(0.8, 0.8, 0.0),
        ];
        let truth = Vector3::new(0.36, 0.5, 0.71);
        let d: Vec<f64> = anchors.iter().map(|a| (truth - a).norm()).collect();
        let fix = multilaterate(&anchors, &d, truth + Vector3::new(0.03, -0.02, 0.04), 3, 10).unwrap();
        assert!((fix.position - truth).norm() < 1e-7);
        assert!(fix.rms_residual < 1e-7);
        let truth2 = Vector3::new(0.6, 0.3, 0.0);
        let d2: Vec<f64> = anchors.iter().map(|a| (truth2 - a).norm()).collect();
        let fix2 = multilaterate(&anchors, &d2, Vector3::new(0.62, 0.28, 0.0), 2, 10).unwrap();
        assert!((fix2.position - truth2).norm() < 1e-7);
        assert_eq!(fix2.position.z, 0.0);
    }
}
