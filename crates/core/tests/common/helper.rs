//! A small wideband-frame simulator for the TurboTrack tests (independent
//! of the Python simulator): plus-shaped helper array in z = 0, a tag on a
//! figure-eight or at rest, complex Gaussian noise per subcarrier.

use nalgebra::{Complex, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use scattertrack_core::scene::{Scene, SPEED_OF_LIGHT};
use scattertrack_core::track::WidebandFrame;

pub struct HelperOptions {
    pub dimensions: usize,
    /// Peak speed, m/s (0: static).
    pub speed: f64,
    pub duration_s: f64,
    pub frame_rate: f64,
    /// Per-subcarrier noise rms relative to the tag channel amplitude.
    pub noise: f64,
    pub centre: Vector3<f64>,
}

impl Default for HelperOptions {
    fn default() -> Self {
        Self { dimensions: 3, speed: 0.2, duration_s: 5.0, frame_rate: 300.0, noise: 0.1, centre: Vector3::new(0.5, 1.2, 0.8) }
    }
}

pub fn helper_scene(dimensions: usize, plane_z: f64) -> Scene {
    Scene::plus_helper(dimensions, plane_z)
}

pub fn subcarriers() -> Vec<f64> {
    (0..20).map(|k| 867.5e6 + 5e6 * k as f64).collect()
}

/// Frames and the true position at each.
pub fn simulate_frames(o: &HelperOptions, seed: u64) -> (Scene, Vec<WidebandFrame>, Vec<Vector3<f64>>) {
    let scene = helper_scene(o.dimensions, o.centre.z);
    let mut rng = StdRng::seed_from_u64(seed);
    let freqs = subcarriers();
    let tx = scene.antennas[0].position;
    let rx: Vec<usize> = (1..5).collect();
    let mut frames = Vec::new();
    let mut truths = Vec::new();
    let mut t = 0.0;
    // Figure-eight of half-width a: peak speed ≈ a ω √(1 + 4)/... choose ω for the speed.
    let a = 0.3;
    let omega = if o.speed > 0.0 { o.speed / (a * 5f64.sqrt()) } else { 0.0 };
    let phase0: f64 = rng.random::<f64>() * std::f64::consts::TAU;
    while t < o.duration_s {
        let th = omega * t + phase0;
        let mut p = o.centre + Vector3::new(a * th.sin(), a * (2.0 * th).sin() / 2.0, 0.0);
        if o.dimensions == 3 {
            p.z += 0.15 * (0.5 * th).sin();
        }
        let mut h = Vec::with_capacity(rx.len() * freqs.len());
        for &r in &rx {
            let d = (p - tx).norm() + (p - scene.antennas[r].position).norm();
            for &f in &freqs {
                let (s, c) = (std::f64::consts::TAU * f * d / SPEED_OF_LIGHT).sin_cos();
                let noise = Complex::new(rng.sample::<f64, _>(StandardNormal), rng.sample::<f64, _>(StandardNormal)) * (o.noise / 2f64.sqrt());
                h.push(Complex::new(c, -s) + noise);
            }
        }
        frames.push(WidebandFrame { time_s: t, tx: 0, rx: rx.clone(), frequencies_hz: freqs.clone(), h });
        truths.push(p);
        t += (0.5 + rng.random::<f64>()) / o.frame_rate;
    }
    (scene, frames, truths)
}
