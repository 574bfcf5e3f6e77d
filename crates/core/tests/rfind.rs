//! The RFind-style baseline (`rfind`) on simulated wideband frames: a static
//! tag is localised once the acquisition window is full, and a moving tag —
//! which breaks RFind's static assumption and smears the pooled channel —
//! still gets (poor) estimates instead of none, with every frame accounted
//! for in the tracker's stats.
//!
//! The frames mimic the benchmark's 2D speed scenarios
//! (`scenarios/turbotrack-2d-speed-*.toml`): the plus-shaped helper in
//! z = 0, the tag on a lemniscate of Gerono (x 0.1–0.7 m, y 0.25–0.55 m) in
//! the plane z = 0.5 m at constant speed, ~300 frames/s, 20 subcarriers
//! over 100 MHz, per-subcarrier SNR 23 dB for a tag 1 m from tx and rx.

mod common;

use common::helper::{helper_scene, simulate_frames, subcarriers, HelperOptions};
use common::percentile;
use nalgebra::{Complex, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use scattertrack_core::scene::{Region, Scene, SPEED_OF_LIGHT};
use scattertrack_core::track::{make, Measurement, Params, TrackerStats, WidebandFrame};

/// The benchmark's 2D speed scene: the helper of `common::helper` with the
/// tag confined to `z = 0.5` and the benchmark's (wide) region.
fn speed_scene() -> Scene {
    let base = helper_scene(2, 0.5);
    let region = Region { min: Vector3::new(-1.5, -1.5, 0.49), max: Vector3::new(2.3, 2.3, 0.51) };
    Scene::new(2, 0.5, 1.0, std::f64::consts::TAU, 0.1, base.antennas, Some(region), vec![]).unwrap()
}

/// Lemniscate of Gerono `(A sin θ, B sin θ cos θ)` around `centre`,
/// travelled at constant `speed` (m/s): the position at time `t`.
struct FigureEight {
    centre: Vector3<f64>,
    a: f64,
    b: f64,
    /// Cumulative arc length at θ = i·dθ over one period.
    arc: Vec<f64>,
    dtheta: f64,
}

impl FigureEight {
    fn new(centre: Vector3<f64>, width: f64, height: f64) -> Self {
        let (a, b) = (width / 2.0, height);
        let n = 20_000;
        let dtheta = std::f64::consts::TAU / n as f64;
        let mut arc = vec![0.0];
        for i in 0..n {
            let th = (i as f64 + 0.5) * dtheta;
            let (dx, dy) = (a * th.cos(), b * (2.0 * th).cos());
            arc.push(arc[i] + (dx * dx + dy * dy).sqrt() * dtheta);
        }
        Self { centre, a, b, arc, dtheta }
    }

    fn at(&self, speed: f64, t: f64) -> Vector3<f64> {
        let perimeter = *self.arc.last().unwrap();
        let s = (speed * t).rem_euclid(perimeter);
        let i = self.arc.partition_point(|&v| v <= s).clamp(1, self.arc.len() - 1);
        let th = (i - 1) as f64 * self.dtheta + self.dtheta * (s - self.arc[i - 1]) / (self.arc[i] - self.arc[i - 1]).max(1e-300);
        self.centre + Vector3::new(self.a * th.sin(), self.b * th.sin() * th.cos(), 0.0)
    }
}

/// Where the tag rests when `speed` is 0: off the figure's centre (which
/// is the region's centre, where the solver starts).
const REST: [f64; 3] = [0.6, 0.3, 0.5];

/// Frames (and the true positions) of the benchmark's 2D speed scenario at
/// `speed` m/s (0: at rest at `REST`) for `duration_s`.
fn speed_frames(speed: f64, duration_s: f64, seed: u64) -> (Scene, Vec<WidebandFrame>, Vec<Vector3<f64>>) {
    let scene = speed_scene();
    let path = FigureEight::new(Vector3::new(0.4, 0.4, 0.5), 0.6, 0.3);
    let mut rng = StdRng::seed_from_u64(seed);
    let freqs = subcarriers();
    let tx = scene.antennas[0].position;
    let rx: Vec<usize> = (1..5).collect();
    let sigma = 10f64.powf(-23.0 / 20.0);
    let (mut frames, mut truths) = (Vec::new(), Vec::new());
    let mut t = 0.0;
    while t < duration_s {
        let p = if speed > 0.0 { path.at(speed, t) } else { Vector3::from(REST) };
        let mut h = Vec::with_capacity(rx.len() * freqs.len());
        for &r in &rx {
            let (d1, d2) = ((p - tx).norm(), (p - scene.antennas[r].position).norm());
            let amplitude = 1.0 / (d1 * d2);
            for &f in &freqs {
                let (s, c) = (std::f64::consts::TAU * f * (d1 + d2) / SPEED_OF_LIGHT).sin_cos();
                let noise = Complex::new(rng.sample::<f64, _>(StandardNormal), rng.sample::<f64, _>(StandardNormal)) * (sigma / 2f64.sqrt());
                h.push(Complex::new(c, -s) * amplitude + noise);
            }
        }
        frames.push(WidebandFrame { time_s: t, tx: 0, rx: rx.clone(), frequencies_hz: freqs.clone(), h });
        truths.push(p);
        t += (0.5 + rng.random::<f64>()) / 300.0;
    }
    (scene, frames, truths)
}

struct Run {
    /// 3D errors of the estimates after `settle_s`, m.
    errors: Vec<f64>,
    estimates: u64,
    stats: TrackerStats,
}

fn run_rfind(scene: &Scene, frames: Vec<WidebandFrame>, truths: &[Vector3<f64>], settle_s: f64) -> Run {
    let mut tracker = make("rfind", scene, &Params::default()).unwrap();
    let (mut errors, mut estimates) = (Vec::new(), 0);
    for (f, p) in frames.into_iter().zip(truths) {
        let t = f.time_s;
        if let Some(e) = tracker.step(&Measurement::Wideband(f)) {
            assert!(e.position.iter().all(|v| v.is_finite()), "non-finite estimate at {t}: {:?}", e.position);
            estimates += 1;
            if t >= settle_s {
                errors.push((Vector3::from(e.position) - p).norm());
            }
        }
    }
    Run { errors, estimates, stats: tracker.stats() }
}

/// Every frame is either answered or counted as declined (never dropped silently).
fn assert_accounted(run: &Run, label: &str) {
    let s = run.stats;
    let declined = s.out_of_order + s.invalid + s.outliers + s.initialising;
    assert_eq!(run.estimates + declined, s.measurements, "{label}: frames dropped silently: {s:?}, {} estimates", run.estimates);
}

#[test]
fn rfind_moving_tag_still_gets_estimates() {
    // RFind assumes a static tag over its 3 s window; at these speeds the
    // pooled channel is smeared, and the answer is poor, but there is one.
    for (speed, seed) in [(0.1, 0), (0.3, 0), (0.3, 1), (0.5, 2)] {
        let (scene, frames, truths) = speed_frames(speed, 8.0, seed);
        let n = frames.len() as u64;
        let run = run_rfind(&scene, frames, &truths, 0.5);
        let s = run.stats;
        assert_accounted(&run, &format!("{speed} m/s seed {seed}"));
        // After the acquisition window fills, (almost) every frame is answered.
        let after_window = n - s.initialising;
        assert!(
            run.estimates as f64 >= 0.9 * after_window as f64,
            "{speed} m/s seed {seed}: {} estimates of {after_window} frames ({s:?})",
            run.estimates
        );
        let median = percentile(run.errors.clone(), 0.5);
        eprintln!("rfind {speed} m/s seed {seed}: median {:.1} cm over {} estimates ({s:?})", median * 1e2, run.estimates);
        // Poor, but an estimate of the region the tag moves in (it spans 60 × 30 cm).
        assert!(median < 0.5, "{speed} m/s seed {seed}: median {median}");
    }
}

#[test]
fn rfind_static_tag_is_accurate_in_2d_and_3d() {
    let (scene, frames, truths) = speed_frames(0.0, 5.0, 3);
    let run = run_rfind(&scene, frames, &truths, 0.0);
    assert_accounted(&run, "2D static");
    let median = percentile(run.errors.clone(), 0.5);
    eprintln!("rfind 2D static: median {:.2} mm over {} estimates ({:?})", median * 1e3, run.estimates, run.stats);
    assert!(median < 0.001, "{median}");
    for seed in 0..3 {
        let o = HelperOptions { dimensions: 3, speed: 0.0, duration_s: 4.0, ..Default::default() };
        let (scene, frames, truths) = simulate_frames(&o, seed);
        let run = run_rfind(&scene, frames, &truths, 0.0);
        assert_accounted(&run, "3D static");
        let median = percentile(run.errors.clone(), 0.5);
        eprintln!("rfind 3D static seed {seed}: median {:.2} mm over {} estimates ({:?})", median * 1e3, run.estimates, run.stats);
        assert!(median < 0.002, "{median}");
    }
}

#[test]
fn rfind_declined_frames_are_counted() {
    let (scene, frames, _) = speed_frames(0.0, 4.0, 5);
    let mut tracker = make("rfind", &scene, &Params::default()).unwrap();
    let mut answered = 0u64;
    for f in &frames {
        answered += tracker.step(&Measurement::Wideband(f.clone())).is_some() as u64;
    }
    assert!(answered > 0);
    let before = tracker.stats();
    let last = frames.last().unwrap().clone();
    // Out of time order.
    let mut late = last.clone();
    late.time_s = frames[10].time_s;
    assert!(tracker.step(&Measurement::Wideband(late)).is_none());
    // An unknown receive antenna.
    let mut unknown = last.clone();
    unknown.rx[0] = 99;
    assert!(tracker.step(&Measurement::Wideband(unknown)).is_none());
    // A COTS phase read is not this method's input.
    let read = scattertrack_core::track::PhaseRead { time_s: 10.0, antenna: 1, frequency_hz: 915e6, phase_rad: 0.1 };
    assert!(tracker.step(&Measurement::Phase(read)).is_none());
    let s = tracker.stats();
    assert_eq!(s.measurements, before.measurements + 3);
    assert_eq!(s.out_of_order, before.out_of_order + 1);
    assert_eq!(s.invalid, before.invalid + 2);
    // The channel goes dark (every subcarrier NaN) for longer than the
    // window: estimates from the pooled channel while it still holds good
    // frames, then every frame is declined as invalid (no usable channel).
    let dark: Vec<WidebandFrame> = frames
        .iter()
        .map(|f| {
            let mut f = f.clone();
            f.time_s += last.time_s + 0.01;
            f.h.iter_mut().for_each(|h| *h = Complex::new(f64::NAN, f64::NAN));
            f
        })
        .collect();
    let window = Params::default().turbotrack.rfind_window_s;
    let mut declined = 0;
    for f in &dark {
        let since = f.time_s - last.time_s;
        match tracker.step(&Measurement::Wideband(f.clone())) {
            Some(e) => assert!(since <= window && e.position.iter().all(|v| v.is_finite()), "{since} s into the dark: {e:?}"),
            None => {
                assert!(since > window, "declined {since} s into the dark");
                declined += 1;
            }
        }
    }
    assert!(declined > 0);
    let after = tracker.stats();
    assert_eq!(after.measurements, s.measurements + dark.len() as u64);
    assert_eq!(after.invalid, s.invalid + declined);
}
