//! The pipeline: threads, bounded queues, in-order fusion, latency.

use std::collections::BTreeMap;
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use num_complex::{Complex32, Complex64};
use scattertrack_core::engine::Engine;
use scattertrack_core::track::{Estimate, Measurement, WidebandFrame};

/// One tag reply as captured: the IQ window of every receive antenna.
#[derive(Debug, Clone)]
pub struct Reply {
    /// Dense tag index (the caller's EPC → index map).
    pub tag: usize,
    /// Reply time on the recording's clock, s (frame time of the output).
    pub time_s: f64,
    /// One IQ window per receive antenna, in `RuntimeConfig::rx` order.
    pub windows: Vec<Vec<Complex32>>,
}

/// Channel estimation for one receive antenna's window of one reply
/// (the helper's DSP, thesis ch. 4): the calibrated tag channel at
/// `RuntimeConfig::frequencies_hz`, or None when no reply is detected.
/// One instance per worker thread (it may keep FFT plans and buffers).
pub trait ChannelEstimator: Send {
    fn estimate(&mut self, rx_slot: usize, window: &[Complex32]) -> Option<Vec<Complex64>>;
}

/// How fast capture hands replies to the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Each reply as soon as the pipeline accepts it (throughput test).
    AsFastAsPossible,
    /// At the recording's own timing, `speed` × real time (1 = live).
    Recorded { speed: f64 },
}

/// Pipeline shape and the helper's geometry.
#[derive(Debug, Clone)]
pub struct RuntimeConfig {
    /// Worker threads per receive antenna (thesis: a pool of two).
    pub workers_per_antenna: usize,
    /// Replies that may wait per antenna queue before capture blocks.
    pub queue_depth: usize,
    pub pacing: Pacing,
    /// Transmit antenna index in the engine's scene.
    pub tx: usize,
    /// Receive antenna indices in the scene, one per window slot.
    pub rx: Vec<usize>,
    /// Subcarrier frequencies of the estimated channels, Hz.
    pub frequencies_hz: Vec<f64>,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self { workers_per_antenna: 2, queue_depth: 64, pacing: Pacing::AsFastAsPossible, tx: 0, rx: Vec::new(), frequencies_hz: Vec::new() }
    }
}

/// What the pipeline produced for one reply.
#[derive(Debug, Clone)]
pub struct Output {
    /// Capture order of the reply (0, 1, ...).
    pub index: u64,
    pub tag: usize,
    pub time_s: f64,
    /// The tracker's estimate (None while initialising, or when declined).
    pub estimate: Option<Estimate>,
    /// Receive antennas whose channel was estimated.
    pub receivers: usize,
    /// From the reply's arrival to this output, ns.
    pub latency_ns: u64,
}

/// Everything a run produced, with its throughput and latency.
#[derive(Debug, Clone, Default)]
pub struct RunReport {
    pub outputs: Vec<Output>,
    /// Wall clock from the first arrival to the last output, s.
    pub wall_s: f64,
    /// Replies where no receive antenna detected the tag (counted, passed
    /// to no tracker).
    pub no_channel: u64,
}

impl RunReport {
    /// Replies processed per second of wall clock.
    pub fn frames_per_s(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.outputs.len() as f64 / self.wall_s
        } else {
            0.0
        }
    }

    /// The `q`-quantile (0–1) of the per-reply latency, ns (nearest rank).
    pub fn latency_percentile_ns(&self, q: f64) -> f64 {
        let mut l: Vec<u64> = self.outputs.iter().map(|o| o.latency_ns).collect();
        if l.is_empty() {
            return 0.0;
        }
        l.sort_unstable();
        let rank = ((q.clamp(0.0, 1.0) * l.len() as f64).ceil() as usize).clamp(1, l.len());
        l[rank - 1] as f64
    }
}

struct Job {
    index: u64,
    slot: usize,
    reply: Arc<Reply>,
}

enum Event {
    /// Capture announces a reply (so fusion knows how many results to await).
    Arrived { index: u64, tag: usize, time_s: f64, arrival: Instant },
    /// A worker's channel estimate for one antenna.
    Estimated { index: u64, slot: usize, channel: Option<Vec<Complex64>> },
}

struct Pending {
    tag: usize,
    time_s: f64,
    arrival: Option<Instant>,
    channels: Vec<Option<Vec<Complex64>>>,
    done: usize,
}

/// Runs the pipeline over `replies` with one estimator per worker (from
/// `make_estimator`, called with the antenna slot) and the tracker(s) in
/// `engine`; returns when every reply has an output.
pub fn run<I, F>(replies: I, make_estimator: F, engine: &mut Engine, config: &RuntimeConfig) -> RunReport
where
    I: IntoIterator<Item = Reply>,
    I::IntoIter: Send,
    F: Fn(usize) -> Box<dyn ChannelEstimator>,
{
    let antennas = config.rx.len();
    let workers = config.workers_per_antenna.max(1);
    let (events_tx, events_rx) = channel::<Event>();
    let mut queues: Vec<std::sync::mpsc::SyncSender<Job>> = Vec::with_capacity(antennas);
    let mut worker_inputs: Vec<Arc<Mutex<Receiver<Job>>>> = Vec::with_capacity(antennas);
    for _ in 0..antennas {
        let (q_tx, q_rx) = sync_channel::<Job>(config.queue_depth.max(1));
        queues.push(q_tx);
        worker_inputs.push(Arc::new(Mutex::new(q_rx)));
    }
    let estimators: Vec<Vec<Box<dyn ChannelEstimator>>> =
        (0..antennas).map(|slot| (0..workers).map(|_| make_estimator(slot)).collect()).collect();
    let replies = replies.into_iter();
    let pacing = config.pacing;
    std::thread::scope(|scope| {
        // Workers: k per antenna, each pulling from its antenna's queue.
        for (slot, pool) in estimators.into_iter().enumerate() {
            for mut estimator in pool {
                let input = Arc::clone(&worker_inputs[slot]);
                let events = events_tx.clone();
                scope.spawn(move || loop {
                    let job = {
                        let guard = input.lock().expect("worker queue poisoned");
                        guard.recv()
                    };
                    let Ok(job) = job else { break };
                    let channel = estimator.estimate(job.slot, &job.reply.windows[job.slot]);
                    if events.send(Event::Estimated { index: job.index, slot: job.slot, channel }).is_err() {
                        break;
                    }
                });
            }
        }
        drop(worker_inputs);
        // Capture: paces the replies and fans each out to the antenna queues.
        let capture_events = events_tx.clone();
        scope.spawn(move || capture(replies, queues, capture_events, pacing));
        drop(events_tx);
        fuse_and_track(events_rx, engine, config)
    })
}

fn capture<I: Iterator<Item = Reply>>(replies: I, queues: Vec<std::sync::mpsc::SyncSender<Job>>, events: Sender<Event>, pacing: Pacing) {
    let start = Instant::now();
    let mut first_time: Option<f64> = None;
    for (index, reply) in replies.enumerate() {
        let index = index as u64;
        if let Pacing::Recorded { speed } = pacing {
            let t0 = *first_time.get_or_insert(reply.time_s);
            let due = Duration::from_secs_f64(((reply.time_s - t0) / speed.max(1e-9)).max(0.0));
            let elapsed = start.elapsed();
            if due > elapsed {
                std::thread::sleep(due - elapsed);
            }
        }
        let reply = Arc::new(reply);
        let arrival = Instant::now();
        if events.send(Event::Arrived { index, tag: reply.tag, time_s: reply.time_s, arrival }).is_err() {
            return;
        }
        for (slot, queue) in queues.iter().enumerate() {
            if queue.send(Job { index, slot, reply: Arc::clone(&reply) }).is_err() {
                return;
            }
        }
    }
}

/// Collects every antenna's estimate of a reply, releases replies in
/// capture order (the tracker is causal: frames must arrive in time order),
/// steps the engine and stamps the latency.
fn fuse_and_track(events: Receiver<Event>, engine: &mut Engine, config: &RuntimeConfig) -> RunReport {
    let antennas = config.rx.len();
    let mut pending: BTreeMap<u64, Pending> = BTreeMap::new();
    let mut next: u64 = 0;
    let mut report = RunReport::default();
    let mut first_arrival: Option<Instant> = None;
    for event in events {
        match event {
            Event::Arrived { index, tag, time_s, arrival } => {
                first_arrival.get_or_insert(arrival);
                let p = pending.entry(index).or_insert_with(|| Pending {
                    tag,
                    time_s,
                    arrival: None,
                    channels: vec![None; antennas],
                    done: 0,
                });
                p.tag = tag;
                p.time_s = time_s;
                p.arrival = Some(arrival);
            }
            Event::Estimated { index, slot, channel } => {
                let p = pending.entry(index).or_insert_with(|| Pending {
                    tag: 0,
                    time_s: f64::NAN,
                    arrival: None,
                    channels: vec![None; antennas],
                    done: 0,
                });
                p.channels[slot] = channel;
                p.done += 1;
            }
        }
        // Release every complete reply at the head, in order.
        while pending.get(&next).is_some_and(|p| p.done == antennas && p.arrival.is_some()) {
            let p = pending.remove(&next).expect("present");
            let mut rx = Vec::with_capacity(antennas);
            let mut h = Vec::with_capacity(antennas * config.frequencies_hz.len());
            for (slot, channel) in p.channels.into_iter().enumerate() {
                if let Some(c) = channel {
                    if c.len() == config.frequencies_hz.len() {
                        rx.push(config.rx[slot]);
                        h.extend(c.into_iter().map(|v| nalgebra::Complex::new(v.re, v.im)));
                    }
                }
            }
            let receivers = rx.len();
            let estimate = if receivers == 0 {
                report.no_channel += 1;
                None
            } else {
                let frame = WidebandFrame { time_s: p.time_s, tx: config.tx, rx, frequencies_hz: config.frequencies_hz.clone(), h };
                engine.step(p.tag, &Measurement::Wideband(frame))
            };
            let arrival = p.arrival.expect("checked");
            report.outputs.push(Output {
                index: next,
                tag: p.tag,
                time_s: p.time_s,
                estimate,
                receivers,
                latency_ns: arrival.elapsed().as_nanos() as u64,
            });
            next += 1;
        }
    }
    report.wall_s = first_arrival.map_or(0.0, |t| t.elapsed().as_secs_f64());
    report
}
