//! Many tags at once: one tracker per tag, a reorder window for live
//! streams whose reads arrive slightly out of order, and per-step latency.
//!
//! Contract: [`Engine::step`] takes one measurement of tag `tag` (a dense
//! index the caller assigns, e.g. per EPC) and returns that tag's estimate.
//! Trackers are created on first sight of a tag, so tags can appear at any
//! time; each is tracked on its own.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::time::Instant;

use crate::error::Result;
use crate::scene::Scene;
use crate::track::{make, Estimate, Measurement, Params, Tracker, TrackerStats};

/// Wall-clock cost of `step` calls, nanoseconds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Latency {
    pub count: u64,
    pub total_ns: u64,
    pub max_ns: u64,
    /// Every step's cost (the first `MAX_LATENCY_SAMPLES`), for percentiles.
    pub samples_ns: Vec<u32>,
}

/// Step costs kept for percentiles (4 bytes each: 40 MB at most).
pub const MAX_LATENCY_SAMPLES: usize = 10_000_000;

impl Latency {
    /// Records one step's cost.
    pub fn record(&mut self, ns: u64) {
        self.count += 1;
        self.total_ns += ns;
        self.max_ns = self.max_ns.max(ns);
        if self.samples_ns.len() < MAX_LATENCY_SAMPLES {
            self.samples_ns.push(ns.min(u32::MAX as u64) as u32);
        }
    }

    /// The `q`-quantile (0–1) of the recorded step costs, ns (nearest rank); 0 when empty.
    pub fn percentile_ns(&self, q: f64) -> f64 {
        if self.samples_ns.is_empty() {
            return 0.0;
        }
        let mut sorted = self.samples_ns.clone();
        sorted.sort_unstable();
        let rank = ((q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
        sorted[rank - 1] as f64
    }

    pub fn mean_ns(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.total_ns as f64 / self.count as f64
        }
    }
}

/// Per-tag trackers of one method over one scene.
pub struct Engine {
    scene: Scene,
    method: String,
    params: Params,
    /// A tracker in its initial state: new tags' trackers are its
    /// [`Tracker::fresh`] copies (sharing its scene and parameters).
    prototype: Box<dyn Tracker>,
    trackers: Vec<Option<Box<dyn Tracker>>>,
    latency: Latency,
    /// [`Engine::run_batch`]'s working arrays, kept between batches: a
    /// batch's estimates are ~12 MB at 35,000 reads, and allocated afresh
    /// they were grown by doubling and faulted in page by page every batch
    /// (docs/notes/glac-many-tags-cost.md, "Page faults").
    batch: BatchScratch,
}

/// Batches up to this many reads keep their working arrays for the next
/// one (≈ 0.1 GB of estimates at most); a larger batch (a whole recording
/// run at once) frees them.
const KEPT_BATCH_READS: usize = 1 << 18;

/// Working arrays of one batch (emptied, not freed, between batches).
#[derive(Default)]
struct BatchScratch {
    /// Read indices grouped by tag (see [`grouped_by_tag`]).
    order: Vec<u32>,
    /// Per tag, where its reads start in `order` (counting sort).
    counts: Vec<u32>,
    /// Where each tag's reads start in `order`.
    starts: Vec<usize>,
    /// Where each read's estimate lies in `estimates` (u32::MAX: none).
    slot: Vec<u32>,
    estimates: Vec<Estimate>,
}

impl BatchScratch {
    fn release_if_larger_than(&mut self, reads: usize) {
        if self.slot.capacity() > reads {
            *self = Self::default();
        }
    }
}

impl Engine {
    /// Fails on an unknown method or invalid parameters (checked by
    /// building one tracker up front).
    pub fn new(scene: Scene, method: &str, params: Params) -> Result<Self> {
        let prototype = make(method, &scene, &params)?;
        Ok(Self {
            scene,
            method: method.to_string(),
            params,
            prototype,
            trackers: Vec::new(),
            latency: Latency::default(),
            batch: BatchScratch::default(),
        })
    }

    /// One measurement of tag `tag`.
    pub fn step(&mut self, tag: usize, measurement: &Measurement) -> Option<Estimate> {
        if tag >= self.trackers.len() {
            self.trackers.resize_with(tag + 1, || None);
        }
        if self.trackers[tag].is_none() {
            // The method and parameters were validated in `new`.
            self.trackers[tag] = self.prototype.fresh().or_else(|| make(&self.method, &self.scene, &self.params).ok());
        }
        let tracker = self.trackers[tag].as_mut()?;
        let start = Instant::now();
        let estimate = tracker.step(measurement);
        self.latency.record(start.elapsed().as_nanos() as u64);
        estimate
    }

    /// A batch: measurement `measurements[i]` of tag `tags[i]` for every
    /// `i`, and `emit(i, estimate)` for each estimate, in increasing `i`.
    ///
    /// Each tag's measurements go through its tracker in their order, so
    /// the estimates are exactly those of [`Engine::step`] over the batch
    /// in input order; but they are taken tag by tag (a stable grouping):
    /// with thousands of tags a tag's state is out of cache by its next
    /// read in time order, and grouped it is fetched once per batch
    /// instead of once per read. Causal per tag, as every tracker is.
    pub fn run_batch(&mut self, tags: &[usize], measurements: &[Measurement], mut emit: impl FnMut(usize, &Estimate)) {
        assert_eq!(tags.len(), measurements.len(), "one tag per measurement");
        let mut b = std::mem::take(&mut self.batch);
        grouped_by_tag(tags, &mut b.order, &mut b.counts);
        let order = &b.order;
        let tag_at = |j: usize| tags[order[j] as usize];
        b.starts.clear();
        b.starts.extend((0..order.len()).filter(|&j| j == 0 || tag_at(j) != tag_at(j - 1)));
        b.slot.clear();
        b.slot.resize(tags.len(), u32::MAX);
        b.estimates.clear();
        for (g, &start) in b.starts.iter().enumerate() {
            // While this tag is stepped, the next two load: the tracker
            // after next its own lines (no read of it needed), the next
            // one what they point to (they arrived during the last tag).
            if let Some(Some(later)) = b.starts.get(g + 2).and_then(|&j| self.trackers.get(tag_at(j))) {
                crate::prefetch::bytes((&**later as *const dyn Tracker).cast(), 4 * crate::prefetch::LINE_BYTES);
            }
            if let Some(Some(next)) = b.starts.get(g + 1).and_then(|&j| self.trackers.get(tag_at(j))) {
                next.prefetch();
            }
            let end = b.starts.get(g + 1).copied().unwrap_or(order.len());
            for &i in &order[start..end] {
                let i = i as usize;
                if let Some(e) = self.step(tags[i], &measurements[i]) {
                    b.slot[i] = b.estimates.len() as u32;
                    b.estimates.push(e);
                }
            }
        }
        for (i, &k) in b.slot.iter().enumerate() {
            if k != u32::MAX {
                emit(i, &b.estimates[k as usize]);
            }
        }
        b.release_if_larger_than(KEPT_BATCH_READS);
        self.batch = b;
    }

    /// Counters of tag `tag` (zero if never seen).
    pub fn stats(&self, tag: usize) -> TrackerStats {
        self.trackers.get(tag).and_then(|t| t.as_ref()).map_or_else(TrackerStats::default, |t| t.stats())
    }

    /// Live hypotheses of tag `tag` (position m, normalised log-likelihood).
    pub fn hypotheses(&self, tag: usize) -> Vec<([f64; 3], f64)> {
        self.trackers.get(tag).and_then(|t| t.as_ref()).map_or_else(Vec::new, |t| t.hypotheses())
    }

    /// Smoothed trajectory of tag `tag` (methods that revise the past).
    pub fn trajectory(&self, tag: usize) -> Vec<(f64, [f64; 3])> {
        self.trackers.get(tag).and_then(|t| t.as_ref()).map_or_else(Vec::new, |t| t.trajectory())
    }

    pub fn latency(&self) -> &Latency {
        &self.latency
    }

    pub fn tags(&self) -> usize {
        self.trackers.len()
    }
}

/// Fills `order` with the indices `0..tags.len()` ordered by tag, each
/// tag's in increasing order (a stable counting sort when the tag indices
/// are dense enough, `start` its per-tag counters; else a stable sort).
fn grouped_by_tag(tags: &[usize], order: &mut Vec<u32>, start: &mut Vec<u32>) {
    let n = tags.len();
    assert!(n < u32::MAX as usize, "batches hold fewer than 2³² reads");
    let top = tags.iter().copied().max().map_or(0, |t| t + 1);
    order.clear();
    if top > 4 * n + 1024 {
        order.extend(0..n as u32);
        order.sort_by_key(|&i| tags[i as usize]);
        return;
    }
    start.clear();
    start.resize(top + 1, 0);
    for &t in tags {
        start[t + 1] += 1;
    }
    for t in 0..top {
        start[t + 1] += start[t];
    }
    order.resize(n, 0);
    for (i, &t) in tags.iter().enumerate() {
        order[start[t] as usize] = i as u32;
        start[t] += 1;
    }
}

/// A measurement waiting in the reorder window.
#[derive(Debug, Clone)]
struct Pending {
    tag: usize,
    sequence: u64,
    measurement: Measurement,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    /// Min-heap on (time, arrival order): reversed for `BinaryHeap`.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .measurement
            .time_s()
            .total_cmp(&self.measurement.time_s())
            .then_with(|| other.sequence.cmp(&self.sequence))
    }
}

/// Holds live measurements for `window_s` seconds (of reader time) and
/// releases them in time order, so reads that arrive slightly late are
/// sorted rather than dropped. Ties keep arrival order.
#[derive(Debug, Default)]
pub struct ReorderWindow {
    window_s: f64,
    heap: BinaryHeap<Pending>,
    newest_s: f64,
    sequence: u64,
    released_s: f64,
    /// Measurements older than one already released (too late to sort).
    pub late: u64,
}

impl ReorderWindow {
    pub fn new(window_s: f64) -> Self {
        Self { window_s, newest_s: f64::NEG_INFINITY, released_s: f64::NEG_INFINITY, ..Default::default() }
    }

    /// Adds a measurement; returns those now older than the window.
    pub fn push(&mut self, tag: usize, measurement: Measurement) -> Vec<(usize, Measurement)> {
        if measurement.time_s() < self.released_s {
            self.late += 1;
        }
        self.newest_s = self.newest_s.max(measurement.time_s());
        self.heap.push(Pending { tag, sequence: self.sequence, measurement });
        self.sequence += 1;
        self.release(self.newest_s - self.window_s)
    }

    /// Releases everything (end of stream).
    pub fn flush(&mut self) -> Vec<(usize, Measurement)> {
        self.release(f64::INFINITY)
    }

    fn release(&mut self, until_s: f64) -> Vec<(usize, Measurement)> {
        let mut out = Vec::new();
        while self.heap.peek().is_some_and(|p| p.measurement.time_s() <= until_s) {
            let p = self.heap.pop().unwrap();
            self.released_s = self.released_s.max(p.measurement.time_s());
            out.push((p.tag, p.measurement));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(t: f64) -> Measurement {
        Measurement::Phase(crate::track::PhaseRead { time_s: t, antenna: 0, frequency_hz: 915e6, phase_rad: 0.0 })
    }

    fn grouped(tags: &[usize]) -> Vec<u32> {
        let (mut order, mut start) = (vec![7; 9], vec![5; 2]); // stale contents are overwritten
        grouped_by_tag(tags, &mut order, &mut start);
        order
    }

    #[test]
    fn grouping_is_stable_within_each_tag() {
        let tags = [3, 0, 3, 1, 0, 3];
        assert_eq!(grouped(&tags), vec![1, 4, 3, 0, 2, 5]);
        // Sparse tag indices take the sorting path, with the same order.
        let sparse: Vec<usize> = tags.iter().map(|t| t * 1_000_000).collect();
        assert_eq!(grouped(&sparse), vec![1, 4, 3, 0, 2, 5]);
        assert!(grouped(&[]).is_empty());
    }

    #[test]
    fn a_batch_gives_the_estimates_of_stepping_in_input_order() {
        use crate::track::{GlacParams, PhaseRead};
        use crate::scene::{Antenna, Region};
        use nalgebra::Vector3;
        // GLAC's 2D layout, the region excluding the mirror.
        let antennas = [[0.0, 0.0], [0.0, 0.3], [0.0, 0.8], [0.8, 0.8]]
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: 0.0, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(0.1, -0.5, 0.0), max: Vector3::new(1.6, 1.5, 0.0) };
        let scene = Scene::new(2, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, Some(region), vec![]).unwrap();
        let params = crate::track::Params::from(GlacParams::default());
        // Three tags on circles, read round-robin over the antennas.
        let mut tags = Vec::new();
        let mut reads = Vec::new();
        for k in 0..900 {
            let tag = k % 3;
            let t = k as f64 / 90.0;
            let angle = 0.4 * t + tag as f64;
            let p = Vector3::new(0.7 + 0.2 * angle.cos(), 0.35 + 0.2 * angle.sin(), 0.0);
            let a = (k / 3) % scene.antennas.len();
            let d = (p - scene.antennas[a].position).norm();
            let phase = scene.ideal_phase(a, 915.25e6, d).rem_euclid(std::f64::consts::TAU);
            tags.push(tag * 7); // sparse codes, as shards give them
            reads.push(Measurement::Phase(PhaseRead { time_s: t, antenna: a, frequency_hz: 915.25e6, phase_rad: phase }));
        }
        let mut one_by_one = Engine::new(scene.clone(), "glac", params.clone()).unwrap();
        let expected: Vec<(usize, Estimate)> =
            tags.iter().zip(&reads).enumerate().filter_map(|(i, (&t, m))| one_by_one.step(t, m).map(|e| (i, e))).collect();
        let mut batched = Engine::new(scene, "glac", params).unwrap();
        let mut got = Vec::new();
        for (lo, hi) in [(0, 250), (250, 251), (251, 900)] {
            batched.run_batch(&tags[lo..hi], &reads[lo..hi], |i, e| got.push((lo + i, e.clone())));
        }
        assert!(expected.len() > 800, "the tags are tracked");
        assert_eq!(got, expected);
    }

    #[test]
    fn reorder_window_sorts_late_arrivals() {
        let mut w = ReorderWindow::new(0.1);
        let mut out = Vec::new();
        for t in [0.0, 0.05, 0.03, 0.2, 0.12, 0.4] {
            out.extend(w.push(0, m(t)));
        }
        out.extend(w.flush());
        let times: Vec<f64> = out.iter().map(|(_, m)| m.time_s()).collect();
        assert_eq!(times, vec![0.0, 0.03, 0.05, 0.12, 0.2, 0.4]);
        assert_eq!(w.late, 0);
    }

    #[test]
    fn latency_percentiles() {
        let mut l = Latency::default();
        for ns in 1..=100 {
            l.record(ns);
        }
        assert_eq!(l.percentile_ns(0.5), 50.0);
        assert_eq!(l.percentile_ns(0.99), 99.0);
        assert_eq!(l.max_ns, 100);
        assert!((l.mean_ns() - 50.5).abs() < 1e-12);
    }
}
