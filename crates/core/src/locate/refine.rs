//! The local maximum of R(p) near a seed, by Gauss–Newton.

use nalgebra::{Complex, Matrix3, Vector3};

use super::coherence::Envelopes;
use super::{coherence, rotation, PhaseReads};

/// The local maximum of R near `start`: Gauss–Newton on
/// r_k = arg(z_k e^{−j k_k d_k} e^{−jθ}), θ re-profiled each step, the
/// Jacobian centred over reads (θ is a nuisance). `axes` = 2 keeps z.
/// Under known reflectors d_k is the apparent range and its gradient.
/// A group's residual is its summed phasor's, weighted by its reads.
/// Returns the position and its coherence.
pub fn refine(reads: &PhaseReads, start: Vector3<f64>, axes: usize, iterations: usize) -> (Vector3<f64>, f64) {
    let n = reads.z.len();
    let mut p = start;
    let mut rotated = vec![Complex::new(0.0, 0.0); n];
    let mut jacobian = vec![Vector3::zeros(); n];
    for _ in 0..iterations {
        let mut sum = Complex::new(0.0, 0.0);
        for i in 0..n {
            let (d, gradient) = reads.distance_gradient(i, &p);
            rotated[i] = reads.z[i] * rotation(reads.k[i] * d);
            sum += rotated[i];
            jacobian[i] = gradient * reads.k[i];
        }
        let theta = Complex::new(0.0, -sum.arg()).exp();
        let mean: Vector3<f64> = (0..n).map(|i| jacobian[i] * reads.count(i)).sum::<Vector3<f64>>() / reads.total();
        let mut normal = Matrix3::zeros();
        let mut gradient = Vector3::zeros();
        for i in 0..n {
            let mut j = jacobian[i] - mean;
            if axes == 2 {
                j.z = 0.0;
            }
            let (r, w) = ((rotated[i] * theta).arg(), reads.count(i));
            normal += w * j * j.transpose();
            gradient += w * j * r;
        }
        if axes == 2 {
            normal[(2, 2)] = 1.0;
        }
        let Some(inverse) = normal.try_inverse() else { break };
        let step = inverse * gradient;
        p += step;
        if step.norm() < 1e-7 {
            break;
        }
    }
    (p, coherence(reads, &p))
}

/// A seed brought near its local maximum of R cheaply, on the envelope
/// tables: each antenna is one phasor A_a = e^{−j k̄ d_a} E_a(d_a) whose
/// phase turns at κ_a = Im(A_a′ / A_a) rad/m along the range, and
/// Gauss–Newton aligns the antennas' phases (weights |A_a|, θ profiled).
/// Within an antenna the channels' envelope is taken as flat, which moves
/// the point by about (|E|′/|E|) / k̄² (a fraction of a millimetre):
/// [`refine`] on the reads finishes from there.
pub fn refine_on_envelopes(envelopes: &Envelopes, start: Vector3<f64>, axes: usize, iterations: usize) -> Vector3<f64> {
    let mut p = start;
    let tables = &envelopes.tables;
    for _ in 0..iterations {
        let mut sum = Complex::new(0.0, 0.0);
        let mut parts = Vec::with_capacity(tables.len());
        for table in tables {
            let offset = p - table.anchor;
            let d = offset.norm().max(1e-9);
            let (e, slope) = table.at_with_slope(d);
            let carrier = rotation(envelopes.mean_k * d);
            let value = e * carrier;
            let derivative = (slope - Complex::new(0.0, envelopes.mean_k) * e) * carrier;
            sum += value;
            parts.push((value, derivative, offset / d));
        }
        let theta = Complex::new(0.0, -sum.arg()).exp();
        let weight_total: f64 = parts.iter().map(|(v, _, _)| v.norm()).sum();
        if weight_total <= 0.0 {
            break;
        }
        // j_a = −κ_a u_a: the residual's derivative is −j_a, as for single reads (j = k u).
        let rows: Vec<(Vector3<f64>, f64, f64)> =
            parts.iter().map(|(v, dv, u)| (-(dv / v).im * u, (v * theta).arg(), v.norm())).collect();
        let mean: Vector3<f64> = rows.iter().map(|(j, _, w)| j * *w).sum::<Vector3<f64>>() / weight_total;
        let mut normal = Matrix3::zeros();
        let mut gradient = Vector3::zeros();
        for (j, r, w) in &rows {
            let mut j = j - mean;
            if axes == 2 {
                j.z = 0.0;
            }
            normal += *w * j * j.transpose();
            gradient += *w * j * *r;
        }
        for axis in axes..3 {
            normal[(axis, axis)] = 1.0;
        }
        // Fewer antennas than unknowns (+ θ): the minimum-norm step.
        let Some(inverse) = normal.try_inverse().or_else(|| normal.pseudo_inverse(1e-9 * normal.norm()).ok()) else { break };
        let step = inverse * gradient;
        if !step.iter().all(|v| v.is_finite()) {
            break;
        }
        p += step;
        if step.norm() < 1e-6 {
            break;
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    #[test]
    fn refine_climbs_to_the_true_position() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        assert!((coherence(&reads, &truth) - 1.0).abs() < 1e-12);
        let (p, r) = refine(&reads, truth + Vector3::new(0.01, -0.008, 0.005), 3, 10);
        assert!((p - truth).norm() < 1e-6 && r > 0.999999);
    }

    #[test]
    fn envelope_refinement_lands_near_the_maximum() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let envelopes = Envelopes::new(&reads, &(truth - Vector3::repeat(0.1)), &(truth + Vector3::repeat(0.1)));
        let p = refine_on_envelopes(&envelopes, truth + Vector3::new(0.012, -0.01, 0.008), 3, 10);
        assert!((p - truth).norm() < 5e-4, "{:?}", p - truth);
    }

    #[test]
    fn two_axes_keep_the_height() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.0);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let (p, _) = refine(&reads, truth + Vector3::new(0.01, -0.01, 0.0), 2, 10);
        assert!((p - truth).norm() < 1e-6 && p.z == 0.0);
    }
}
