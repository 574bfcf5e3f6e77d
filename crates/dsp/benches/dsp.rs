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
//! * `lora/*` (Marvel, docs/marvel.md section 7): `epoch` is one sensing
//!   epoch, 2 channels x 4 tags x 3 antennas = 24 chirps of 4096 samples
//!   (SF 12, 500 kHz) at -10 dB per sample, through peaks, MUSIC per tag,
//!   Doppler/CFO, phases, range and yaw (`EpochProcessor::process`); the
//!   epoch rate is 10 Hz, so the budget is 100 ms per epoch. `peak` is one
//!   chirp's dechirp + FFT + refinement, `music_tag` one tag's MUSIC.

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::time::Duration;

use common::Reply;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use num_complex::{Complex32, Complex64};
use scattertrack_dsp::backscatter::{preamble_chips, Encoding};
use scattertrack_dsp::detect::{
    combined_magnitude, combined_projection, combined_projection_from_sums, detect_preamble, DetectionOptions, Feature,
    FeatureSums, Template,
};
use scattertrack_dsp::estimate::{symbol_states, tag_channel, ChipGrid, SymbolSums};
use scattertrack_dsp::lora::{music, Corrections, EpochConfig, EpochProcessor, PeakFinder, PeakOptions};
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

/// One synthetic Marvel epoch: per (channel, tag, antenna) a dechirpable
/// tone of a few hertz with an antenna phase for a drone at (az 1.2, el
/// 0.2), plus complex white noise at -10 dB per sample.
fn lora_epoch(config: &EpochConfig) -> Vec<Complex32> {
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = StdRng::seed_from_u64(12);
    let noise = Normal::new(0.0, (10f64.powf(1.0) / 2.0).sqrt()).unwrap();
    let up = config.chirp.upchirp();
    let fs = config.chirp.sample_rate_hz();
    let u = scattertrack_dsp::lora::geometry::direction(1.2, 0.2);
    let mut out = Vec::with_capacity(config.samples_per_epoch());
    for j in 0..2 {
        for k in 0..4 {
            let f = config.carrier_hz(j, k);
            for e in config.array.elements() {
                let phase = std::f64::consts::TAU * f / scattertrack_dsp::SPEED_OF_LIGHT * (e[0] * u[0] + e[1] * u[1] + e[2] * u[2]);
                let tone = 3.0 + k as f64 - 0.5 * j as f64;
                for (n, c) in up.iter().enumerate() {
                    let s = c * Complex64::from_polar(1.0, phase + std::f64::consts::TAU * tone * n as f64 / fs)
                        + Complex64::new(noise.sample(&mut rng), noise.sample(&mut rng));
                    out.push(Complex32::new(s.re as f32, s.im as f32));
                }
            }
        }
    }
    out
}

fn bench_lora(c: &mut Criterion) {
    let config = EpochConfig::marvel();
    let samples = lora_epoch(&config);
    let mut processor = EpochProcessor::new(config.clone()).unwrap();
    let corrections = Corrections {
        clock_error: 1e-6,
        velocity: Some([1.0, 0.5, 0.0]),
        attitude: Some(scattertrack_dsp::lora::geometry::IDENTITY),
        omega_body: Some([0.0, 0.0, 1.0]),
        ..Default::default()
    };
    let check = processor.process(&samples, &corrections).unwrap();
    println!(
        "lora epoch: az {:.3} el {:.3} rad, snr {:.1} dB, timing range {:.2} m",
        check.azimuth, check.elevation, check.snr_db, check.timing_range_m
    );
    let mut group = c.benchmark_group("lora");
    group.measurement_time(Duration::from_secs(4));
    group.throughput(Throughput::Elements(1));
    group.bench_function("epoch", |b| b.iter(|| black_box(processor.process(black_box(&samples), &corrections).unwrap())));
    let mut finder = PeakFinder::new(config.chirp, PeakOptions::default()).unwrap();
    let n = config.chirp.samples();
    group.bench_function("peak", |b| b.iter(|| black_box(finder.process(black_box(&samples[..n])).unwrap())));
    let phases: Vec<f64> = (0..3).flat_map(|m| (0..2).map(move |j| (j, m))).map(|(j, m)| check.peaks[j * 12 + m].amplitude_centre.arg()).collect();
    let freqs = [config.carrier_hz(0, 0), config.carrier_hz(1, 0)];
    group.bench_function("music_tag", |b| {
        b.iter(|| black_box(music(&config.array, &config.music, black_box(&phases), &freqs).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench, bench_lora);
criterion_main!(benches);
