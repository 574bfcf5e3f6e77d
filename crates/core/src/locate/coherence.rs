//! R(p) = |Σ_k z_k e^{−j k_k d_k(p)}| / n, directly and through per-antenna
//! envelope tables for the grid.
//!
//! Why tables: a grid point costs one sine/cosine per read directly, and a
//! grid holds up to 10⁵ points. Splitting k_k = k̄ + δ_k, one antenna's sum
//! is e^{−j k̄ d} E_a(d) with the envelope E_a(d) = Σ_{k∈a} z_k e^{−j δ_k d},
//! a function of the range d alone that turns slowly (|δ_k| ≤ half the
//! band's spread in k, about 0.26 rad/m in the US band, against k̄ ≈ 38
//! rad/m). Tabulated once per antenna over the box's ranges and linearly
//! interpolated, a grid point costs one sine/cosine per *antenna*.

use nalgebra::{Complex, Vector3};

use super::{rotation, PhaseReads};

/// R(p) (see the module docs).
pub fn coherence(reads: &PhaseReads, p: &Vector3<f64>) -> f64 {
    let mut sum = Complex::new(0.0, 0.0);
    for i in 0..reads.z.len() {
        sum += reads.z[i] * rotation(reads.k[i] * reads.distance(i, p));
    }
    sum.norm() / reads.total().max(1.0)
}

/// Largest envelope phase change between table samples, rad: linear
/// interpolation's error is then ≤ 0.02²/8 ≈ 5·10⁻⁵ of the envelope.
const MAX_PHASE_STEP_RAD: f64 = 0.02;
/// Finest table spacing, m (bounds the table of a very wide band).
const MIN_SPACING_M: f64 = 1e-4;

/// Ranges this far beyond the box (m) are tabled too: refinement may step
/// out of the box before it is judged.
const RANGE_MARGIN_M: f64 = 0.1;

/// One antenna's envelope E_a(d) sampled at d₀ + i h.
pub(super) struct Table {
    pub(super) anchor: Vector3<f64>,
    start_m: f64,
    spacing_m: f64,
    values: Vec<Complex<f64>>,
}

impl Table {
    fn at(&self, d: f64) -> Complex<f64> {
        self.at_with_slope(d).0
    }

    /// E_a(d) and dE_a/dd (the interpolating segment's slope).
    pub(super) fn at_with_slope(&self, d: f64) -> (Complex<f64>, Complex<f64>) {
        if self.values.len() == 1 {
            return (self.values[0], Complex::new(0.0, 0.0));
        }
        let x = ((d - self.start_m) / self.spacing_m).clamp(0.0, (self.values.len() - 1) as f64);
        let i = (x.floor() as usize).min(self.values.len() - 2);
        let t = x - i as f64;
        let (a, b) = (self.values[i], self.values[i + 1]);
        (a * (1.0 - t) + b * t, (b - a) / self.spacing_m)
    }
}

/// R over a box from per-antenna envelope tables (module docs).
pub struct Envelopes {
    pub(super) mean_k: f64,
    pub(super) tables: Vec<Table>,
    n: f64,
}

impl Envelopes {
    /// Tables covering every range from the antennas to the box [low, high].
    pub fn new(reads: &PhaseReads, low: &Vector3<f64>, high: &Vector3<f64>) -> Self {
        let n = reads.z.len();
        let mean_k = (0..n).map(|i| reads.count(i) * reads.k[i]).sum::<f64>() / reads.total().max(1.0);
        let mut tables = Vec::new();
        for a in reads.used_anchors() {
            let anchor = reads.anchors[a];
            let rows: Vec<usize> = (0..n).filter(|&i| reads.antenna[i] == a).collect();
            // (max then min, not clamp: an empty box, low > high, is legal and searches low.)
            let nearest = Vector3::from_fn(|axis, _| anchor[axis].max(low[axis]).min(high[axis].max(low[axis])));
            let start = ((nearest - anchor).norm() - RANGE_MARGIN_M).max(0.0);
            let end = (0..8)
                .map(|corner| Vector3::from_fn(|axis, _| if corner >> axis & 1 == 1 { high[axis] } else { low[axis] }))
                .map(|q| (q - anchor).norm())
                .fold(start, f64::max)
                + RANGE_MARGIN_M;
            let widest = rows.iter().map(|&i| (reads.k[i] - mean_k).abs()).fold(0.0, f64::max);
            // An envelope that turns by less than a micro-radian over the box is constant.
            let turns = widest * (end - start) > 1e-6;
            let spacing = if turns { (MAX_PHASE_STEP_RAD / widest).max(MIN_SPACING_M) } else { 1.0 };
            let samples = if turns { ((end - start) / spacing).ceil() as usize + 2 } else { 1 };
            let values = (0..samples)
                .map(|s| {
                    let d = start + s as f64 * spacing;
                    rows.iter().map(|&i| reads.z[i] * rotation((reads.k[i] - mean_k) * d)).sum()
                })
                .collect();
            tables.push(Table { anchor, start_m: start, spacing_m: spacing, values });
        }
        Envelopes { mean_k, tables, n: reads.total().max(1.0) }
    }

    /// R(p), p inside the box the tables were built for.
    pub fn coherence(&self, p: &Vector3<f64>) -> f64 {
        let mut sum = Complex::new(0.0, 0.0);
        for table in &self.tables {
            let d = (p - table.anchor).norm();
            sum += table.at(d) * rotation(self.mean_k * d);
        }
        sum.norm() / self.n
    }
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    #[test]
    fn tables_agree_with_the_direct_sum() {
        let anchors = layout();
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let (low, high) = (Vector3::new(0.2, 0.3, 0.4), Vector3::new(0.9, 1.0, 1.1));
        let envelopes = Envelopes::new(&reads, &low, &high);
        for i in 0..200 {
            let t = i as f64 / 200.0;
            let p = low + (high - low).component_mul(&Vector3::new(t, (7.0 * t).fract(), (13.0 * t).fract()));
            let (direct, tabled) = (coherence(&reads, &p), envelopes.coherence(&p));
            assert!((direct - tabled).abs() < 1e-4, "{p:?}: {direct} vs {tabled}");
        }
    }

    #[test]
    fn one_channel_needs_one_sample_per_antenna() {
        let anchors = layout();
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &[915e6]);
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let envelopes = Envelopes::new(&reads, &Vector3::zeros(), &Vector3::repeat(1.0));
        assert!(envelopes.tables.iter().all(|t| t.values.len() == 1));
        let p = Vector3::new(0.3, 0.2, 0.9);
        assert!((coherence(&reads, &p) - envelopes.coherence(&p)).abs() < 1e-12, "{} {}", coherence(&reads, &p), envelopes.coherence(&p));
    }
}
