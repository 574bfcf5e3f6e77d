//! Criterion benchmarks of the helper's per-reply DSP (thesis ch. 4.3) in
//! the paper's set-up (100 MHz, N = 20, BLF 40 kHz, FM0, a 300 µs window,
//! 4 rx antennas, tag SNR 0 dB per sample), on windows from the crate's
//! test simulator (`tests/common`).
//!
//! * `reply/process_4rx`: the whole chain for one reply over 4 rx (timing,
//!   1500 FFTs per antenna, projection feature, preamble search, edge
//!   elimination, tag channel, payload reading). Target: ≥ 300 replies/s on
//!   2 cores, i.e. well under 3.3 ms per reply per core.
//! * `reply/process_4rx_magnitude`: the same with the paper's `Σ_f |H|`
//!   feature.
//! * `stage/*`: the stages alone — one antenna's timing and per-symbol
//!   FFTs (30 000 samples), its projection and magnitude features, the
//!   preamble search over 4 antennas' features, one antenna's tag channel;
//!   the real-time path's time-domain symbol sums and projection from them;
//!   `front_known_grid` (one antenna's worker job) and `finish_4rx` (the
//!   fusion's).

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::time::Duration;

use common::Reply;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use num_complex::Complex32;
use scattertrack_dsp::backscatter::{preamble_chips, Encoding};
use scattertrack_dsp::detect::{
    combined_magnitude, combined_projection, combined_projection_from_sums, detect_preamble, DetectionOptions, Feature,
    FeatureSums, Template,
};
use scattertrack_dsp::estimate::{symbol_states, tag_channel, ChipGrid, SymbolSums};
use scattertrack_dsp::ofdm::{symbol_timing, ChannelMatrix, ChannelTransform, Demodulator};
use scattertrack_dsp::reply::{AntennaFront, AntennaSymbols, ReplyOptions, ReplyProcessor};

fn bench(c: &mut Criterion) {
    let reply = Reply::paper(1);
    let windows = reply.windows();
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();

    let mut group = c.benchmark_group("reply");
    group.throughput(Throughput::Elements(1));
    group.measurement_time(Duration::from_secs(4));
    for (name, feature) in [("process_4rx", Feature::Projection), ("process_4rx_magnitude", Feature::CombinedMagnitude)]
    {
        let options = ReplyOptions { feature, ..Default::default() };
        let mut processor = ReplyProcessor::new(reply.config.clone(), reply.symbol.clone(), options).unwrap();
        let check = processor.process(&refs, None).unwrap();
        println!(
            "{name}: score {:.3}, {} symbols, {} payload chips, counts rx0 {:?}",
            check.detection.score, check.symbols, check.payload_chips, check.counts[0]
        );
        group.bench_function(name, |b| b.iter(|| black_box(processor.process(black_box(&refs), Some(7)).unwrap())));
    }
    group.finish();

    let mut group = c.benchmark_group("stage");
    group.measurement_time(Duration::from_secs(3));
    group.bench_function("symbol_timing", |b| {
        b.iter(|| black_box(symbol_timing(black_box(refs[0]), &reply.symbol).unwrap()))
    });
    let mut demodulator = Demodulator::new(&reply.config, &reply.symbol).unwrap();
    let mut h = ChannelMatrix::default();
    group.bench_function("demodulate", |b| {
        b.iter(|| demodulator.demodulate(black_box(refs[0]), 3, &mut h).unwrap());
    });
    demodulator.demodulate(refs[0], 3, &mut h).unwrap();
    let mut feature = Vec::new();
    group.bench_function("projection", |b| b.iter(|| combined_projection(black_box(&h), 15, &mut feature)));
    // The real-time path: time-domain symbol sums, and the projection from
    // them (no per-symbol FFT).
    let mut sums = SymbolSums::default();
    group.bench_function("symbol_sums", |b| b.iter(|| sums.reset(black_box(refs[0]), 3, 20).unwrap()));
    sums.reset(refs[0], 3, 20).unwrap();
    let mut transform = ChannelTransform::new(&reply.config, &reply.symbol).unwrap();
    group.bench_function("projection_from_sums", |b| {
        b.iter(|| combined_projection_from_sums(black_box(&sums), &mut transform, 15, &mut feature))
    });
    group.bench_function("magnitude", |b| b.iter(|| combined_magnitude(black_box(&h), &mut feature)));
    combined_projection(&h, 15, &mut feature);
    let sums: Vec<FeatureSums> = (0..4).map(|_| FeatureSums::new(&feature).unwrap()).collect();
    let template = Template::new(preamble_chips(Encoding::Fm0, false).unwrap()).unwrap();
    let options = DetectionOptions::default();
    group.bench_function("detect_preamble_4rx", |b| {
        b.iter(|| black_box(detect_preamble(black_box(&sums), &template, 62.5, &options).unwrap()))
    });
    let detection = detect_preamble(&sums, &template, 62.5, &options).unwrap();
    let grid = ChipGrid {
        start_symbol: detection.start_symbol,
        chip_symbols: detection.chip_symbols,
        guard_symbols: 1.0,
        drift_per_chip: 0.0,
        reference_chip: 6.0,
    };
    let levels: Vec<Option<u8>> = template.levels.iter().map(|&l| Some(l)).collect();
    let mut states = Vec::new();
    symbol_states(&grid, &levels, &h.valid, &mut states);
    group.bench_function("tag_channel", |b| b.iter(|| black_box(tag_channel(black_box(&h), &states).unwrap())));

    // The runtime's split: one antenna's front with the symbol grid known
    // (a worker's job), and the joint finish over 4 antennas (fusion).
    let options = ReplyOptions::default();
    let mut processor = ReplyProcessor::new(reply.config.clone(), reply.symbol.clone(), options.clone()).unwrap();
    processor.process(&refs, Some(7)).unwrap(); // learns the timing reference
    let mut front = AntennaFront::new(&reply.config, &reply.symbol, &options).unwrap();
    let mut one = AntennaSymbols::default();
    let first = processor.first_sample(0, Some(7));
    group.bench_function("front_known_grid", |b| b.iter(|| front.process(black_box(refs[0]), first, &mut one)));
    let mut antennas: Vec<AntennaSymbols> = (0..refs.len())
        .map(|a| {
            let mut out = AntennaSymbols::default();
            front.process(refs[a], processor.first_sample(a, Some(7)), &mut out);
            out
        })
        .collect();
    group.bench_function("finish_4rx", |b| b.iter(|| black_box(processor.finish(&mut antennas, Some(7)).unwrap())));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
