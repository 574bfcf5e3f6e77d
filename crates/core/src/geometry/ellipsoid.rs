//! Intersections of confocal bistatic loci: the points `p` whose path
//! length `|p − tx| + |p − rxᵢ| = dᵢ` for several receive antennas that
//! share one transmit antenna (TurboTrack thesis §5.2, Fig. 5-2(a)):
//! ellipsoids in 3D, ellipses when the tag is confined to a plane.
//!
//! Derivation (why this is closed form). Put the transmitter at the origin,
//! `u = p − tx`, `r = |u|`, `aᵢ = rxᵢ − tx`. Then `|u − aᵢ| = dᵢ − r`;
//! squaring and cancelling `r²` leaves an equation *linear* in `(u, r)`:
//!
//! `aᵢ · u − dᵢ r = (|aᵢ|² − dᵢ²) / 2`.
//!
//! With 3 receivers in 3D (or 2 in a plane, where `u_z` is known) that is
//! 3 (2) linear equations in 4 (3) unknowns: the solutions form a line
//! `(u, r) = s₀ + t n` (n spanning the null space), and the last
//! condition `|u|² = r²` is a quadratic in `t`. So there are at most two
//! points — for antennas in one plane they are the mirror pair about it —
//! and each must satisfy `r ≤ dᵢ` (the tag lies between the foci's sums).

use nalgebra::{Matrix3, Vector3, Vector4};

/// Bistatic path length `|p − tx| + |p − rx|` (m) and, on request, its
/// gradient with respect to `p`: the sum of the two unit vectors pointing
/// from the antennas to `p` (the normal of the ellipsoid through `p`).
pub fn bistatic_distance(p: &Vector3<f64>, tx: &Vector3<f64>, rx: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let (a, b) = (p - tx, p - rx);
    let (na, nb) = (a.norm(), b.norm());
    let mut gradient = Vector3::zeros();
    if na > 0.0 {
        gradient += a / na;
    }
    if nb > 0.0 {
        gradient += b / nb;
    }
    (na + nb, gradient)
}

/// Points where the bistatic loci of `receivers` (positions, m) with path
/// lengths `distances` (m) meet, for transmitter `tx`.
///
/// `plane_z`: `Some(z)` confines the tag to the plane `z` (then exactly 2
/// receivers are needed: ellipses); `None` is free 3D (exactly 3
/// receivers: ellipsoids). Returns 0–2 points; a degenerate geometry
/// (collinear receivers, inconsistent distances) returns none. A slightly
/// negative discriminant (within `tolerance_m²` of a tangency, from noise)
/// is treated as a tangency so that noisy tags near the antenna plane are
/// not lost.
pub fn bistatic_intersections(
    tx: &Vector3<f64>,
    receivers: &[Vector3<f64>],
    distances: &[f64],
    plane_z: Option<f64>,
    tolerance_m: f64,
) -> Vec<Vector3<f64>> {
    let needed = if plane_z.is_some() { 2 } else { 3 };
    if receivers.len() != needed || distances.len() != needed {
        return Vec::new();
    }
    // Rows [aᵢ, −dᵢ] · [u; r] = (|aᵢ|² − dᵢ²)/2, padded to a 3×4 system.
    let mut a = [[0.0f64; 4]; 3];
    let mut b = [0.0f64; 3];
    for i in 0..needed {
        let ai = receivers[i] - tx;
        a[i] = [ai.x, ai.y, ai.z, -distances[i]];
        b[i] = 0.5 * (ai.norm_squared() - distances[i] * distances[i]);
    }
    if let Some(z) = plane_z {
        // Known u_z: its column moves to the right-hand side; the third
        // row pins u_z itself.
        let uz = z - tx.z;
        for i in 0..2 {
            b[i] -= a[i][2] * uz;
            a[i][2] = 0.0;
        }
        a[2] = [0.0, 0.0, 1.0, 0.0];
        b[2] = uz;
    }
    let Some((s0, n)) = line_of_solutions(&a, &b) else { return Vec::new() };
    // |u₀ + t n_u|² − (r₀ + t n_r)² = 0.
    let (u0, nu) = (s0.xyz(), n.xyz());
    let (r0, nr) = (s0.w, n.w);
    let qa = nu.norm_squared() - nr * nr;
    let qb = 2.0 * (u0.dot(&nu) - r0 * nr);
    let qc = u0.norm_squared() - r0 * r0;
    let mut roots = Vec::with_capacity(2);
    if qa.abs() < 1e-12 * (qb.abs() + qc.abs()).max(1e-300) {
        if qb.abs() > 0.0 {
            roots.push(-qc / qb);
        }
    } else {
        let mut disc = qb * qb - 4.0 * qa * qc;
        // The discriminant has units of (m²)² scaled by qa; compare the
        // squared half-chord it implies with the tolerance.
        if disc < 0.0 && -disc / (4.0 * qa * qa) <= tolerance_m * tolerance_m {
            disc = 0.0;
        }
        if disc >= 0.0 {
            let sq = disc.sqrt();
            // Numerically stable pair (no cancellation).
            let q = -0.5 * (qb + qb.signum() * sq);
            if q != 0.0 {
                roots.push(q / qa);
                roots.push(qc / q);
            } else {
                roots.push(-qb / (2.0 * qa));
            }
            if disc == 0.0 {
                roots.truncate(1);
            }
        }
    }
    let mut points = Vec::with_capacity(2);
    for t in roots {
        let u = u0 + nu * t;
        let r = r0 + nr * t;
        if !(u.iter().all(|v| v.is_finite()) && r.is_finite()) || r < -tolerance_m {
            continue;
        }
        // Each receiver leg |u − aᵢ| = dᵢ − r must be non-negative.
        if (0..needed).any(|i| distances[i] - r < -tolerance_m) {
            continue;
        }
        let p = tx + u;
        if !points.iter().any(|q: &Vector3<f64>| (q - p).norm() < 1e-9) {
            points.push(p);
        }
    }
    points
}

/// Particular solution and null-space direction of a rank-3 system
/// `A s = b` with `A` 3×4: `s = s₀ + t n`. None when the rank is lower
/// (collinear receivers).
fn line_of_solutions(a: &[[f64; 4]; 3], b: &[f64; 3]) -> Option<(Vector4<f64>, Vector4<f64>)> {
    // Drop one column at a time; the 3×3 minor with the largest
    // |determinant| is best conditioned. Its solution with the dropped
    // unknown at 0 is s₀; the null vector's components are the signed
    // minors (generalised cross product of the three rows).
    let minor = |skip: usize| -> Matrix3<f64> {
        let mut m = Matrix3::zeros();
        for r in 0..3 {
            let mut c = 0;
            for k in 0..4 {
                if k != skip {
                    m[(r, c)] = a[r][k];
                    c += 1;
                }
            }
        }
        m
    };
    let dets: Vec<f64> = (0..4).map(|k| minor(k).determinant()).collect();
    let scale: f64 = a.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max).max(1e-300);
    let (skip, &best) = dets.iter().enumerate().max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))?;
    if best.abs() < 1e-10 * scale.powi(3) {
        return None;
    }
    let sol = minor(skip).try_inverse()? * Vector3::new(b[0], b[1], b[2]);
    let mut s0 = Vector4::zeros();
    let mut c = 0;
    for k in 0..4 {
        if k != skip {
            s0[k] = sol[c];
            c += 1;
        }
    }
    // Null vector: n_k = (−1)^k det(minor without column k).
    let mut n = Vector4::zeros();
    for k in 0..4 {
        n[k] = if k % 2 == 0 { dets[k] } else { -dets[k] };
    }
    let norm = n.norm();
    if norm == 0.0 {
        return None;
    }
    Some((s0, n / norm))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plus_layout() -> (Vector3<f64>, Vec<Vector3<f64>>) {
        let tx = Vector3::new(0.4, 0.4, 0.0);
        let rx = vec![
            Vector3::new(0.0, 0.4, 0.0),
            Vector3::new(0.8, 0.4, 0.0),
            Vector3::new(0.4, 0.0, 0.0),
            Vector3::new(0.4, 0.8, 0.0),
        ];
        (tx, rx)
    }

    fn lengths(p: &Vector3<f64>, tx: &Vector3<f64>, rx: &[Vector3<f64>]) -> Vec<f64> {
        rx.iter().map(|r| bistatic_distance(p, tx, r).0).collect()
    }

    #[test]
    fn recovers_a_point_and_its_mirror_for_planar_antennas() {
        let (tx, rx) = plus_layout();
        for p in [Vector3::new(0.3, 0.9, 1.1), Vector3::new(-0.5, 1.7, 0.4), Vector3::new(1.2, -0.3, 2.5)] {
            for triple in [[0, 1, 2], [0, 2, 3], [1, 2, 3], [0, 1, 3]] {
                let r: Vec<_> = triple.iter().map(|&i| rx[i]).collect();
                let d = lengths(&p, &tx, &r);
                let pts = bistatic_intersections(&tx, &r, &d, None, 1e-6);
                assert!(pts.iter().any(|q| (q - p).norm() < 1e-7), "{p:?} not in {pts:?}");
                let mirror = Vector3::new(p.x, p.y, -p.z);
                assert!(pts.iter().any(|q| (q - mirror).norm() < 1e-7), "mirror of {p:?} not in {pts:?}");
            }
        }
    }

    #[test]
    fn recovers_a_point_for_non_planar_antennas() {
        let tx = Vector3::new(0.0, 0.0, 0.3);
        let rx = vec![Vector3::new(0.5, 0.0, 0.0), Vector3::new(0.0, 0.6, 0.1), Vector3::new(-0.4, 0.2, 0.5)];
        let p = Vector3::new(0.7, 1.3, 0.9);
        let pts = bistatic_intersections(&tx, &rx, &lengths(&p, &tx, &rx), None, 1e-6);
        assert!(pts.iter().any(|q| (q - p).norm() < 1e-7), "{pts:?}");
        for q in &pts {
            for (r, d) in rx.iter().zip(lengths(&p, &tx, &rx)) {
                assert!((bistatic_distance(q, &tx, r).0 - d).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn ellipses_in_a_plane() {
        let (tx, rx) = plus_layout();
        let p = Vector3::new(0.9, 1.4, 0.5);
        let r = vec![rx[0], rx[1]];
        let pts = bistatic_intersections(&tx, &r, &lengths(&p, &tx, &r), Some(0.5), 1e-6);
        assert!(pts.iter().any(|q| (q - p).norm() < 1e-7), "{pts:?}");
        assert!(pts.iter().all(|q| (q.z - 0.5).abs() < 1e-12));
    }

    #[test]
    fn degenerate_and_impossible_give_nothing() {
        let tx = Vector3::zeros();
        let collinear = vec![Vector3::new(0.2, 0.0, 0.0), Vector3::new(0.4, 0.0, 0.0), Vector3::new(0.6, 0.0, 0.0)];
        assert!(bistatic_intersections(&tx, &collinear, &[2.0, 2.0, 2.0], None, 1e-6).is_empty());
        let (tx, rx) = plus_layout();
        // Path lengths shorter than the baselines: no tag can produce them.
        assert!(bistatic_intersections(&tx, &rx[..3], &[0.1, 0.1, 0.1], None, 1e-6).is_empty());
        assert!(bistatic_intersections(&tx, &rx[..2], &[3.0, 3.0, 3.0], None, 1e-6).is_empty(), "wrong count");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let tx = Vector3::new(0.4, 0.4, 0.0);
        let rx = Vector3::new(0.0, 0.4, 0.0);
        let p = Vector3::new(0.3, 1.1, 0.8);
        let (_, g) = bistatic_distance(&p, &tx, &rx);
        let h = 1e-6;
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let fd = (bistatic_distance(&(p + e), &tx, &rx).0 - bistatic_distance(&(p - e), &tx, &rx).0) / (2.0 * h);
            assert!((fd - g[k]).abs() < 1e-8, "axis {k}: {fd} vs {}", g[k]);
        }
    }
}
