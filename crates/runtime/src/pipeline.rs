//! The pipeline: threads, bounded queues, in-order fusion, latency.

use std::collections::{BTreeMap, VecDeque};
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
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
    /// Index of the windows' first sample in the transmitter's sample
    /// stream modulo `N` (tx and rx share one clock), when recorded.
    pub tx_phase: Option<usize>,
    /// One IQ window per receive antenna, in `RuntimeConfig::rx` order.
    pub windows: Vec<Vec<Complex32>>,
}

/// The per-antenna stage (thesis §6: a worker pool per receive antenna):
/// whatever one antenna's window alone allows — for the helper's DSP the
/// symbol timing, the symbols' prefix sums and the detection feature, most
/// of the cost. One instance per worker thread (it may keep FFT plans and
/// buffers).
pub trait AntennaWorker: Send {
    /// What one antenna's window becomes (sent to the fusion stage).
    type Output: Send;
    /// Processes antenna `slot`'s window of `reply`.
    fn process(&mut self, slot: usize, reply: &Reply) -> Self::Output;
}

/// The joint stage, on the fusion thread: the per-antenna outputs of one
/// reply (in slot order) → the calibrated tag channel of each receive
/// antenna at `RuntimeConfig::frequencies_hz` (None where it could not be
/// estimated), or the reason the whole reply is declined (counted).
pub trait ReplyFusion<T> {
    fn fuse(&mut self, reply: &ReplyHeader, antennas: Vec<T>) -> Result<Vec<Option<Vec<Complex64>>>, String>;
}

/// What fusion knows of a reply besides its antennas' outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplyHeader {
    pub index: u64,
    pub tag: usize,
    pub time_s: f64,
    pub tx_phase: Option<usize>,
}

/// Channel estimation antenna by antenna, nothing joint: each worker
/// returns its antenna's channel and fusion passes them through.
pub trait ChannelEstimator: Send {
    fn estimate(&mut self, rx_slot: usize, window: &[Complex32]) -> Option<Vec<Complex64>>;
}

/// Adapts a [`ChannelEstimator`] to an [`AntennaWorker`].
pub struct PerAntenna<E>(pub E);

impl<E: ChannelEstimator> AntennaWorker for PerAntenna<E> {
    type Output = Option<Vec<Complex64>>;
    fn process(&mut self, slot: usize, reply: &Reply) -> Self::Output {
        self.0.estimate(slot, &reply.windows[slot])
    }
}

/// The fusion of independent per-antenna channels: passes them through.
pub struct PassThroughFusion;

impl ReplyFusion<Option<Vec<Complex64>>> for PassThroughFusion {
    fn fuse(&mut self, _reply: &ReplyHeader, antennas: Vec<Option<Vec<Complex64>>>) -> Result<Vec<Option<Vec<Complex64>>>, String> {
        Ok(antennas)
    }
}

/// Where capture takes replies from. Split in two so that a replay source
/// can wait for a reply's due time *before* loading its samples: loading
/// (reading and converting half a megabyte) right after the previous
/// dispatch would compete for the cores with that reply's workers.
pub trait ReplySource: Send {
    /// Recording time of the next reply, s (None when done), without
    /// loading it.
    fn next_time(&mut self) -> Option<f64>;
    /// The next reply, loaded.
    fn next_reply(&mut self) -> Option<Reply>;
}

/// A [`ReplySource`] over replies already in memory.
pub struct InMemory<I: Iterator<Item = Reply>>(std::iter::Peekable<I>);

impl<I: Iterator<Item = Reply>> InMemory<I> {
    pub fn new(replies: impl IntoIterator<IntoIter = I>) -> Self {
        Self(replies.into_iter().peekable())
    }
}

impl<I: Iterator<Item = Reply> + Send> ReplySource for InMemory<I> {
    fn next_time(&mut self) -> Option<f64> {
        self.0.peek().map(|r| r.time_s)
    }

    fn next_reply(&mut self) -> Option<Reply> {
        self.0.next()
    }
}

/// How fast capture hands replies to the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Each reply as soon as the pipeline accepts it (throughput test).
    AsFastAsPossible,
    /// At the recording's own timing, `speed` × real time (1 = live).
    Recorded { speed: f64 },
}

/// How antenna jobs are spread over worker threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Workers {
    /// One queue and `k` threads per receive antenna (the thesis's layout,
    /// §6: a pool per antenna). The default, with `k = 1`: every antenna's
    /// job of a reply is handed to its own waiting thread at once.
    PerAntenna(usize),
    /// One queue of every antenna's jobs, in reply order, and `k` threads
    /// taking any job. Fewer threads than antennas when cores are few; but
    /// measured on 2 cores (4 rx, 300 replies/s) its latency was worse
    /// (p50 1.22 ms against 0.97–1.03 ms per antenna): the threads wake one
    /// after the other through the queue's lock.
    Shared(usize),
    /// `k` threads in all (best: one per core), capture being one of them,
    /// that take the antenna jobs of the oldest reply with jobs left;
    /// whichever finishes a reply's last antenna runs fusion and the
    /// tracker itself, in reply order (one thread at a time). No fusion
    /// thread, so no hand-off wake-up on the critical path; capture starts
    /// the first job of the reply it hands over without a wake-up; and no
    /// more threads than cores, so a reply's jobs are not time-sliced
    /// against each other.
    Team(usize),
}

/// Pipeline shape and the helper's geometry.
#[derive(Debug, Clone)]
pub struct RuntimeConfig {
    /// Worker threads and their queues (default one per antenna).
    pub workers: Workers,
    /// Replies that may wait per queue before capture blocks.
    pub queue_depth: usize,
    pub pacing: Pacing,
    /// Transmit antenna index in the engine's scene.
    pub tx: usize,
    /// Receive antenna indices in the scene, one per window slot.
    pub rx: Vec<usize>,
    /// Subcarrier frequencies of the estimated channels, Hz.
    pub frequencies_hz: Vec<f64>,
    /// [`Workers::Team`] with [`Pacing::Recorded`]: how long before a
    /// reply is due capture wakes the idle workers, which then poll for it
    /// (at most twice this long) instead of sleeping, and capture polls
    /// too. Why: a sleeping thread took up to 0.3–0.5 ms to wake on the
    /// 2-core virtual machine, more than an antenna's job (measured: with
    /// 0.3 ms the last job of a reply still started 0.49 ms after arrival
    /// at p50, with 0.5 ms 0.19 ms). A live helper knows as early when a
    /// reply is due: it opens the window on the reader's query. The price
    /// is polling: up to 2 × this per reply in all threads. Zero: workers
    /// sleep until a reply arrives. Default 1 ms: 0.5 ms still let a few
    /// replies in a hundred wait for a late worker (p99 of the last job's
    /// start 0.32–0.49 ms against 0.31–0.34 ms).
    pub prewake: Duration,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            workers: Workers::PerAntenna(1),
            queue_depth: 64,
            pacing: Pacing::AsFastAsPossible,
            tx: 0,
            rx: Vec::new(),
            frequencies_hz: Vec::new(),
            prewake: Duration::from_micros(1000),
        }
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
    /// Replies the fusion stage declined, by reason (counted, passed to no
    /// tracker; also in `no_channel`).
    pub declined: BTreeMap<String, u64>,
    /// Where each reply's latency went, ns (capture order), see [`STAGES`]:
    /// arrival → the last antenna worker starting it (queueing and thread
    /// wake-up), the slowest worker's processing, the last worker's result
    /// → fusion starting it (hand-off, waiting for earlier replies), fusion,
    /// tracker.
    pub stage_ns: Vec<[u64; 5]>,
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
        percentile(self.outputs.iter().map(|o| o.latency_ns).collect(), q)
    }

    /// The `q`-quantile of stage `stage` (an index into [`STAGES`]), ns.
    pub fn stage_percentile_ns(&self, stage: usize, q: f64) -> f64 {
        percentile(self.stage_ns.iter().map(|s| s[stage.min(STAGES.len() - 1)]).collect(), q)
    }
}

/// The parts of a reply's latency in [`RunReport::stage_ns`].
pub const STAGES: [&str; 5] = ["dispatch", "antenna", "hand-off", "fusion", "tracker"];

/// Nearest-rank quantile of `values` (0 when empty).
fn percentile(mut values: Vec<u64>, q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_unstable();
    let rank = ((q.clamp(0.0, 1.0) * values.len() as f64).ceil() as usize).clamp(1, values.len());
    values[rank - 1] as f64
}

struct Job {
    index: u64,
    slot: usize,
    reply: Arc<Reply>,
}

enum Event<T> {
    /// Capture announces a reply (so fusion knows how many results to await).
    Arrived { header: ReplyHeader, arrival: Instant },
    /// A worker's output for one antenna: when it started and finished.
    Processed { index: u64, slot: usize, output: T, started: Instant, finished: Instant },
}

struct Pending<T> {
    header: Option<ReplyHeader>,
    arrival: Option<Instant>,
    outputs: Vec<Option<T>>,
    done: usize,
    /// Latest worker start, longest worker run, latest worker finish.
    last_start: Option<Instant>,
    busy_ns: u64,
    last_finish: Option<Instant>,
}

impl<T> Pending<T> {
    /// Antenna `slot`'s output, processed from `started` to `finished`.
    fn record(&mut self, slot: usize, output: T, started: Instant, finished: Instant) {
        self.outputs[slot] = Some(output);
        self.done += 1;
        self.last_start = Some(self.last_start.map_or(started, |t| t.max(started)));
        self.last_finish = Some(self.last_finish.map_or(finished, |t| t.max(finished)));
        self.busy_ns = self.busy_ns.max(finished.duration_since(started).as_nanos() as u64);
    }

    fn new(antennas: usize) -> Self {
        Self {
            header: None,
            arrival: None,
            outputs: (0..antennas).map(|_| None).collect(),
            done: 0,
            last_start: None,
            busy_ns: 0,
            last_finish: None,
        }
    }
}

/// Runs the pipeline over `replies` with one worker per thread (from
/// `make_worker`, called with the thread's index; a worker must handle any
/// antenna slot), `fusion` and the tracker(s) in `engine` on the calling
/// thread; returns when every reply has an output.
pub fn run<I, W, F, U>(replies: I, make_worker: F, fusion: &mut U, engine: &mut Engine, config: &RuntimeConfig) -> RunReport
where
    I: IntoIterator<Item = Reply>,
    I::IntoIter: Send,
    W: AntennaWorker,
    F: Fn(usize) -> W,
    U: ReplyFusion<W::Output> + Send,
{
    run_source(InMemory::new(replies), make_worker, fusion, engine, config)
}

/// [`run`] over any [`ReplySource`] (e.g. [`crate::source::IqFileReplies`]).
pub fn run_source<S, W, F, U>(replies: S, make_worker: F, fusion: &mut U, engine: &mut Engine, config: &RuntimeConfig) -> RunReport
where
    S: ReplySource,
    W: AntennaWorker,
    F: Fn(usize) -> W,
    U: ReplyFusion<W::Output> + Send,
{
    let antennas = config.rx.len();
    let (queue_count, per_queue) = match config.workers {
        Workers::PerAntenna(k) => (antennas.max(1), k.max(1)),
        Workers::Shared(k) => (1, k.max(1)),
        Workers::Team(k) => return run_team(replies, (0..k.max(1)).map(make_worker).collect(), fusion, engine, config),
    };
    let (events_tx, events_rx) = channel::<Event<W::Output>>();
    let mut queues: Vec<std::sync::mpsc::SyncSender<Job>> = Vec::with_capacity(queue_count);
    let mut worker_inputs: Vec<Arc<Mutex<Receiver<Job>>>> = Vec::with_capacity(queue_count);
    for _ in 0..queue_count {
        // Shared: one queue holds every antenna's jobs.
        let depth = config.queue_depth.max(1) * if queue_count == 1 { antennas.max(1) } else { 1 };
        let (q_tx, q_rx) = sync_channel::<Job>(depth);
        queues.push(q_tx);
        worker_inputs.push(Arc::new(Mutex::new(q_rx)));
    }
    let pools: Vec<Vec<W>> =
        (0..queue_count).map(|q| (0..per_queue).map(|i| make_worker(q * per_queue + i)).collect()).collect();
    let pacing = config.pacing;
    std::thread::scope(|scope| {
        // Workers: each pulls jobs from its queue.
        for (q, pool) in pools.into_iter().enumerate() {
            for mut worker in pool {
                let input = Arc::clone(&worker_inputs[q]);
                let events = events_tx.clone();
                scope.spawn(move || loop {
                    let job = {
                        let guard = input.lock().expect("worker queue poisoned");
                        guard.recv()
                    };
                    let Ok(job) = job else { break };
                    let started = Instant::now();
                    let output = worker.process(job.slot, &job.reply);
                    let finished = Instant::now();
                    if events.send(Event::Processed { index: job.index, slot: job.slot, output, started, finished }).is_err() {
                        break;
                    }
                });
            }
        }
        drop(worker_inputs);
        // Capture: paces the replies and fans each out to the queues.
        let capture_events = events_tx.clone();
        scope.spawn(move || capture(replies, antennas, queues, capture_events, pacing));
        drop(events_tx);
        fuse_and_track(events_rx, fusion, engine, config)
    })
}

/// When a paced capture hands each reply over: the recording's time since
/// its first reply, divided by the speed, from the moment capture started.
struct ReplayClock {
    start: Instant,
    /// Recording time of the first reply, s.
    first: Option<f64>,
    pacing: Pacing,
}

impl ReplayClock {
    fn new(pacing: Pacing) -> Self {
        Self { start: Instant::now(), first: None, pacing }
    }

    /// Reply at recording time `time_s` (s) is due this long after `start`
    /// (None: as fast as possible).
    fn due(&mut self, time_s: f64) -> Option<Duration> {
        let Pacing::Recorded { speed } = self.pacing else { return None };
        let t0 = *self.first.get_or_insert(time_s);
        Some(Duration::from_secs_f64(((time_s - t0) / speed.max(1e-9)).max(0.0)))
    }
}

fn capture<S: ReplySource, T>(
    mut replies: S,
    antennas: usize,
    queues: Vec<std::sync::mpsc::SyncSender<Job>>,
    events: Sender<Event<T>>,
    pacing: Pacing,
) {
    let mut clock = ReplayClock::new(pacing);
    let mut index = 0u64;
    while let Some(time_s) = replies.next_time() {
        if let Some(due) = clock.due(time_s) {
            let elapsed = clock.start.elapsed();
            if due > elapsed {
                std::thread::sleep(due - elapsed);
            }
        }
        let Some(reply) = replies.next_reply() else { break };
        let reply = Arc::new(reply);
        let arrival = Instant::now();
        let header = ReplyHeader { index, tag: reply.tag, time_s: reply.time_s, tx_phase: reply.tx_phase };
        if events.send(Event::Arrived { header, arrival }).is_err() {
            return;
        }
        for slot in 0..antennas {
            let queue = &queues[slot % queues.len()];
            if queue.send(Job { index, slot, reply: Arc::clone(&reply) }).is_err() {
                return;
            }
        }
        index += 1;
    }
}

/// A reply in flight in [`Workers::Team`]: its antenna jobs handed out so
/// far and its outputs.
struct InFlight<T> {
    index: u64,
    reply: Arc<Reply>,
    claimed: usize,
    pending: Pending<T>,
}

/// What the team's threads share under one lock: the replies in flight, in
/// capture order (contiguous indices; the front is the next to release).
struct Team<T> {
    replies: VecDeque<InFlight<T>>,
    /// Bumped by every reply handed over and every pre-wake.
    generation: u64,
    /// Bumped by every pre-wake.
    prewakes: u64,
    /// Capture has no more replies.
    closed: bool,
}

impl<T> Team<T> {
    fn head_complete(&self, antennas: usize) -> bool {
        self.replies.front().is_some_and(|r| r.pending.done == antennas)
    }
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().expect("pipeline state poisoned")
}

/// What [`Workers::Team`]'s threads share.
struct TeamShared<'a, T, U> {
    antennas: usize,
    state: Mutex<Team<T>>,
    /// Workers wait here for jobs.
    work: Condvar,
    /// Capture waits here for room (at most `queue_depth` replies in flight).
    space: Condvar,
    release: Mutex<Release<'a, U>>,
    /// Replies handed over so far (read without the lock while polling).
    handed: AtomicU64,
    /// Longest poll after a pre-wake.
    poll: Duration,
}

impl<T, U: ReplyFusion<T>> TeamShared<'_, T, U> {
    /// The next antenna job, oldest reply first; with `wait`, blocks until
    /// there is one (None once capture closed and no job is left). A
    /// pre-wake turns the wait into polling for the next hand-over.
    fn claim(&self, wait: bool) -> Option<(u64, usize, Arc<Reply>)> {
        let mut state = lock(&self.state);
        loop {
            if let Some(r) = state.replies.iter_mut().find(|r| r.claimed < self.antennas) {
                r.claimed += 1;
                return Some((r.index, r.claimed - 1, Arc::clone(&r.reply)));
            }
            if state.closed || !wait {
                return None;
            }
            let (generation, prewakes) = (state.generation, state.prewakes);
            state = self.work.wait_while(state, |s| s.generation == generation && !s.closed).expect("pipeline state poisoned");
            if state.prewakes != prewakes && state.replies.iter().all(|r| r.claimed >= self.antennas) && !state.closed {
                // Pre-woken: poll, without the lock, for the reply.
                let handed = self.handed.load(Ordering::Acquire);
                drop(state);
                let since = Instant::now();
                while self.handed.load(Ordering::Acquire) == handed && since.elapsed() < self.poll {
                    std::hint::spin_loop();
                }
                state = lock(&self.state);
            }
        }
    }

    /// Wakes the idle workers to poll for a reply about to arrive.
    fn prewake(&self) {
        let mut state = lock(&self.state);
        state.generation += 1;
        state.prewakes += 1;
        drop(state);
        self.work.notify_all();
    }

    /// Runs one claimed job on `worker`, records it and, when it completed
    /// the head reply, releases what is complete.
    fn run<W: AntennaWorker<Output = T>>(&self, worker: &mut W, (index, slot, reply): (u64, usize, Arc<Reply>)) {
        let started = Instant::now();
        let output = worker.process(slot, &reply);
        let finished = Instant::now();
        drop(reply);
        let complete = {
            let mut state = lock(&self.state);
            let front = state.replies.front().map_or(index, |r| r.index);
            state.replies[(index - front) as usize].pending.record(slot, output, started, finished);
            state.head_complete(self.antennas)
        };
        if complete {
            self.drain();
        }
    }

    /// Releases complete replies at the head, in order. Whoever holds
    /// `release` drains; a thread finding it held leaves, and the holder
    /// looks again after letting go, so a head completed meanwhile is not
    /// stranded.
    fn drain(&self) {
        while let Ok(mut out) = self.release.try_lock() {
            loop {
                let head = {
                    let mut state = lock(&self.state);
                    if !state.head_complete(self.antennas) {
                        break;
                    }
                    self.space.notify_one();
                    state.replies.pop_front().expect("complete head")
                };
                out.release(head.pending);
            }
            drop(out);
            if !lock(&self.state).head_complete(self.antennas) {
                break;
            }
        }
    }
}

/// [`Workers::Team`]: capture on the calling thread, which also takes jobs
/// of the reply it just handed over (its first job starts without a
/// wake-up), and `workers − 1` threads; every thread claims antenna jobs
/// oldest reply first, and the one completing the head reply releases it
/// (fusion, tracker) and any complete ones behind it.
fn run_team<S, W, U>(mut replies: S, mut workers: Vec<W>, fusion: &mut U, engine: &mut Engine, config: &RuntimeConfig) -> RunReport
where
    S: ReplySource,
    W: AntennaWorker,
    U: ReplyFusion<W::Output> + Send,
{
    let antennas = config.rx.len();
    let depth = config.queue_depth.max(1);
    let shared = TeamShared {
        antennas,
        state: Mutex::new(Team { replies: VecDeque::new(), generation: 0, prewakes: 0, closed: false }),
        work: Condvar::new(),
        space: Condvar::new(),
        release: Mutex::new(Release::new(fusion, engine, config)),
        handed: AtomicU64::new(0),
        poll: 2 * config.prewake,
    };
    let mut own = workers.pop().expect("at least one worker");
    std::thread::scope(|scope| {
        for mut worker in workers {
            let shared = &shared;
            scope.spawn(move || {
                while let Some(job) = shared.claim(true) {
                    shared.run(&mut worker, job);
                }
            });
        }
        let mut clock = ReplayClock::new(config.pacing);
        let start = clock.start;
        let mut index = 0u64;
        while let Some(time_s) = replies.next_time() {
            if let Some(due) = clock.due(time_s) {
                let elapsed = start.elapsed();
                if config.prewake.is_zero() {
                    if due > elapsed {
                        std::thread::sleep(due - elapsed);
                    }
                } else {
                    if due > elapsed + config.prewake {
                        std::thread::sleep(due - elapsed - config.prewake);
                    }
                    shared.prewake();
                    // Awake already: poll too (a second sleep could
                    // overshoot the reply's time by as much as a wake-up).
                    while start.elapsed() < due {
                        std::hint::spin_loop();
                    }
                }
            }
            let mut state = lock(&shared.state);
            while state.replies.len() >= depth {
                state = shared.space.wait(state).expect("pipeline state poisoned");
            }
            drop(state);
            let Some(reply) = replies.next_reply() else { break };
            let arrival = Instant::now();
            let mut pending = Pending::new(antennas);
            pending.header = Some(ReplyHeader { index, tag: reply.tag, time_s: reply.time_s, tx_phase: reply.tx_phase });
            pending.arrival = Some(arrival);
            if antennas == 0 {
                // Complete on arrival, and no worker would release it.
                lock(&shared.release).release(pending);
            } else {
                {
                    let mut state = lock(&shared.state);
                    state.replies.push_back(InFlight { index, reply: Arc::new(reply), claimed: 0, pending });
                    state.generation += 1;
                }
                shared.handed.fetch_add(1, Ordering::Release);
                shared.work.notify_all();
                // Help until this reply's jobs are all taken.
                while let Some(job) = shared.claim(false) {
                    shared.run(&mut own, job);
                }
            }
            index += 1;
        }
        lock(&shared.state).closed = true;
        shared.work.notify_all();
        // Jobs left when capture closed (as fast as possible): help finish.
        while let Some(job) = shared.claim(false) {
            shared.run(&mut own, job);
        }
    });
    shared.release.into_inner().expect("release poisoned").finish()
}

/// Collects every antenna's output of a reply, releases replies in
/// capture order (the tracker is causal: frames must arrive in time order),
/// fuses them, steps the engine and stamps the latency.
fn fuse_and_track<T, U: ReplyFusion<T>>(
    events: Receiver<Event<T>>,
    fusion: &mut U,
    engine: &mut Engine,
    config: &RuntimeConfig,
) -> RunReport {
    let antennas = config.rx.len();
    let mut pending: BTreeMap<u64, Pending<T>> = BTreeMap::new();
    let mut release = Release::new(fusion, engine, config);
    for event in events {
        match event {
            Event::Arrived { header, arrival } => {
                release.first_arrival.get_or_insert(arrival);
                let p = pending.entry(header.index).or_insert_with(|| Pending::new(antennas));
                p.header = Some(header);
                p.arrival = Some(arrival);
            }
            Event::Processed { index, slot, output, started, finished } => {
                pending.entry(index).or_insert_with(|| Pending::new(antennas)).record(slot, output, started, finished);
            }
        }
        // Release every complete reply at the head, in order.
        while pending.get(&release.next).is_some_and(|p| p.done == antennas && p.arrival.is_some()) {
            let p = pending.remove(&release.next).expect("present");
            release.release(p);
        }
    }
    release.finish()
}

/// The in-order end of the pipeline: fusion, tracker, latency, counts.
struct Release<'a, U> {
    fusion: &'a mut U,
    engine: &'a mut Engine,
    config: &'a RuntimeConfig,
    /// Capture index of the next reply to release.
    next: u64,
    first_arrival: Option<Instant>,
    report: RunReport,
}

impl<'a, U> Release<'a, U> {
    fn new(fusion: &'a mut U, engine: &'a mut Engine, config: &'a RuntimeConfig) -> Self {
        Self { fusion, engine, config, next: 0, first_arrival: None, report: RunReport::default() }
    }

    /// Fuses reply `self.next` (complete: every antenna done, arrived),
    /// steps the engine and records its output.
    fn release<T>(&mut self, p: Pending<T>)
    where
        U: ReplyFusion<T>,
    {
        let config = self.config;
        let antennas = config.rx.len();
        let f_count = config.frequencies_hz.len();
        let header = p.header.expect("arrived");
        let outputs: Vec<T> = p.outputs.into_iter().map(|o| o.expect("every slot done")).collect();
        let fusion_start = Instant::now();
        let arrival = p.arrival.expect("checked");
        self.first_arrival.get_or_insert(arrival);
        let dispatch_ns = p.last_start.map_or(0, |t| t.saturating_duration_since(arrival).as_nanos() as u64);
        let handoff_ns = p.last_finish.map_or(0, |t| fusion_start.saturating_duration_since(t).as_nanos() as u64);
        let fused = self.fusion.fuse(&header, outputs);
        let fusion_ns = fusion_start.elapsed().as_nanos() as u64;
        let mut rx = Vec::with_capacity(antennas);
        let mut h = Vec::with_capacity(antennas * f_count);
        match fused {
            Ok(channels) => {
                for (slot, channel) in channels.into_iter().enumerate().take(antennas) {
                    if let Some(c) = channel {
                        if c.len() == f_count && c.iter().all(|v| v.is_finite()) {
                            rx.push(config.rx[slot]);
                            h.extend(c.into_iter().map(|v| nalgebra::Complex::new(v.re, v.im)));
                        }
                    }
                }
            }
            Err(reason) => *self.report.declined.entry(reason).or_insert(0) += 1,
        }
        let receivers = rx.len();
        let track_start = Instant::now();
        let estimate = if receivers == 0 {
            self.report.no_channel += 1;
            None
        } else {
            let frame = WidebandFrame { time_s: header.time_s, tx: config.tx, rx, frequencies_hz: config.frequencies_hz.clone(), h };
            self.engine.step(header.tag, &Measurement::Wideband(frame))
        };
        let track_ns = track_start.elapsed().as_nanos() as u64;
        self.report.outputs.push(Output {
            index: self.next,
            tag: header.tag,
            time_s: header.time_s,
            estimate,
            receivers,
            latency_ns: arrival.elapsed().as_nanos() as u64,
        });
        self.report.stage_ns.push([dispatch_ns, p.busy_ns, handoff_ns, fusion_ns, track_ns]);
        self.next += 1;
    }

    fn finish(mut self) -> RunReport {
        self.report.wall_s = self.first_arrival.map_or(0.0, |t| t.elapsed().as_secs_f64());
        self.report
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use scattertrack_core::scene::{Scene, SPEED_OF_LIGHT};
    use scattertrack_core::track::Params;
    use std::sync::atomic::AtomicUsize;

    /// A helper: tx in the middle, four rx 40 cm around it.
    fn scene() -> Scene {
        Scene::plus_helper(3, 0.0)
    }

    fn frequencies() -> Vec<f64> {
        (0..20).map(|k| 867.5e6 + 5e6 * k as f64).collect()
    }

    /// `n` replies 1 ms apart of a static tag; each window is the
    /// noiseless channel itself (the stand-in worker passes it on).
    fn replies(n: usize) -> Vec<Reply> {
        let s = scene();
        let p = Vector3::new(0.5, 1.2, 0.7);
        let d = |a: usize| (p - s.antennas[0].position).norm() + (p - s.antennas[a].position).norm();
        let windows: Vec<Vec<Complex32>> = (1..5)
            .map(|a| {
                frequencies()
                    .iter()
                    .map(|f| {
                        let (sn, cs) = (std::f64::consts::TAU * f * d(a) / SPEED_OF_LIGHT).sin_cos();
                        Complex32::new(cs as f32, -sn as f32)
                    })
                    .collect()
            })
            .collect();
        (0..n).map(|k| Reply { tag: k % 2, time_s: k as f64 * 1e-3, tx_phase: None, windows: windows.clone() }).collect()
    }

    /// Tags its output with the slot and reply it processed.
    struct Slotted;

    impl AntennaWorker for Slotted {
        type Output = (usize, f64, Vec<Complex64>);
        fn process(&mut self, slot: usize, reply: &Reply) -> Self::Output {
            let channel = reply.windows[slot].iter().map(|v| Complex64::new(v.re as f64, v.im as f64)).collect();
            (slot, reply.time_s, channel)
        }
    }

    /// Checks that each reply's outputs arrive complete, in slot order,
    /// and replies in capture order; declines every 7th reply.
    struct Checking {
        seen: Vec<u64>,
    }

    impl ReplyFusion<(usize, f64, Vec<Complex64>)> for Checking {
        fn fuse(&mut self, reply: &ReplyHeader, antennas: Vec<(usize, f64, Vec<Complex64>)>) -> std::result::Result<Vec<Option<Vec<Complex64>>>, String> {
            assert_eq!(antennas.len(), 4);
            for (i, (slot, time_s, _)) in antennas.iter().enumerate() {
                assert_eq!((*slot, *time_s), (i, reply.time_s), "reply {}", reply.index);
            }
            self.seen.push(reply.index);
            if reply.index % 7 == 3 {
                return Err("test decline".into());
            }
            Ok(antennas.into_iter().map(|(_, _, h)| Some(h)).collect())
        }
    }

    fn config(workers: Workers) -> RuntimeConfig {
        RuntimeConfig { workers, queue_depth: 4, tx: 0, rx: vec![1, 2, 3, 4], frequencies_hz: frequencies(), ..Default::default() }
    }

    #[test]
    fn every_layout_processes_n_replies_in_order_with_n_latencies() {
        let n = 60;
        for workers in [Workers::PerAntenna(1), Workers::PerAntenna(2), Workers::Shared(2), Workers::Team(2), Workers::Team(1)] {
            let mut engine = Engine::new(scene(), "ellipse-intersection", Params::default()).unwrap();
            let mut fusion = Checking { seen: Vec::new() };
            let made = AtomicUsize::new(0);
            let report = run(
                replies(n),
                |_| {
                    made.fetch_add(1, Ordering::Relaxed);
                    Slotted
                },
                &mut fusion,
                &mut engine,
                &config(workers),
            );
            assert_eq!(fusion.seen, (0..n as u64).collect::<Vec<_>>(), "{workers:?}: fusion order");
            assert_eq!(report.outputs.len(), n, "{workers:?}");
            assert!(report.outputs.iter().enumerate().all(|(i, o)| o.index == i as u64 && o.tag == i % 2), "{workers:?}: output order");
            assert!(report.outputs.iter().all(|o| o.latency_ns > 0), "{workers:?}");
            assert_eq!(report.stage_ns.len(), n, "{workers:?}");
            let declined = (0..n).filter(|i| i % 7 == 3).count() as u64;
            assert_eq!(report.declined.get("test decline"), Some(&declined), "{workers:?}");
            assert_eq!(report.no_channel, declined, "{workers:?}");
            for o in &report.outputs {
                if o.index % 7 == 3 {
                    assert!(o.estimate.is_none() && o.receivers == 0, "{workers:?}: declined reply {} tracked", o.index);
                } else {
                    assert_eq!(o.receivers, 4, "{workers:?}");
                    let e = o.estimate.as_ref().expect("ellipse intersection answers every frame");
                    let error = (Vector3::from(e.position) - Vector3::new(0.5, 1.2, 0.7)).norm();
                    assert!(error < 0.01, "{workers:?}: reply {} off by {error} m", o.index);
                }
            }
            let expected_workers = match workers {
                Workers::PerAntenna(k) => 4 * k,
                Workers::Shared(k) | Workers::Team(k) => k,
            };
            assert_eq!(made.load(Ordering::Relaxed), expected_workers, "{workers:?}");
            assert!(report.latency_percentile_ns(0.5) <= report.latency_percentile_ns(1.0));
        }
    }

    /// At recorded pacing capture waits for each reply's time: 30 replies
    /// 1 ms apart take at least 29 ms of wall clock at speed 1, half at 2.
    #[test]
    fn recorded_pacing_follows_the_replies_timing() {
        for (speed, at_least_s) in [(1.0, 0.029), (2.0, 0.0145)] {
            let mut engine = Engine::new(scene(), "ellipse-intersection", Params::default()).unwrap();
            let config = RuntimeConfig { pacing: Pacing::Recorded { speed }, ..config(Workers::PerAntenna(1)) };
            let report = run(replies(30), |_| Slotted, &mut Checking { seen: Vec::new() }, &mut engine, &config);
            assert_eq!(report.outputs.len(), 30);
            assert!(report.wall_s >= at_least_s, "speed {speed}: {} s", report.wall_s);
        }
    }

    #[test]
    fn percentiles_are_nearest_rank() {
        assert_eq!(percentile(vec![], 0.5), 0.0);
        assert_eq!(percentile(vec![5, 1, 3, 2, 4], 0.5), 3.0);
        assert_eq!(percentile(vec![5, 1, 3, 2, 4], 0.0), 1.0);
        assert_eq!(percentile(vec![5, 1, 3, 2, 4], 1.0), 5.0);
        let report = RunReport { wall_s: 0.5, outputs: Vec::new(), ..Default::default() };
        assert_eq!(report.frames_per_s(), 0.0);
    }
}
