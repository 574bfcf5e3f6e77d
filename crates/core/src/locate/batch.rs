//! Many tags' candidates on every core, results in tag order.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use nalgebra::{Complex, Vector3};

use super::{phase_candidates, Candidate, Paths, PhaseReads, Settings};

/// Every tag's reads, concatenated: tag t owns rows `bounds[t]..bounds[t + 1]`.
pub struct TagBatch<'a> {
    pub z: &'a [Complex<f64>],
    pub k: &'a [f64],
    pub time_s: &'a [f64],
    /// Index into `anchors`.
    pub antenna: &'a [usize],
    pub anchors: &'a [Vector3<f64>],
    pub bounds: &'a [usize],
    /// Each tag's search box, m.
    pub low: &'a [Vector3<f64>],
    pub high: &'a [Vector3<f64>],
    /// Known reflectors (`None`: the direct path alone).
    pub paths: Option<Paths<'a>>,
}

/// [`phase_candidates`] for every tag of `batch`, on `threads` threads
/// (at least one); tag t's candidates at index t, whatever the thread
/// schedule (tags are claimed one at a time from a shared counter, so a
/// slow tag does not hold up a whole share).
pub fn locate_batch(batch: &TagBatch, axes: usize, settings: &Settings, threads: usize) -> Vec<Vec<Candidate>> {
    let tags = batch.bounds.len().saturating_sub(1);
    let results: Vec<Mutex<Vec<Candidate>>> = (0..tags).map(|_| Mutex::new(Vec::new())).collect();
    let next = AtomicUsize::new(0);
    let work = || loop {
        let t = next.fetch_add(1, Ordering::Relaxed);
        if t >= tags {
            break;
        }
        let rows = batch.bounds[t]..batch.bounds[t + 1];
        let mut reads = PhaseReads::new(&batch.z[rows.clone()], &batch.k[rows.clone()], &batch.antenna[rows.clone()], batch.anchors);
        if let Some(paths) = batch.paths {
            reads = reads.with_paths(paths);
        }
        let found = phase_candidates(&reads, &batch.time_s[rows], batch.low[t], batch.high[t], axes, settings);
        *results[t].lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = found;
    };
    let threads = threads.clamp(1, tags.max(1));
    if threads == 1 {
        work();
    } else {
        std::thread::scope(|scope| {
            for _ in 0..threads {
                scope.spawn(work);
            }
        });
    }
    results.into_iter().map(|r| r.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner())).collect()
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{layout, reads_at, us_band};
    use super::*;

    #[test]
    fn threads_do_not_change_the_results_or_their_order() {
        let anchors = layout();
        let truths = [Vector3::new(0.5, 0.6, 0.7), Vector3::new(0.2, 0.9, 0.4), Vector3::new(0.8, 0.3, 0.9)];
        let (mut z, mut k, mut antenna, mut bounds) = (Vec::new(), Vec::new(), Vec::new(), vec![0]);
        for truth in truths {
            let (zt, kt, at) = reads_at(truth, &anchors, &us_band());
            z.extend(zt);
            k.extend(kt);
            antenna.extend(at);
            bounds.push(z.len());
        }
        let time: Vec<f64> = (0..z.len()).map(|i| (i % 200) as f64 * 0.03).collect();
        let (low, high) = (vec![Vector3::zeros(); 3], vec![Vector3::repeat(1.5); 3]);
        let batch = TagBatch { z: &z, k: &k, time_s: &time, antenna: &antenna, anchors: &anchors, bounds: &bounds, low: &low, high: &high, paths: None };
        let settings = Settings { temperature: 1.0, bias_sigma_rad: 0.07, correlation_s: 0.5, max_candidates: 5, min_weight: 1e-3, hopping_spread_hz: 2e6, max_points: 100_000 };
        let one = locate_batch(&batch, 3, &settings, 1);
        let two = locate_batch(&batch, 3, &settings, 2);
        for (t, truth) in truths.iter().enumerate() {
            assert!((one[t][0].position - truth).norm() < 1e-5);
            assert_eq!(one[t].len(), two[t].len());
            assert_eq!(one[t][0].position, two[t][0].position);
        }
    }
}
