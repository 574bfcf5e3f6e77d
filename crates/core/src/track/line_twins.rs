//! Twins of a tag position when three (or more) antennas lie on one line
//! and exactly one antenna is off it (the GLAC paper's layout): the
//! positions that fit every phase of one channel exactly.
//!
//! Antennas on a line through `a` with unit direction `u` measure
//! `dᵢ² = ρ² + (t − tᵢ)²` with t = (p − a)·u the position along the line
//! and ρ the distance from it: they fix t and ρ and nothing of the angle θ
//! around the line. The off-line antenna b measures
//! `d_b(θ)² = |c − b|² + ρ² + 2ρ (c − b)·(cos θ e₁ + sin θ e₂)`, with
//! c = a + t u and (e₁, e₂) a basis normal to u, i.e.
//! `d_b² = C + 2ρR cos(θ − φ)`. A twin shifts d_b by k·s (s the candidate
//! spacing, λ/2 or λ/4): `cos(θ − φ) = ((d_b + k s)² − C) / (2ρR)`, two
//! angles per k when the right side lies in [−1, 1]. Closed form, a few
//! hundred nanoseconds per position (docs/glac.md derives it).

use nalgebra::Vector3;

/// A line of antennas and the one antenna off it.
#[derive(Debug, Clone, PartialEq)]
pub struct LineLayout {
    /// A point on the line, m.
    pub origin: Vector3<f64>,
    /// Unit direction of the line.
    pub direction: Vector3<f64>,
    /// Position of the antenna off the line, m.
    pub free: Vector3<f64>,
}

/// Antennas within this distance of a line through two others count as on
/// it, metres (the geometry check's tolerance for "collinear").
pub const ON_LINE_M: f64 = 0.01;

/// The layout if at least three of `antennas` (m) lie on one line and
/// exactly one does not; `None` otherwise (then no integer is free).
pub fn line_layout(antennas: &[Vector3<f64>]) -> Option<LineLayout> {
    let n = antennas.len();
    for i in 0..n {
        for j in i + 1..n {
            let axis = antennas[j] - antennas[i];
            let length = axis.norm();
            if length < ON_LINE_M {
                continue;
            }
            let u = axis / length;
            let off: Vec<usize> = (0..n)
                .filter(|&k| {
                    let v = antennas[k] - antennas[i];
                    (v - u * v.dot(&u)).norm() > ON_LINE_M
                })
                .collect();
            if n - off.len() >= 3 && off.len() == 1 {
                return Some(LineLayout { origin: antennas[i], direction: u, free: antennas[off[0]] });
            }
        }
    }
    None
}

/// Every twin of `p` (m) with the off-line antenna's range shifted by k·`spacing`
/// for 1 ≤ |k| ≤ `max_shift`, for which `keep` holds (e.g. inside the region).
pub fn line_twins(layout: &LineLayout, p: &Vector3<f64>, spacing: f64, max_shift: i32, keep: impl Fn(&Vector3<f64>) -> bool) -> Vec<Vector3<f64>> {
    let u = layout.direction;
    let t = (p - layout.origin).dot(&u);
    let c = layout.origin + u * t;
    let radial = p - c;
    let rho = radial.norm();
    if rho < 1e-6 {
        return Vec::new(); // on the line: the angle is moot
    }
    // A basis normal to u, e₁ along the tag's own radial direction.
    let e1 = radial / rho;
    let e2 = u.cross(&e1);
    let w = c - layout.free;
    let (a, b) = (w.dot(&e1), w.dot(&e2));
    let r = (a * a + b * b).sqrt();
    if r < 1e-9 {
        return Vec::new(); // the free antenna is on the line's axis of symmetry
    }
    let big_c = w.norm_squared() + rho * rho;
    let phi = b.atan2(a);
    let d = (p - layout.free).norm();
    let mut twins = Vec::new();
    for k in (-max_shift..=max_shift).filter(|&k| k != 0) {
        let target = d + k as f64 * spacing;
        if target <= 0.0 {
            continue;
        }
        let cosine = (target * target - big_c) / (2.0 * rho * r);
        if cosine.abs() > 1.0 {
            continue;
        }
        let delta = cosine.acos();
        for theta in [phi + delta, phi - delta] {
            let q = c + (e1 * theta.cos() + e2 * theta.sin()) * rho;
            if keep(&q) {
                twins.push(q);
            }
        }
    }
    twins
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> Vec<Vector3<f64>> {
        [[0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.8, 0.0], [0.8, 0.8, 0.0]].iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect()
    }

    #[test]
    fn finds_the_paper_layout_and_not_a_general_one() {
        let layout = line_layout(&paper()).unwrap();
        assert!((layout.direction.y.abs() - 1.0).abs() < 1e-12);
        assert_eq!(layout.free, Vector3::new(0.8, 0.8, 0.0));
        let mut moved = paper();
        moved[1] = Vector3::new(0.3, 0.0, 0.0); // glac-3d-arm's layout
        assert_eq!(line_layout(&moved), None);
    }

    /// Every twin keeps the ranges to the line's antennas and shifts the
    /// free antenna's by a whole number of spacings.
    #[test]
    fn twins_fit_every_range_up_to_whole_spacings() {
        let antennas = paper();
        let layout = line_layout(&antennas).unwrap();
        let p = Vector3::new(0.45, 0.35, 0.7);
        let s = 0.1637;
        let twins = line_twins(&layout, &p, s, 3, |q| q.z > 0.05);
        assert!(twins.len() >= 4, "{twins:?}");
        for q in &twins {
            for a in &antennas[..3] {
                assert!(((q - a).norm() - (p - a).norm()).abs() < 1e-9);
            }
            let shift = ((q - antennas[3]).norm() - (p - antennas[3]).norm()) / s;
            assert!((shift - shift.round()).abs() < 1e-9 && shift.round() != 0.0, "{shift}");
            assert!(q.z > 0.05);
        }
    }
}
