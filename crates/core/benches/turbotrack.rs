//! TurboTrack per-frame cost (criterion): a converged step with 4 receive
//! antennas × 20 subcarriers at N = 100 particles (the thesis's setting),
//! the same at N = 1000, the initialising step (intersection tuples,
//! pruning, sampling), and candidate extraction alone.
//!
//! `cargo bench -p scattertrack-core --bench turbotrack`

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::time::Duration;

use common::helper::{simulate_frames, HelperOptions};
use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion, Throughput};
use scattertrack_core::model::wideband::{distance_candidates, CandidateParams};
use scattertrack_core::track::{Measurement, Tracker, TurboTrack, TurboTrackParams};

fn converged_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("turbotrack");
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    let o = HelperOptions { dimensions: 3, speed: 0.3, duration_s: 30.0, ..Default::default() };
    let (scene, frames, _) = simulate_frames(&o, 11);
    let frames: Vec<Measurement> = frames.into_iter().map(Measurement::Wideband).collect();
    for particles in [100usize, 1000] {
        let mut tracker = TurboTrack::new(scene.clone(), TurboTrackParams { particles, ..Default::default() }).unwrap();
        // Converge on the first second, then cycle through the rest.
        for m in &frames[..300] {
            tracker.step(m);
        }
        let mut k = 300;
        group.throughput(Throughput::Elements(1));
        group.bench_function(BenchmarkId::new("converged_step_4rx", particles), |b| {
            b.iter(|| {
                let m = &frames[k];
                k = if k + 1 < frames.len() { k + 1 } else { 300 };
                black_box(tracker.step(black_box(m)))
            })
        });
    }
    group.bench_function("initialising_step_4rx_100", |b| {
        b.iter_batched_ref(
            || TurboTrack::new(scene.clone(), TurboTrackParams::default()).unwrap(),
            |t| black_box(t.step(black_box(&frames[0]))),
            BatchSize::SmallInput,
        )
    });
    if let Measurement::Wideband(f) = &frames[0] {
        let h = &f.h[..f.frequencies_hz.len()];
        group.bench_function("candidates_one_rx", |b| {
            b.iter(|| black_box(distance_candidates(&f.frequencies_hz, black_box(h), 0.4, 7.5, &CandidateParams::default())))
        });
    }
    group.finish();
}

criterion_group!(benches, converged_step);
criterion_main!(benches);
