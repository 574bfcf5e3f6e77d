//! GLAC on simulated reads: accuracy and convergence in paper-like
//! conditions (σφ = 0.1 rad, ~30 reads/s, one channel), and with hopping,
//! a negative phase sign and a mod-π reader.

mod common;

use common::{percentile, simulate, Options};
use scattertrack_core::track::{make, GlacParams};

fn run(o: &Options, seed: u64, method: &str) -> (f64, f64, f64) {
    let (scene, reads, truths) = simulate(o, seed);
    let mut tracker = make(method, &scene, &GlacParams::default()).unwrap();
    let mut errors = Vec::new();
    let mut first = f64::NAN;
    let mut last_bad = 0.0;
    for (m, p) in reads.iter().zip(&truths) {
        if let Some(e) = tracker.step(m) {
            if first.is_nan() {
                first = m.time_s;
            }
            let err = ((e.position[0] - p.x).powi(2) + (e.position[1] - p.y).powi(2) + (e.position[2] - p.z).powi(2)).sqrt();
            if err > 0.02 {
                last_bad = m.time_s;
            }
            errors.push(err);
        }
    }
    assert!(!errors.is_empty(), "no estimates");
    (percentile(errors.clone(), 0.5), percentile(errors, 0.9), last_bad)
}

#[test]
fn glac_3d_and_2d_paper_conditions() {
    for (dims, speed) in [(3, 0.1), (2, 0.1), (2, 0.4), (3, 0.3)] {
        let o = Options { dimensions: dims, speed, ..Default::default() };
        for seed in 0..5 {
            let (med, p90, conv) = run(&o, seed, "glac");
            eprintln!("{dims}D {speed} m/s seed {seed}: median {:.2} mm p90 {:.2} mm converged {:.2} s", med * 1e3, p90 * 1e3, conv);
        }
    }
}
