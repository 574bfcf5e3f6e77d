//! The candidates' seeds on a grid over the box, refined.

use nalgebra::Vector3;

use super::coherence::Envelopes;
use super::refine::refine_on_envelopes;
use super::{refine, PhaseReads};

/// Gauss–Newton steps per seed on the envelope tables, then on the reads.
const ENVELOPE_ITERATIONS: usize = 8;
const REFINE_ITERATIONS: usize = 8;
/// A refined point this far outside the box (m) is dropped.
const MARGIN_M: f64 = 0.05;
/// Refined points closer than this (m) are one candidate.
const MERGE_M: f64 = 0.005;
/// Under known reflectors every lattice cell of the box gets a seed, and at
/// least this many times the usual number climb. The tables rank the grid
/// on the direct model, whose best peaks the reflectors' excess can
/// reorder; so many seeds climb on the full model (the direct refinement,
/// a few thousand range evaluations a seed), not on the tables.
const REFLECTED_SEED_FACTOR: usize = 20;
/// ... and at most this many seeds (a box of 20 000 lattice cells: 1.3 m
/// on a side at the mod-π lattice step of 8 cm).
const REFLECTED_MAX_SEEDS: usize = 20_000;

/// The candidates of one tag: positions with their coherence, best first.
///
/// The grid steps a quarter of the lattice step 2π/k̄ (coarser, by 1.25×
/// at a time, until it has at most `max_points` points); the seeds are the
/// best points at least half a lattice step apart that reach half the best
/// coherence, at most `max_seeds` of them. Each seed climbs on the
/// envelope tables first ([`refine_on_envelopes`]); only the seeds that
/// `polish(best R, its R)` keeps (R from the tables, within 10⁻⁴ of the
/// reads' own) are refined on the reads: most seeds end on lattice points
/// far less coherent than the best, whose weight would be nil.
pub fn search(
    reads: &PhaseReads,
    low: Vector3<f64>,
    high: Vector3<f64>,
    axes: usize,
    max_points: usize,
    max_seeds: usize,
    polish: &dyn Fn(f64, f64) -> bool,
) -> Vec<(Vector3<f64>, f64)> {
    let mean_k = (0..reads.z.len()).map(|i| reads.count(i) * reads.k[i].abs()).sum::<f64>() / reads.total().max(1.0);
    if mean_k <= 0.0 {
        return Vec::new();
    }
    let spacing = 2.0 * std::f64::consts::PI / mean_k;
    let sizes = |step: f64| -> [usize; 3] { std::array::from_fn(|a| if high[a] > low[a] { ((high[a] - low[a]) / step).floor() as usize + 1 } else { 1 }) };
    let mut step = spacing / 4.0;
    while sizes(step).iter().product::<usize>() > max_points {
        step *= 1.25;
    }
    let size = sizes(step);
    // The grid is ranked on the direct model's envelope tables, also under
    // known reflectors: their excess moves the peaks by millimetres, every
    // lattice cell of the box gets a seed there, and the seeds then climb
    // on the full model.
    let reflected = reads.has_reflectors();
    let envelopes = Envelopes::new(reads, &low, &high);
    let max_seeds = if !reflected {
        max_seeds
    } else {
        let cells: f64 = (0..3).map(|a| if high[a] > low[a] { (high[a] - low[a]) / spacing + 1.0 } else { 1.0 }).product();
        (max_seeds * REFLECTED_SEED_FACTOR).max(cells.ceil().min(REFLECTED_MAX_SEEDS as f64) as usize)
    };
    let mut points = Vec::with_capacity(size.iter().product());
    for ix in 0..size[0] {
        for iy in 0..size[1] {
            for iz in 0..size[2] {
                let p = low + Vector3::new(ix as f64, iy as f64, iz as f64) * step;
                points.push((p, envelopes.coherence(&p)));
            }
        }
    }
    points.sort_by(|a, b| b.1.total_cmp(&a.1));
    let floor = points.first().map_or(0.0, |p| 0.5 * p.1);
    let mut seeds: Vec<Vector3<f64>> = Vec::new();
    for (p, value) in points.iter().take(50 * max_seeds.max(1)) {
        if seeds.len() >= max_seeds || *value < floor {
            break;
        }
        if seeds.iter().all(|s| (s - p).norm() > 0.5 * spacing) {
            seeds.push(*p);
        }
    }
    let mut climbed: Vec<(Vector3<f64>, f64)> = seeds
        .into_iter()
        .map(|seed| {
            if reflected {
                refine(reads, seed, axes, ENVELOPE_ITERATIONS)
            } else {
                let p = refine_on_envelopes(&envelopes, seed, axes, ENVELOPE_ITERATIONS);
                (p, envelopes.coherence(&p))
            }
        })
        .collect();
    climbed.sort_by(|a, b| b.1.total_cmp(&a.1));
    // Seeds that climbed to one maximum are refined once.
    let mut distinct: Vec<(Vector3<f64>, f64)> = Vec::with_capacity(climbed.len());
    for (p, r) in climbed {
        if distinct.iter().all(|(q, _)| (q - p).norm() > MERGE_M) {
            distinct.push((p, r));
        }
    }
    let climbed = distinct;
    let best = climbed.first().map_or(0.0, |c| c.1);
    let mut refined: Vec<(Vector3<f64>, f64)> = Vec::new();
    for (start, _) in climbed.into_iter().filter(|(_, r)| polish(best, *r)) {
        let (p, r) = refine(reads, start, axes, REFINE_ITERATIONS);
        let inside = (0..3).all(|a| p[a] >= low[a] - MARGIN_M && p[a] <= high[a] + MARGIN_M);
        if inside && p.iter().all(|v| v.is_finite()) && refined.iter().all(|(q, _)| (q - p).norm() > MERGE_M) {
            refined.push((p, r));
        }
    }
    refined.sort_by(|a, b| b.1.total_cmp(&a.1));
    refined
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    #[test]
    fn search_finds_the_truth_first() {
        let anchors = layout();
        let truth = Vector3::new(0.5, 0.6, 0.7);
        let (z, k, antenna) = reads_at(truth, &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let found = search(&reads, truth - Vector3::repeat(0.1), truth + Vector3::repeat(0.1), 3, 100_000, 20, &|_, _| true);
        assert!((found[0].0 - truth).norm() < 1e-5, "{:?}", found[0]);
        assert!(found.windows(2).all(|w| w[0].1 >= w[1].1));
    }

    #[test]
    fn an_empty_box_searches_its_low_corner_without_panicking() {
        let anchors = layout();
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors);
        let found = search(&reads, Vector3::repeat(0.8), Vector3::repeat(0.7), 3, 100_000, 20, &|_, _| true);
        assert!(found.len() <= 1);
    }
}
