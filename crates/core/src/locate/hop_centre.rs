//! Frequency diversity's position: each antenna's hop range, multilaterated.

use nalgebra::{Complex, Matrix3, Vector3};

use super::{hop_range, PhaseReads};
use crate::model::ReflectedPath;

/// Position and covariance (m, m²; in 2D the z row and column are zero)
/// from each antenna's hop range ([`hop_range`], weighted by 1/σ², σ at
/// least 1 mm), by weighted Gauss–Newton from the box's centre. The
/// carrier's own constant is the tag's offset, common to all antennas, so
/// one antenna alone has no lattice: only the slopes range. `None` with
/// fewer ranges than axes.
pub fn hop_centre(reads: &PhaseReads, low: &Vector3<f64>, high: &Vector3<f64>, axes: usize) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let used = reads.used_anchors();
    let max_range = used
        .iter()
        .flat_map(|&a| [(low - reads.anchors[a]).norm(), (high - reads.anchors[a]).norm()])
        .fold(0.0, f64::max)
        + 1.0;
    let (mut anchors, mut ranges, mut weights, mut owners) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for a in used {
        let rows: Vec<usize> = (0..reads.z.len()).filter(|&i| reads.antenna[i] == a).collect();
        let z: Vec<Complex<f64>> = rows.iter().map(|&i| reads.z[i]).collect();
        let k: Vec<f64> = rows.iter().map(|&i| reads.k[i]).collect();
        let count: Vec<f64> = rows.iter().map(|&i| reads.count(i)).collect();
        if let Some((d, sigma)) = hop_range(&z, &k, Some(&count), max_range) {
            if d.is_finite() && sigma.is_finite() {
                anchors.push(reads.anchors[a]);
                owners.push(a);
                ranges.push(d);
                weights.push(1.0 / sigma.max(1e-3).powi(2));
            }
        }
    }
    if ranges.len() < axes {
        return None;
    }
    let (centre, covariance) = weighted_multilateration(&anchors, &ranges, &weights, 0.5 * (low + high), axes)?;
    let Some(paths) = reads.paths else { return Some((centre, covariance)) };
    // Known reflectors bend each hop range by up to their excess phase's
    // slope against k (`slope_bias_bound`); that bound joins each range's
    // variance, so the box spans the lattice points the reflectors can
    // have moved the ranges over.
    let widened: Vec<f64> = owners
        .iter()
        .zip(&weights)
        .map(|(&a, &w)| {
            let own = paths.per_anchor.get(a).map_or(&[][..], |p| p.as_slice());
            let bias = slope_bias_bound(own, &reads.anchors[a], &centre);
            1.0 / (1.0 / w + bias * bias)
        })
        .collect();
    weighted_multilateration(&anchors, &ranges, &widened, centre, axes)
}

/// The most that reflected paths can move an antenna's hop range at tag
/// position p, m. The hop range is the slope of the phase k d_app against
/// k, d − ∂arg S/∂k with S = 1 + Σ t_p, t_p = Γ_p (d/L_p) e^{−jk(L_p − d)}
/// ([`crate::model::apparent_range`]); |∂arg S/∂k| ≤ Σ |t_p| (L_p − d) /
/// (1 − Σ |t_p|).
fn slope_bias_bound(paths: &[ReflectedPath], anchor: &Vector3<f64>, p: &Vector3<f64>) -> f64 {
    let d = (p - anchor).norm().max(1e-9);
    let (mut turning, mut magnitude) = (0.0, 0.0);
    for path in paths {
        if let Some((q, n, side)) = path.plane {
            if (p - q).dot(&n) * side <= 0.0 {
                continue;
            }
        }
        let length = path.lead_m + (p - path.source).norm().max(1e-9);
        let t = path.coefficient.abs() * d / length;
        turning += t * (length - d).abs();
        magnitude += t;
    }
    if magnitude >= 1.0 {
        return f64::INFINITY;
    }
    turning / (1.0 - magnitude)
}

/// Minimises Σ wᵢ (|p − aᵢ| − dᵢ)² by Gauss–Newton (20 steps at most);
/// returns p and (Σ wᵢ uᵢuᵢᵀ)⁻¹ at the last step, the covariance for
/// range variances 1/wᵢ (infinite when singular). A singular normal
/// matrix takes the minimum-norm step (the pseudo-inverse).
fn weighted_multilateration(anchors: &[Vector3<f64>], ranges: &[f64], weights: &[f64], start: Vector3<f64>, axes: usize) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let mut p = start;
    let mut normal = Matrix3::zeros();
    for _ in 0..20 {
        normal = Matrix3::zeros();
        let mut gradient = Vector3::zeros();
        for ((a, &d), &w) in anchors.iter().zip(ranges).zip(weights) {
            let offset = p - a;
            let r = offset.norm().max(1e-12);
            let mut u = offset / r;
            if axes == 2 {
                u.z = 0.0;
            }
            normal += w * u * u.transpose();
            gradient += w * u * (d - r);
        }
        let step = solve(&normal, &gradient, axes)?;
        p += step;
        if step.norm() < 1e-7 {
            break;
        }
    }
    let covariance = invert(&normal, axes).unwrap_or_else(|| infinite(axes));
    Some((p, covariance))
}

/// Infinite over the first `axes` (a singular fit), zero beyond.
pub(super) fn infinite(axes: usize) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| if r < axes && c < axes { f64::INFINITY } else { 0.0 })
}

/// (H restricted to the first `axes`)⁻¹, zero-padded; `None` if singular.
pub(super) fn invert(h: &Matrix3<f64>, axes: usize) -> Option<Matrix3<f64>> {
    let mut padded = *h;
    for axis in axes..3 {
        padded.row_mut(axis).fill(0.0);
        padded.column_mut(axis).fill(0.0);
        padded[(axis, axis)] = 1.0;
    }
    let mut inverse = padded.try_inverse()?;
    if inverse.iter().any(|v| !v.is_finite()) {
        return None;
    }
    for axis in axes..3 {
        inverse[(axis, axis)] = 0.0;
    }
    Some(inverse)
}

fn solve(h: &Matrix3<f64>, g: &Vector3<f64>, axes: usize) -> Option<Vector3<f64>> {
    let mut padded = *h;
    for axis in axes..3 {
        padded.row_mut(axis).fill(0.0);
        padded.column_mut(axis).fill(0.0);
    }
    let mut gradient = *g;
    for axis in axes..3 {
        gradient[axis] = 0.0;
    }
    let step = padded.pseudo_inverse(1e-12).ok()? * gradient;
    step.iter().all(|v| v.is_finite()).then_some(step)
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    #[test]
    fn hop_ranges_multilaterate_near_the_truth() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let (p, covariance) = hop_centre(&reads, &Vector3::zeros(), &Vector3::repeat(1.5), 3).unwrap();
        assert!((p - truth).norm() < 1e-4, "{p:?}");
        assert!(covariance.diagonal().iter().all(|v| v.is_finite() && *v > 0.0));
        assert!(hop_centre(&reads, &Vector3::zeros(), &Vector3::repeat(1.5), 3).is_some());
        let one = PhaseReads::new(&z[..50], &k[..50], &antenna[..50], &anchors);
        assert!(hop_centre(&one, &Vector3::zeros(), &Vector3::repeat(1.5), 3).is_none());
    }
}
