//! Phase → candidate distances, and GLAC's nearest-neighbour pick (eq. 9).

/// The candidate distance nearest to `predicted` (m) among
/// `residue + n · spacing`, n ∈ ℤ (GLAC eq. 9).
///
/// `residue` ∈ [0, spacing) comes from
/// [`Scene::distance_residue`](crate::scene::Scene::distance_residue) and
/// `spacing` is λ/2 (λ/4 for mod-π readers). Never negative: the smallest
/// candidate is `residue` itself.
#[inline]
pub fn nearest_candidate(residue: f64, spacing: f64, predicted: f64) -> f64 {
    let n = ((predicted - residue) / spacing).round().max(0.0);
    residue + n * spacing
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_the_nearest_and_is_within_half_a_spacing() {
        let s = 0.1637;
        for k in 0..500 {
            let residue = (k as f64 * 0.0137) % s;
            let predicted = 0.05 + k as f64 * 0.0041;
            let z = nearest_candidate(residue, s, predicted);
            assert!((z - predicted).abs() <= 0.5 * s + 1e-12);
            let n = (z - residue) / s;
            assert!((n - n.round()).abs() < 1e-9);
        }
        assert_eq!(nearest_candidate(0.02, 0.16, -1.0), 0.02);
    }
}
