//! End-to-end tests of the per-reply pipeline on the simulator of
//! `common`: exact recovery without noise, accuracy with noise, FM0 and
//! Miller, BLF error, missing replies, non-finite windows, the timing
//! reference and calibration.

mod common;

use common::Reply;
use num_complex::{Complex32, Complex64};
use scattertrack_dsp::backscatter::Encoding;
use scattertrack_dsp::detect::Feature;
use scattertrack_dsp::estimate::{path_channel, Calibration, SymbolState};
use scattertrack_dsp::reply::{ReplyEstimate, ReplyOptions, ReplyProcessor};
use scattertrack_dsp::Error;

fn processor(reply: &Reply, options: ReplyOptions) -> ReplyProcessor {
    ReplyProcessor::new(reply.config.clone(), reply.symbol.clone(), options).unwrap()
}

fn run(reply: &Reply, options: ReplyOptions) -> Result<ReplyEstimate, Error> {
    let windows = reply.windows();
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
    processor(reply, ReplyOptions { encoding: reply.encoding, trext: reply.trext, ..options }).process(&refs, None)
}

/// The estimate with the timing's linear phase removed, to compare with
/// `Reply::raw_tag_channel`: `Ĥ(k) = G Γ T · exp(j2π k' D / N)`,
/// `D = first_sample + tx_phase`.
fn untimed(reply: &Reply, estimate: &ReplyEstimate) -> Vec<Complex64> {
    let n = reply.config.subcarriers as f64;
    let bins = reply.signed_active_bins();
    let f = estimate.subcarriers;
    estimate
        .tag_channel
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let d = (estimate.first_samples[i / f] + reply.tx_phase) as f64;
            h * Complex64::from_polar(1.0, -std::f64::consts::TAU * bins[i % f] * d / n)
        })
        .collect()
}

/// Mean of `|estimate − truth|² / reported variance`: about 1 when the
/// estimate is unbiased and its reported variance right.
fn normalised_error(estimate: &[Complex64], truth: &[Complex64], variance: &[f64]) -> f64 {
    estimate.iter().zip(truth).zip(variance).map(|((g, t), v)| (g - t).norm_sqr() / v).sum::<f64>() / truth.len() as f64
}

fn worst_relative_error(a: &[Complex64], b: &[Complex64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).norm() / y.norm()).fold(0.0, f64::max)
}

#[test]
fn noiseless_reply_recovers_the_tag_channel_exactly() {
    let mut reply = Reply::paper(1);
    reply.snr_db = f64::INFINITY;
    let estimate = run(&reply, ReplyOptions::default()).unwrap();
    // Below 1 only by the smoothing's smear of the transitions (an eighth of a chip).
    assert!(estimate.detection.score > 0.97, "{:?}", estimate.detection);
    assert!((estimate.start_sample - 25e-6 * 100e6).abs() < 20.0, "{}", estimate.start_sample);
    let error = worst_relative_error(&untimed(&reply, &estimate), &reply.raw_tag_channel());
    // f32 samples with the leakage 55 dB above the tag: ~1e-4 relative.
    assert!(error < 1e-3, "relative error {error}");
    assert!(estimate.payload_chips > 0);
    assert!(estimate.antenna_errors.iter().all(|e| e.is_none()));
}

#[test]
fn edge_elimination_counts_match_the_chip_grid() {
    let mut reply = Reply::paper(2);
    reply.snr_db = f64::INFINITY;
    reply.transition_samples = 0.0;
    let options = ReplyOptions { use_payload: false, guard_symbols: 1.0, ..Default::default() };
    let estimate = run(&reply, options).unwrap();
    // Independent count: symbols [m, m+1) of 20 samples each, wholly inside
    // a run of equal preamble chips shrunk by the guard (1 symbol) at each
    // end that is a transition; the preamble 110100100011 has runs
    // 11|0|1|00|1|000|11 → lengths 2,1,1,2,1,3,2 chips of 62.5 symbols.
    let first = estimate.first_samples[0] as f64;
    let start = (25e-6 * 100e6 - first) / 20.0; // reply start in symbols
    let guard = 1.0 + 62.5 * estimate.detection.scale_uncertainty * 6.0; // widest (chip 0 and 12)
    let runs = [(0, 2, 1), (2, 3, 0), (3, 4, 1), (4, 6, 0), (6, 7, 1), (7, 10, 0), (10, 12, 1)];
    let (mut high, mut low) = (0, 0);
    for (i, j, level) in runs {
        let a = start + i as f64 * 62.5;
        let b = start + j as f64 * 62.5;
        // Bounds between the narrowest and widest guard.
        let inner = ((b - guard).floor() - (a + guard).ceil()) as i64;
        if level == 1 {
            high += inner.max(0) as usize;
        } else {
            low += inner.max(0) as usize;
        }
    }
    let c = estimate.counts[0];
    assert!(c.high >= high && c.high <= high + 14, "high {} vs ≥ {high}", c.high);
    assert!(c.low >= low && c.low <= low + 14, "low {} vs ≥ {low}", c.low);
    // Eight transitions inside the preamble plus its two ends, each
    // discarding about two guards' worth of symbols.
    assert!(c.edge >= 8 * 2 && c.edge <= 10 * 8, "edge {}", c.edge);
    assert_eq!(c.high + c.low + c.edge + c.outside + c.invalid, estimate.symbols);
    // No used symbol overlaps a transition of the true waveform.
    let states = &estimate.states[..estimate.symbols];
    let chips = reply.chips();
    for (m, s) in states.iter().enumerate() {
        if !matches!(s, SymbolState::High | SymbolState::Low) {
            continue;
        }
        let level = |sample: f64| {
            let c = ((sample - 2500.0) / 1250.0).floor() as usize;
            chips[c]
        };
        let (from, to) = (first + 20.0 * m as f64, first + 20.0 * (m + 1) as f64 - 1.0);
        assert_eq!(level(from), level(to), "symbol {m} straddles a transition");
        assert_eq!(level(from), u8::from(*s == SymbolState::High), "symbol {m}");
    }
}

#[test]
fn noisy_replies_are_accurate_within_the_predicted_variance() {
    for (seed, snr_db) in [(3, 0.0), (4, -10.0)] {
        let mut reply = Reply::paper(seed);
        reply.snr_db = snr_db;
        let estimate = run(&reply, ReplyOptions::default()).unwrap();
        let truth = reply.raw_tag_channel();
        let got = untimed(&reply, &estimate);
        // Normalised squared errors follow the reported variance: their mean
        // is about 1 (generous bounds: 76 values, χ² with 152 dof).
        let z = normalised_error(&got, &truth, &estimate.variance);
        assert!(z > 0.6 && z < 1.6, "SNR {snr_db} dB: mean normalised error {z}");
        // Each phase error within 4.5 sigma of its own (σ_φ = √(var/2)/|h|).
        for ((g, t), v) in got.iter().zip(&truth).zip(&estimate.variance) {
            let sigma = (v / 2.0).sqrt() / t.norm();
            assert!((g * t.conj()).arg().abs() < 4.5 * sigma, "SNR {snr_db} dB: phase error beyond 4.5 σ = {sigma}");
        }
        // One reply of ~1000 clean symbols gains ~24 dB over the per-sample SNR.
        let rms: f64 = (got.iter().zip(&truth).map(|(g, t)| (g * t.conj()).arg().powi(2)).sum::<f64>() / 76.0).sqrt();
        assert!(rms < 0.1 * 10f64.powf(-snr_db / 20.0), "SNR {snr_db} dB: rms phase error {rms} rad");
    }
}

#[test]
fn miller_with_pilot_and_blf_error_is_found() {
    for m in [2u8, 4, 8] {
        let mut reply = Reply::paper(5);
        reply.encoding = Encoding::Miller(m);
        reply.trext = m == 4;
        reply.config = scattertrack_dsp::ofdm::OfdmConfig::new(100e6, 20, 915e6, 320e3).unwrap();
        reply.blf_scale = 0.97;
        reply.snr_db = 0.0;
        reply.window_samples = 100_000;
        reply.reply_start_s = 30e-6;
        let estimate = run(&reply, ReplyOptions::default()).unwrap();
        assert!((estimate.blf_hz / 320e3 - 0.97).abs() < 0.005, "M={m}: BLF {}", estimate.blf_hz);
        assert!((estimate.start_sample - 3000.0).abs() < 40.0, "M={m}: start {}", estimate.start_sample);
        let z = normalised_error(&untimed(&reply, &estimate), &reply.raw_tag_channel(), &estimate.variance);
        assert!(z > 0.6 && z < 1.6, "M={m}: mean normalised error {z}");
        assert!(estimate.payload_chips > 0, "M={m}: no payload chip read");
    }
}

#[test]
fn paper_magnitude_feature_also_detects() {
    let mut reply = Reply::paper(6);
    reply.snr_db = 10.0;
    let options = ReplyOptions { feature: Feature::CombinedMagnitude, ..Default::default() };
    let estimate = run(&reply, options).unwrap();
    assert!((estimate.start_sample - 2500.0).abs() < 40.0, "start {}", estimate.start_sample);
}

#[test]
fn a_window_without_reply_is_no_preamble() {
    // Noise alone never reaches the threshold (a false alarm would become a
    // bogus frame): several noise draws, the best score stays well below.
    for seed in 7..13 {
        let mut reply = Reply::paper(seed);
        reply.silent = true;
        match run(&reply, ReplyOptions::default()) {
            Err(Error::NoPreamble { score, threshold }) => assert!(score < 0.6 * threshold, "seed {seed}: {score}"),
            other => panic!("expected NoPreamble, got {other:?}"),
        }
    }
}

#[test]
fn non_finite_windows_fail_per_antenna_or_whole() {
    let reply = Reply::paper(8);
    let mut windows = reply.windows();
    windows[1].iter_mut().for_each(|v| *v = Complex32::new(f32::NAN, f32::NAN));
    windows[2][100] = Complex32::new(f32::INFINITY, 0.0);
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
    let mut p = processor(&reply, ReplyOptions::default());
    let estimate = p.process(&refs, None).unwrap();
    assert!(matches!(estimate.antenna_errors[1], Some(Error::NonFinite(_))));
    let f = estimate.subcarriers;
    assert!(estimate.tag_channel[f..2 * f].iter().all(|v| v.re.is_nan()));
    assert!(estimate.tag_channel[2 * f..].iter().all(|v| v.is_finite()));
    assert_eq!(estimate.counts[2].invalid, 1);
    let nan = vec![Complex32::new(f32::NAN, 0.0); 30_000];
    let all: Vec<&[Complex32]> = vec![&nan, &nan];
    assert!(matches!(p.process(&all, None), Err(Error::NonFinite(_))));
    assert!(matches!(p.process(&[], None), Err(Error::Shape(_))));
    let short = vec![Complex32::new(1.0, 0.0); 5000];
    assert!(matches!(p.process(&[&short], None), Err(Error::TooShort { .. })));
}

#[test]
fn timing_reference_keeps_the_phase_consistent_across_windows() {
    // A hardware delay near half a sample: the correlation peak may pick
    // either neighbour. With the tx phase and a reference, every window
    // gives the same channel whatever its tx phase.
    let mut reply = Reply::paper(9);
    reply.snr_db = f64::INFINITY;
    reply.hardware_delay_samples = vec![2.5 - 0.26, 3.5 - 0.26, 1.5 - 0.26, 2.5 - 0.26];
    let mut p = processor(&reply, ReplyOptions::default());
    let mut results = Vec::new();
    for phase in [0usize, 3, 11, 19] {
        reply.tx_phase = phase;
        let windows = reply.windows();
        let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
        results.push(p.process(&refs, Some(phase)).unwrap().tag_channel);
    }
    assert!(p.timing_reference().is_some());
    for r in &results[1..] {
        assert!(worst_relative_error(r, &results[0]) < 1e-3);
    }
    assert!(p.set_timing_reference(Some(vec![25])).is_err());
}

#[test]
fn calibration_at_a_known_position_gives_the_formats_convention() {
    let mut reply = Reply::paper(10);
    reply.snr_db = 10.0;
    let frequencies = reply.config.subcarrier_frequencies();
    let f = frequencies.len();
    let reference: Vec<Complex64> = (0..reply.rx.len())
        .flat_map(|a| {
            let (d1, d2) = (common::distance(&reply.tx, &reply.tag), common::distance(&reply.tag, &reply.rx[a]));
            path_channel(&frequencies, d1 + d2, 1.0 / (d1 * d2))
        })
        .collect();
    let mut p = processor(&reply, ReplyOptions::default());
    let measure = |p: &mut ReplyProcessor, reply: &Reply| {
        let windows = reply.windows();
        let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
        p.process(&refs, Some(reply.tx_phase)).unwrap().tag_channel
    };
    let cal_replies: Vec<Vec<Complex64>> = (0..3)
        .map(|i| {
            let mut r = reply.clone();
            r.seed = 100 + i;
            measure(&mut p, &r)
        })
        .collect();
    let refs: Vec<&[Complex64]> = cal_replies.iter().map(|c| c.as_slice()).collect();
    let calibration = Calibration::from_measurements(&refs, &reference, reply.rx.len(), f).unwrap();
    // The tag moves 23 cm; another window with another tx phase.
    let mut moved = reply.clone();
    moved.tag = [0.9, 1.2, 0.4];
    moved.tx_phase = 13;
    moved.seed = 200;
    let mut h = measure(&mut p, &moved);
    calibration.apply(&mut h).unwrap();
    let truth = moved.true_tag_channel(&moved.tag);
    let phase: f64 = h.iter().zip(&truth).map(|(g, t)| (g * t.conj()).arg().abs()).fold(0.0, f64::max);
    assert!(phase < 0.15, "worst calibrated phase error {phase} rad");
    // The path length implied by the phase slope across the band, per rx.
    for a in 0..moved.rx.len() {
        let row = &h[a * f..(a + 1) * f];
        let slope: f64 =
            row.windows(2).map(|w| (w[1] * w[0].conj()).arg()).sum::<f64>() / (frequencies[f - 1] - frequencies[0]);
        let implied = -slope * scattertrack_dsp::SPEED_OF_LIGHT / std::f64::consts::TAU;
        let d = common::distance(&moved.tx, &moved.tag) + common::distance(&moved.tag, &moved.rx[a]);
        assert!((implied - d).abs() < 0.05, "rx {a}: {implied} m vs {d} m");
    }
}

/// The split used by a real-time runtime (one worker per antenna, then the
/// joint stage) gives exactly what `process` gives, with and without a
/// timing reference, and unequal window lengths are cut to a common span.
#[test]
fn per_antenna_fronts_then_finish_equal_process() {
    use scattertrack_dsp::reply::{AntennaFront, AntennaSymbols};
    let reply = Reply::paper(5);
    let windows = reply.windows();
    let refs: Vec<&[Complex32]> = windows.iter().map(|w| w.as_slice()).collect();
    let options = ReplyOptions { encoding: reply.encoding, trext: reply.trext, ..Default::default() };
    let mut whole = processor(&reply, options.clone());
    let mut joint = processor(&reply, options.clone());
    let mut front = AntennaFront::new(&reply.config, &reply.symbol, &options).unwrap();
    for tx_phase in [Some(3usize), Some(11), None] {
        let expected = whole.process(&refs, tx_phase).unwrap();
        let mut antennas: Vec<AntennaSymbols> = (0..refs.len())
            .map(|a| {
                let mut out = AntennaSymbols::default();
                front.process(refs[a], joint.first_sample(a, tx_phase), &mut out);
                out
            })
            .collect();
        let got = joint.finish(&mut antennas, tx_phase).unwrap();
        assert_eq!(got.tag_channel, expected.tag_channel);
        assert_eq!(got.first_samples, expected.first_samples);
        assert_eq!(joint.timing_reference(), whole.timing_reference());
    }
    // A shorter window on one antenna: every antenna is cut to its span.
    let mut short: Vec<&[Complex32]> = refs.clone();
    short[2] = &refs[2][..refs[2].len() - 200];
    let expected = whole.process(&short, None).unwrap();
    let mut antennas: Vec<AntennaSymbols> = short
        .iter()
        .map(|w| {
            let mut out = AntennaSymbols::default();
            front.process(w, None, &mut out);
            out
        })
        .collect();
    let got = joint.finish(&mut antennas, None).unwrap();
    assert_eq!(got.symbols, expected.symbols);
    assert_eq!(got.tag_channel, expected.tag_channel);
}
