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
    trackers: Vec<Option<Box<dyn Tracker>>>,
    latency: Latency,
}

impl Engine {
    /// Fails on an unknown method or invalid parameters (checked by
    /// building one tracker up front).
    pub fn new(scene: Scene, method: &str, params: Params) -> Result<Self> {
        make(method, &scene, &params)?;
        Ok(Self { scene, method: method.to_string(), params, trackers: Vec::new(), latency: Latency::default() })
    }

    /// One measurement of tag `tag`.
    pub fn step(&mut self, tag: usize, measurement: &Measurement) -> Option<Estimate> {
        if tag >= self.trackers.len() {
            self.trackers.resize_with(tag + 1, || None);
        }
        if self.trackers[tag].is_none() {
            // The method and parameters were validated in `new`.
            self.trackers[tag] = make(&self.method, &self.scene, &self.params).ok();
        }
        let tracker = self.trackers[tag].as_mut()?;
        let start = Instant::now();
        let estimate = tracker.step(measurement);
        self.latency.record(start.elapsed().as_nanos() as u64);
        estimate
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
