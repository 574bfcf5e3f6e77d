//! TurboTrack on simulated wideband frames (the small simulator in
//! `common::helper`): accuracy of the full method and of its §7.2
//! variants, robustness to declined frames.

mod common;

use common::helper::{simulate_frames, HelperOptions};
use common::percentile;
use scattertrack_core::track::{make, Measurement, Params};

/// Median and p90 3D error (m) after `settle_s`, and the estimates' count.
fn errors(method: &str, o: &HelperOptions, seed: u64, settle_s: f64) -> (f64, f64, usize) {
    let (scene, frames, truths) = simulate_frames(o, seed);
    let mut tracker = make(method, &scene, &Params::default()).unwrap();
    let mut errors = Vec::new();
    for (f, p) in frames.into_iter().zip(&truths) {
        let t = f.time_s;
        if let Some(e) = tracker.step(&Measurement::Wideband(f)) {
            if t >= settle_s {
                errors.push(((e.position[0] - p.x).powi(2) + (e.position[1] - p.y).powi(2) + (e.position[2] - p.z).powi(2)).sqrt());
            }
        }
    }
    let n = errors.len();
    assert!(n > 0, "{method}: no estimates");
    (percentile(errors.clone(), 0.5), percentile(errors, 0.9), n)
}

#[test]
fn turbotrack_reaches_millimetres_in_3d_and_2d() {
    for (dimensions, speed) in [(3, 0.0), (3, 0.2), (2, 0.5)] {
        for seed in 0..3 {
            let o = HelperOptions { dimensions, speed, ..Default::default() };
            let (median, p90, n) = errors("turbotrack", &o, seed, 1.0);
            eprintln!("turbotrack {dimensions}D {speed} m/s seed {seed}: median {:.2} mm p90 {:.2} mm ({n})", median * 1e3, p90 * 1e3);
            assert!(median < 0.01 && p90 < 0.02, "{dimensions}D {speed} m/s seed {seed}: {median} {p90}");
        }
    }
}

#[test]
fn baselines_run_and_full_method_wins() {
    let o = HelperOptions { dimensions: 2, speed: 0.2, duration_s: 4.0, ..Default::default() };
    let (full, _, _) = errors("turbotrack", &o, 7, 1.0);
    let (ellipse, _, _) = errors("ellipse-intersection", &o, 7, 1.0);
    let (gaussian, _, _) = errors("gaussian-pf", &o, 7, 1.0);
    eprintln!("2D: turbotrack {:.1} mm, ellipse {:.1} mm, gaussian-pf {:.1} mm", full * 1e3, ellipse * 1e3, gaussian * 1e3);
    assert!(full < ellipse && full < gaussian);
    // A static tag: RFind answers once its acquisition window is full.
    let o = HelperOptions { dimensions: 3, speed: 0.0, duration_s: 4.0, ..Default::default() };
    let (rfind, _, n) = errors("rfind", &o, 3, 0.0);
    eprintln!("static: rfind {:.1} mm over {n} estimates", rfind * 1e3);
    assert!(rfind < 0.05, "{rfind}");
}

#[test]
fn declined_frames_are_counted() {
    let o = HelperOptions { dimensions: 3, speed: 0.1, duration_s: 1.0, ..Default::default() };
    let (scene, frames, _) = simulate_frames(&o, 1);
    let mut tracker = make("turbotrack", &scene, &Params::default()).unwrap();
    for f in frames.iter().take(50) {
        tracker.step(&Measurement::Wideband(f.clone()));
    }
    // All subcarriers NaN: declined as unusable, counted.
    let mut nan = frames[50].clone();
    nan.h.iter_mut().for_each(|h| *h = nalgebra::Complex::new(f64::NAN, f64::NAN));
    assert!(tracker.step(&Measurement::Wideband(nan)).is_none());
    // Out of time order.
    let mut late = frames[51].clone();
    late.time_s = frames[10].time_s;
    assert!(tracker.step(&Measurement::Wideband(late)).is_none());
    // A COTS phase read is not this method's input.
    let read = scattertrack_core::track::PhaseRead { time_s: 10.0, antenna: 1, frequency_hz: 915e6, phase_rad: 0.1 };
    assert!(tracker.step(&Measurement::Phase(read)).is_none());
    let s = tracker.stats();
    assert_eq!(s.measurements, 53);
    assert_eq!(s.invalid, 2);
    assert_eq!(s.out_of_order, 1);
    assert!(tracker.step(&Measurement::Wideband(frames[52].clone())).is_some());
}
