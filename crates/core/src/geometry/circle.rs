use nalgebra::Vector2;

/// The (up to two) points where circles |p − c₁| = r₁ and |p − c₂| = r₂
/// meet in a plane (m).
///
/// When noise makes the circles just miss each other (gap below
/// `tolerance`), the single closest point on the centre line is returned
/// twice, so that a few millimetres of range noise do not drop the true
/// candidate; otherwise `None`.
pub fn circle_intersections(
    c1: &Vector2<f64>,
    r1: f64,
    c2: &Vector2<f64>,
    r2: f64,
    tolerance: f64,
) -> Option<[Vector2<f64>; 2]> {
    let delta = c2 - c1;
    let d = delta.norm();
    if d < 1e-9 {
        return None;
    }
    let u = delta / d;
    // Too far apart or one inside the other: allow a near miss.
    if d > r1 + r2 + tolerance || d < (r1 - r2).abs() - tolerance {
        return None;
    }
    let a = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d);
    let h2 = r1 * r1 - a * a;
    let h = if h2 > 0.0 { h2.sqrt() } else { 0.0 };
    let base = c1 + u * a;
    let normal = Vector2::new(-u.y, u.x);
    Some([base + normal * h, base - normal * h])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intersects_and_tolerates_near_miss() {
        let c1 = Vector2::new(0.0, 0.0);
        let c2 = Vector2::new(0.0, 0.8);
        let p = Vector2::new(0.6, 0.3);
        let [a, b] = circle_intersections(&c1, p.norm(), &c2, (p - c2).norm(), 1e-3).unwrap();
        assert!((a - p).norm().min((b - p).norm()) < 1e-9);
        assert!(circle_intersections(&c1, 0.3, &c2, 0.3, 0.0).is_none());
        assert!(circle_intersections(&c1, 0.3995, &c2, 0.3995, 0.005).is_some());
    }
}
