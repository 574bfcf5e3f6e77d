//! GLAC on simulated reads (the small simulator in `common`): accuracy in
//! paper-like conditions (σφ = 0.1 rad, ~30 reads/s, one channel), and
//! with hopping, a negative phase sign and a mod-π reader.

mod common;

use common::{percentile, simulate, Options};
use scattertrack_core::track::{make, GlacParams};

/// Median 3D error (m) of the estimates after `settle_s` seconds.
fn median_error(o: &Options, seed: u64, settle_s: f64) -> f64 {
    let (scene, reads, truths) = simulate(o, seed);
    let mut tracker = make("glac", &scene, &GlacParams::default().into()).unwrap();
    let mut errors = Vec::new();
    for (m, p) in reads.iter().zip(&truths) {
        if let Some(e) = tracker.step(&(*m).into()) {
            if m.time_s > settle_s {
                let d = ((e.position[0] - p.x).powi(2) + (e.position[1] - p.y).powi(2) + (e.position[2] - p.z).powi(2)).sqrt();
                errors.push(d);
            }
        }
    }
    assert!(!errors.is_empty(), "no estimates");
    percentile(errors, 0.5)
}

#[test]
fn paper_conditions_2d_and_3d() {
    for (dimensions, speed, settle, bound) in [(2, 0.1, 0.0, 0.008), (2, 0.4, 0.0, 0.008), (3, 0.1, 3.0, 0.012), (3, 0.3, 3.0, 0.012)] {
        let o = Options { dimensions, speed, ..Default::default() };
        for seed in 0..3 {
            let med = median_error(&o, seed, settle);
            assert!(med < bound, "{dimensions}D {speed} m/s seed {seed}: median {:.1} mm", med * 1e3);
        }
    }
}

#[test]
fn hopping_negative_sign_and_mod_pi() {
    let cases = [
        Options { dimensions: 2, speed: 0.3, hopping: true, ..Default::default() },
        Options { dimensions: 2, speed: 0.3, phase_sign: -1.0, ..Default::default() },
        Options { dimensions: 2, speed: 0.3, mod_pi: true, ..Default::default() },
    ];
    for (k, o) in cases.iter().enumerate() {
        let med = median_error(o, 11 + k as u64, 1.0);
        assert!(med < 0.008, "case {k}: median {:.1} mm", med * 1e3);
    }
}
