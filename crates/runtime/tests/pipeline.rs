//! The pipeline with a stand-in estimator (each window carries the channel
//! itself, so the DSP is out of the picture): order, completeness,
//! counted failures, latency, and the tracker fed correctly.

use std::time::Duration;

use nalgebra::Vector3;
use num_complex::{Complex32, Complex64};
use scattertrack_core::engine::Engine;
use scattertrack_core::scene::{Scene, SPEED_OF_LIGHT};
use scattertrack_core::track::Params;
use scattertrack_runtime::{run, ChannelEstimator, Pacing, PassThroughFusion, PerAntenna, Reply, RuntimeConfig, Workers};

fn scene() -> Scene {
    Scene::plus_helper(3, 0.0)
}

fn frequencies() -> Vec<f64> {
    (0..20).map(|k| 867.5e6 + 5e6 * k as f64).collect()
}

/// Replies of a tag moving on a line; window = the noiseless channel.
/// Every 10th reply has an empty window on every antenna (no reply seen).
fn replies(n: usize) -> (Vec<Reply>, Vec<Vector3<f64>>) {
    let s = scene();
    let tx = s.antennas[0].position;
    let mut out = Vec::new();
    let mut truth = Vec::new();
    for k in 0..n {
        let t = k as f64 / 300.0;
        let p = Vector3::new(0.3 + 0.2 * t, 1.1, 0.7);
        let windows = (1..5)
            .map(|a| {
                if k % 10 == 9 {
                    return Vec::new();
                }
                let d = (p - tx).norm() + (p - s.antennas[a].position).norm();
                frequencies()
                    .iter()
                    .map(|f| {
                        let (sn, cs) = (std::f64::consts::TAU * f * d / SPEED_OF_LIGHT).sin_cos();
                        Complex32::new(cs as f32, -sn as f32)
                    })
                    .collect()
            })
            .collect();
        out.push(Reply { tag: 0, time_s: t, tx_phase: None, windows });
        truth.push(p);
    }
    (out, truth)
}

struct PassThrough {
    delay: Duration,
}

impl ChannelEstimator for PassThrough {
    fn estimate(&mut self, _slot: usize, window: &[Complex32]) -> Option<Vec<Complex64>> {
        std::thread::sleep(self.delay);
        (!window.is_empty()).then(|| window.iter().map(|v| Complex64::new(v.re as f64, v.im as f64)).collect())
    }
}

fn config() -> RuntimeConfig {
    RuntimeConfig { tx: 0, rx: vec![1, 2, 3, 4], frequencies_hz: frequencies(), ..Default::default() }
}

#[test]
fn every_reply_comes_out_in_order_with_its_latency() {
    let (input, truth) = replies(300);
    let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
    let report = run(input, |_| PerAntenna(PassThrough { delay: Duration::from_micros(50) }), &mut PassThroughFusion, &mut engine, &config());
    assert_eq!(report.outputs.len(), 300);
    assert!(report.outputs.iter().enumerate().all(|(i, o)| o.index == i as u64));
    assert_eq!(report.no_channel, 30, "every 10th reply has no channel on any antenna");
    assert!(report.outputs.iter().all(|o| o.latency_ns > 0));
    assert!(report.latency_percentile_ns(0.99) >= report.latency_percentile_ns(0.5));
    // The tracker saw the frames in order and converged on the line.
    let last = report.outputs.iter().rev().find_map(|o| o.estimate.clone()).expect("estimates");
    let p = truth[299];
    let err = ((last.position[0] - p.x).powi(2) + (last.position[1] - p.y).powi(2) + (last.position[2] - p.z).powi(2)).sqrt();
    assert!(err < 0.02, "{err}");
    assert_eq!(engine.stats(0).measurements, 270);
}

#[test]
fn recorded_pacing_takes_the_recording_time() {
    let (input, _) = replies(60); // 0.2 s of replies
    let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
    let cfg = RuntimeConfig { pacing: Pacing::Recorded { speed: 1.0 }, workers: Workers::PerAntenna(1), ..config() };
    let report = run(input, |_| PerAntenna(PassThrough { delay: Duration::ZERO }), &mut PassThroughFusion, &mut engine, &cfg);
    assert_eq!(report.outputs.len(), 60);
    // 59 intervals of 1/300 s: the run cannot be faster than the recording.
    assert!(report.wall_s >= 59.0 / 300.0 * 0.95, "{}", report.wall_s);
}


#[test]
fn shared_and_per_antenna_pools_give_the_same_track() {
    let (input, _) = replies(120);
    let mut outputs = Vec::new();
    for workers in [Workers::Shared(1), Workers::Shared(3), Workers::PerAntenna(1), Workers::PerAntenna(2), Workers::Team(1), Workers::Team(2), Workers::Team(5)] {
        let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
        let cfg = RuntimeConfig { workers, ..config() };
        let report =
            run(input.clone(), |_| PerAntenna(PassThrough { delay: Duration::ZERO }), &mut PassThroughFusion, &mut engine, &cfg);
        assert_eq!(report.outputs.len(), 120);
        outputs.push(report.outputs.iter().map(|o| o.estimate.as_ref().map(|e| e.position)).collect::<Vec<_>>());
    }
    assert!(outputs.windows(2).all(|w| w[0] == w[1]));
}

/// Slow on every third reply's first antenna, so later replies finish
/// before earlier ones.
struct Uneven;

impl scattertrack_runtime::AntennaWorker for Uneven {
    type Output = Option<Vec<Complex64>>;
    fn process(&mut self, slot: usize, reply: &Reply) -> Self::Output {
        if slot == 0 && (reply.time_s * 300.0).round() as u64 % 3 == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
        let window = &reply.windows[slot];
        (!window.is_empty()).then(|| window.iter().map(|v| Complex64::new(v.re as f64, v.im as f64)).collect())
    }
}

#[test]
fn team_releases_in_capture_order_when_later_replies_finish_first() {
    let (input, _) = replies(60);
    let mut reference = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
    let expected = run(input.clone(), |_| Uneven, &mut PassThroughFusion, &mut reference, &config());
    for (workers, depth) in [(3, 64), (2, 1), (4, 2)] {
        let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
        let cfg = RuntimeConfig { workers: Workers::Team(workers), queue_depth: depth, ..config() };
        let report = run(input.clone(), |_| Uneven, &mut PassThroughFusion, &mut engine, &cfg);
        assert_eq!(report.outputs.len(), 60);
        assert!(report.outputs.iter().enumerate().all(|(i, o)| o.index == i as u64 && o.time_s == input[i].time_s));
        assert_eq!(report.no_channel, 6);
        assert_eq!(engine.stats(0).measurements, 54);
        let positions = |r: &scattertrack_runtime::RunReport| r.outputs.iter().map(|o| o.estimate.as_ref().map(|e| e.position)).collect::<Vec<_>>();
        assert_eq!(positions(&report), positions(&expected), "team({workers}), depth {depth}");
        assert_eq!(report.stage_ns.len(), 60);
    }
}

#[test]
fn team_with_prewake_keeps_the_recording_time() {
    let (input, _) = replies(60);
    for prewake in [Duration::ZERO, Duration::from_micros(500)] {
        let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
        let cfg = RuntimeConfig { pacing: Pacing::Recorded { speed: 1.0 }, workers: Workers::Team(2), prewake, ..config() };
        let report = run(input.clone(), |_| PerAntenna(PassThrough { delay: Duration::ZERO }), &mut PassThroughFusion, &mut engine, &cfg);
        assert_eq!(report.outputs.len(), 60);
        assert!(report.wall_s >= 59.0 / 300.0 * 0.95, "{}", report.wall_s);
    }
}

#[test]
fn team_without_antennas_still_outputs_every_reply() {
    let (input, _) = replies(5);
    let mut engine = Engine::new(scene(), "turbotrack", Params::default()).unwrap();
    let cfg = RuntimeConfig { workers: Workers::Team(2), rx: vec![], ..config() };
    let report = run(input, |_| PerAntenna(PassThrough { delay: Duration::ZERO }), &mut PassThroughFusion, &mut engine, &cfg);
    assert_eq!(report.outputs.len(), 5);
    assert_eq!(report.no_channel, 5);
}
