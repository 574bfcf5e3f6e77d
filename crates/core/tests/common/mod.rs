//! A small seeded phase simulator for the core's integration tests and
//! benches (the full simulator lives in the Python package; this one only
//! needs to exercise the trackers without I/O).

#![allow(dead_code)]

pub mod helper;

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use scattertrack_core::scene::{Antenna, ChannelOffset, Region, Scene};
use scattertrack_core::track::PhaseRead;

pub struct Options {
    pub dimensions: usize,
    pub speed: f64,
    pub duration: f64,
    pub phase_noise: f64,
    pub phase_sign: f64,
    pub mod_pi: bool,
    pub hopping: bool,
    pub reads_per_s: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self { dimensions: 3, speed: 0.1, duration: 10.0, phase_noise: 0.1, phase_sign: 1.0, mod_pi: false, hopping: false, reads_per_s: 30.0 }
    }
}

pub fn scene(o: &Options, rng: &mut StdRng) -> Scene {
    let pos = if o.dimensions == 3 { [[0.0, 0.0], [0.3, 0.0], [0.0, 0.8], [0.8, 0.8]] } else { [[0.0, 0.0], [0.0, 0.3], [0.0, 0.8], [0.8, 0.8]] };
    let antennas = pos
        .iter()
        .enumerate()
        .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: rng.random::<f64>() * 6.28, role: Default::default() })
        .collect();
    let region = if o.dimensions == 3 {
        Region { min: Vector3::new(-0.1, -0.3, 0.05), max: Vector3::new(1.2, 1.2, 1.2) }
    } else {
        Region { min: Vector3::new(0.1, -0.5, 0.0), max: Vector3::new(1.6, 1.5, 0.0) }
    };
    let channels = if o.hopping {
        (0..50).map(|k| ChannelOffset { frequency_hz: 902.75e6 + 0.5e6 * k as f64, phase_offset_rad: rng.random::<f64>() * 6.28 }).collect()
    } else {
        vec![]
    };
    let period = if o.mod_pi { std::f64::consts::PI } else { std::f64::consts::TAU };
    Scene::new(o.dimensions, 0.0, o.phase_sign, period, o.phase_noise.max(1e-3), antennas, Some(region), channels).unwrap()
}

/// Tag position at time t: a circle (2D) or a tilted 3D loop, constant speed.
pub fn truth(o: &Options, t: f64) -> Vector3<f64> {
    let radius = 0.2;
    let w = o.speed / radius;
    let a = w * t;
    if o.dimensions == 2 {
        Vector3::new(0.7 + radius * a.cos(), 0.35 + radius * a.sin(), 0.0)
    } else {
        Vector3::new(0.45 + radius * a.cos(), 0.4 + radius * a.sin(), 0.6 + 0.1 * a.sin())
    }
}

pub fn simulate(o: &Options, seed: u64) -> (Scene, Vec<PhaseRead>, Vec<Vector3<f64>>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let scene = scene(o, &mut rng);
    let noise = Normal::new(0.0, o.phase_noise.max(1e-12)).unwrap();
    let mut t = rng.random::<f64>() * 0.01;
    let mut k = 0usize;
    let mut reads = Vec::new();
    let mut truths = Vec::new();
    let mut channel = 915.25e6;
    let mut next_hop = 0.0;
    while t < o.duration {
        if o.hopping && t >= next_hop {
            channel = 902.75e6 + 0.5e6 * rng.random_range(0..50) as f64;
            next_hop += 0.2;
        }
        let a = k % scene.antennas.len();
        let p = truth(o, t);
        let d = (p - scene.antennas[a].position).norm();
        let phase = scene.ideal_phase(a, channel, d) + if o.phase_noise > 0.0 { noise.sample(&mut rng) } else { 0.0 };
        let phase = scattertrack_core::angle::wrap(phase, scene.phase_period);
        reads.push(PhaseRead { time_s: t, antenna: a, frequency_hz: channel, phase_rad: phase });
        truths.push(p);
        k += 1;
        // gamma-ish jitter around the mean interval
        t += (1.0 / o.reads_per_s) * (0.6 + 0.8 * rng.random::<f64>());
    }
    (scene, reads, truths)
}

pub fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}
