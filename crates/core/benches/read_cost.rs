//! Per-read cost of GLAC over whole simulated recordings (issue 21): every
//! `Tracker::step` is timed on its own, and the table gives p50, p99,
//! p99.99 and the maximum (µs) with the largest work one read did
//! (`max_expanded_per_read`: hypotheses expanded and initial candidates
//! scored). Rows: converged tags (reads after the first estimate with
//! (one hypothesis left), initialising tags (every other read), mod-π 2D and 3D recordings
//! whole. `cargo bench -p scattertrack-core --bench read_cost`.
//! Times depend on the machine (and on what else runs on it); the
//! per-read work bound is what the tests assert.

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::Instant;

use common::{simulate, Options};
use scattertrack_core::track::{Glac, GlacParams, Measurement, Tracker};

/// Seeds per row: the expensive stage happens once per recording.
const SEEDS: u64 = 12;

struct Row {
    name: &'static str,
    costs_ns: Vec<f64>,
    max_expanded: u64,
}

fn record(options: &Options, params: &GlacParams, converged: &mut Row, initialising: &mut Row, whole: Option<&mut Row>) {
    let mut whole = whole;
    for seed in 0..SEEDS {
        let (scene, reads, _) = simulate(options, seed);
        let mut tracker = Glac::new(scene, params.clone()).unwrap();
        let mut committed = false;
        for m in &reads {
            let start = Instant::now();
            let estimate = tracker.step(&Measurement::Phase(*m));
            let ns = start.elapsed().as_nanos() as f64;
            let live = estimate.as_ref().is_some_and(|e| e.hypotheses > 0);
            let single = estimate.as_ref().is_some_and(|e| e.hypotheses == 1);
            if let Some(w) = whole.as_deref_mut() {
                w.costs_ns.push(ns);
            }
            if committed && single {
                converged.costs_ns.push(ns);
            } else {
                initialising.costs_ns.push(ns);
            }
            committed |= live;
        }
        let expanded = tracker.stats().max_expanded_per_read;
        for row in [&mut *converged, &mut *initialising] {
            row.max_expanded = row.max_expanded.max(expanded);
        }
        if let Some(w) = whole.as_deref_mut() {
            w.max_expanded = w.max_expanded.max(expanded);
        }
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let params = GlacParams { phase_wander_rad: 0.1, ..GlacParams::default() };
    let row = |name| Row { name, costs_ns: Vec::new(), max_expanded: 0 };
    let (mut converged, mut initialising) = (row("converged 2D"), row("initialising 2D"));
    record(&Options { dimensions: 2, duration: 20.0, ..Default::default() }, &params, &mut converged, &mut initialising, None);
    let (mut tracking3, mut initialising3) = (row("converged 3D"), row("initialising 3D"));
    record(&Options { duration: 20.0, ..Default::default() }, &params, &mut tracking3, &mut initialising3, None);
    let (mut c2, mut i2, mut pi2) = (row("-"), row("-"), row("mod-pi 2D"));
    record(&Options { dimensions: 2, mod_pi: true, speed: 0.4, duration: 10.0, ..Default::default() }, &params, &mut c2, &mut i2, Some(&mut pi2));
    let (mut c3, mut i3, mut pi3) = (row("-"), row("-"), row("mod-pi 3D"));
    record(&Options { dimensions: 3, mod_pi: true, duration: 10.0, ..Default::default() }, &params, &mut c3, &mut i3, Some(&mut pi3));
    println!("{:<18} {:>8} {:>9} {:>9} {:>10} {:>10} {:>13}", "per-read cost", "reads", "p50 µs", "p99 µs", "p99.99 µs", "max µs", "max expanded");
    for r in [converged, initialising, tracking3, initialising3, pi2, pi3] {
        let mut v = r.costs_ns;
        if v.is_empty() {
            println!("{:<18} {:>8}", r.name, 0);
            continue;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        let us = |q: f64| quantile(&v, q) / 1e3;
        println!(
            "{:<18} {:>8} {:>9.2} {:>9.2} {:>10.1} {:>10.1} {:>13}",
            r.name, v.len(), us(0.5), us(0.99), us(0.9999), v[v.len() - 1] / 1e3, r.max_expanded
        );
    }
}
