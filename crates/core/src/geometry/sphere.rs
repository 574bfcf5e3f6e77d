use nalgebra::Vector3;

/// Points on all three spheres |p − cᵢ| = rᵢ (m).
///
/// Classic trilateration: build an orthonormal frame with e_x towards c₂
/// and c₃ in the e_x–e_y plane, solve for x and y in closed form, then
/// z = ±√(r₁² − x² − y²). Returns the two mirror points about the plane of
/// the centres. When noise makes the spheres just miss each other
/// (z² < 0 but above −`tolerance`² · r₁), z is clamped to 0 and the single
/// point is returned twice, because a range noise of a few millimetres must
/// not drop the true candidate. Collinear centres return `None`: there the
/// solution is a circle, not two points.
pub fn sphere_intersections(
    c1: &Vector3<f64>,
    r1: f64,
    c2: &Vector3<f64>,
    r2: f64,
    c3: &Vector3<f64>,
    r3: f64,
    tolerance: f64,
) -> Option<[Vector3<f64>; 2]> {
    let d_vec = c2 - c1;
    let d = d_vec.norm();
    if d < 1e-9 {
        return None;
    }
    let ex = d_vec / d;
    let t = c3 - c1;
    let i = ex.dot(&t);
    let ey_raw = t - ex * i;
    let ey_norm = ey_raw.norm();
    if ey_norm < 1e-6 * d.max(1.0) {
        return None;
    }
    let ey = ey_raw / ey_norm;
    let ez = ex.cross(&ey);
    let j = ey.dot(&t);
    let x = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d);
    let y = (r1 * r1 - r3 * r3 + i * i + j * j) / (2.0 * j) - (i / j) * x;
    let z2 = r1 * r1 - x * x - y * y;
    let z = if z2 >= 0.0 {
        z2.sqrt()
    } else if z2 > -2.0 * tolerance * r1.max(tolerance) {
        0.0
    } else {
        return None;
    };
    let base = c1 + ex * x + ey * y;
    Some([base + ez * z, base - ez * z])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_point_and_its_mirror() {
        let c = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.8, 0.0), Vector3::new(0.8, 0.8, 0.0)];
        let p = Vector3::new(0.36, 0.5, 0.71);
        let r: Vec<f64> = c.iter().map(|ci| (p - ci).norm()).collect();
        let [a, b] = sphere_intersections(&c[0], r[0], &c[1], r[1], &c[2], r[2], 1e-3).unwrap();
        let hit = (a - p).norm().min((b - p).norm());
        assert!(hit < 1e-9);
        let mirror = Vector3::new(p.x, p.y, -p.z);
        assert!((a - mirror).norm().min((b - mirror).norm()) < 1e-9);
    }

    #[test]
    fn collinear_centres_have_no_point_pair() {
        let c = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.3, 0.0), Vector3::new(0.0, 0.8, 0.0)];
        assert!(sphere_intersections(&c[0], 1.0, &c[1], 1.0, &c[2], 1.0, 1e-3).is_none());
    }
}
