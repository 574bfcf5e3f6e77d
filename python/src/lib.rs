//! Thin PyO3 bindings over `scattertrack-core`: argument conversion and
//! nothing else. Type stubs: `python/scattertrack/_core.pyi`.

mod dsp;
mod fixed;
mod geometry;
mod locate;
mod lora;
mod params;
mod scene;

use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use scattertrack_core::engine::Engine as CoreEngine;
use scattertrack_core::track::{Estimate, Measurement, PhaseRead, TrackerStats, WidebandFrame};
use nalgebra::Complex;

// mimalloc for the extension's own allocations: thousands of tags allocate
// and free hypothesis arrays of every size from two tracker threads, and
// glibc's arenas kept the freed room (10,000 initialising tags: peak RSS
// 1.97 GB with glibc, 1.66 GB with mimalloc, the same tracks; docs/notes/glac-many-tags-cost.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn stats_dict<'py>(py: Python<'py>, s: &TrackerStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("measurements", s.measurements)?;
    d.set_item("out_of_order", s.out_of_order)?;
    d.set_item("invalid", s.invalid)?;
    d.set_item("outliers", s.outliers)?;
    d.set_item("initialising", s.initialising)?;
    d.set_item("reinitialisations", s.reinitialisations)?;
    d.set_item("max_hypotheses", s.max_hypotheses)?;
    d.set_item("filter_updates", s.filter_updates)?;
    d.set_item("reseeds", s.reseeds)?;
    d.set_item("lobe_switches", s.lobe_switches)?;
    d.set_item("max_expanded_per_read", s.max_expanded_per_read)?;
    Ok(d)
}

/// Columnar estimates: `row` is the index of the input row that produced each.
#[derive(Default)]
struct Columns {
    row: Vec<i64>,
    time_s: Vec<f64>,
    position: Vec<f64>,
    velocity: Vec<f64>,
    /// The full 6×6 covariance, row-major, or (`sigma_only`) the x, y, z
    /// 1-sigma alone: 36 values against 3 per row, for writers that need
    /// no more (track.csv).
    covariance: Vec<f64>,
    sigma_only: bool,
    hypotheses: Vec<i64>,
    weight: Vec<f64>,
}

impl Columns {
    /// Room for `rows` estimates (at most one per input row).
    fn with_capacity(rows: usize, sigma_only: bool) -> Self {
        Self {
            row: Vec::with_capacity(rows),
            time_s: Vec::with_capacity(rows),
            position: Vec::with_capacity(3 * rows),
            velocity: Vec::with_capacity(3 * rows),
            covariance: Vec::with_capacity(if sigma_only { 3 } else { 36 } * rows),
            sigma_only,
            hypotheses: Vec::with_capacity(rows),
            weight: Vec::with_capacity(rows),
        }
    }

    fn push(&mut self, row: usize, e: &Estimate) {
        self.row.push(row as i64);
        self.time_s.push(e.time_s);
        self.position.extend_from_slice(&e.position);
        self.velocity.extend_from_slice(&e.velocity);
        if self.sigma_only {
            // As `track.columns.position_sigma` does: the diagonal, clipped at 0.
            self.covariance.extend([0, 7, 14].map(|k| e.covariance[k].max(0.0).sqrt()));
        } else {
            self.covariance.extend_from_slice(&e.covariance);
        }
        self.hypotheses.push(e.hypotheses as i64);
        self.weight.push(e.weight);
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let n = self.row.len();
        let d = PyDict::new(py);
        d.set_item("row", self.row.into_pyarray(py))?;
        d.set_item("time_s", self.time_s.into_pyarray(py))?;
        let reshape = |v: Vec<f64>, k: usize| -> PyResult<Bound<'_, PyArray2<f64>>> {
            v.into_pyarray(py).reshape([n, k]).map_err(value_error)
        };
        d.set_item("position", reshape(self.position, 3)?)?;
        d.set_item("velocity", reshape(self.velocity, 3)?)?;
        if self.sigma_only {
            d.set_item("sigma", reshape(self.covariance, 3)?)?;
        } else {
            d.set_item("covariance", reshape(self.covariance, 36)?)?;
        }
        d.set_item("hypotheses", self.hypotheses.into_pyarray(py))?;
        d.set_item("weight", self.weight.into_pyarray(py))?;
        Ok(d)
    }
}

/// One frame's rows (sorted by receiver, then frequency) as a
/// `WidebandFrame`; blocks with different subcarriers give a frame whose
/// sizes do not match, which the trackers decline as invalid.
fn frame_from_rows(time_s: f64, tx: usize, rx: &[i64], f: &[f64], re: &[f64], im: &[f64]) -> WidebandFrame {
    let mut receivers: Vec<usize> = Vec::new();
    let mut block_len = 0usize;
    for (i, &r) in rx.iter().enumerate() {
        if receivers.last() != Some(&(r as usize)) {
            receivers.push(r as usize);
        }
        if receivers.len() == 1 {
            block_len = i + 1;
        }
    }
    let frequencies: Vec<f64> = f[..block_len].to_vec();
    let consistent = block_len * receivers.len() == rx.len()
        && (0..rx.len()).all(|i| (f[i] - frequencies[i % block_len.max(1)]).abs() < 1.0);
    let h: Vec<Complex<f64>> =
        if consistent { re.iter().zip(im).map(|(&a, &b)| Complex::new(a, b)).collect() } else { Vec::new() };
    WidebandFrame { time_s, tx, rx: receivers, frequencies_hz: frequencies, h }
}

fn estimate_tuple(e: Estimate) -> (f64, [f64; 3], [f64; 3], Vec<f64>, usize, f64) {
    (e.time_s, e.position, e.velocity, e.covariance.to_vec(), e.hypotheses, e.weight)
}

/// Many tags, one tracker each (a thin wrapper over `engine::Engine`).
#[pyclass(module = "scattertrack._core")]
struct Engine {
    inner: CoreEngine,
    antennas: usize,
    /// `run`'s batch as the core takes it, kept between calls (filled
    /// afresh each time): allocated per batch it was faulted in anew.
    batch_tags: Vec<usize>,
    batch_reads: Vec<Measurement>,
}

#[pymethods]
impl Engine {
    /// Trackers of `method` over `scene` (a `_core.Scene`), with `params`
    /// (name → value) checked by the method's table.
    #[new]
    #[pyo3(signature = (scene, method, params=None))]
    fn new(scene: PyRef<'_, scene::Scene>, method: &str, params: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let scene = scene.inner.clone();
        let antennas = scene.antennas.len();
        let inner = CoreEngine::new(scene, method, params::make_params(method, params)?).map_err(value_error)?;
        Ok(Self { inner, antennas, batch_tags: Vec::new(), batch_reads: Vec::new() })
    }

    /// One measurement of tag `tag` → `None` or
    /// `(time_s, position, velocity, covariance[36], hypotheses, weight)`.
    fn step(
        &mut self,
        tag: usize,
        time_s: f64,
        antenna: usize,
        frequency_hz: f64,
        phase_rad: f64,
    ) -> Option<(f64, [f64; 3], [f64; 3], Vec<f64>, usize, f64)> {
        let m = Measurement::Phase(PhaseRead { time_s, antenna, frequency_hz, phase_rad });
        self.inner.step(tag, &m).map(estimate_tuple)
    }

    /// Runs time-ordered columns as one batch (`Engine::run_batch`: the
    /// estimates of `step` over the rows in order, taken tag by tag; the
    /// GIL is released) and returns the estimates as columns, with `row`
    /// the producing input row, increasing. `covariance=False`: a `sigma`
    /// column (n, 3: the x, y, z 1-sigma, m) in place of `covariance`.
    #[pyo3(signature = (tag, time_s, antenna, frequency_hz, phase_rad, *, covariance=true))]
    #[allow(clippy::too_many_arguments)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        tag: PyReadonlyArray1<i64>,
        time_s: PyReadonlyArray1<f64>,
        antenna: PyReadonlyArray1<i64>,
        frequency_hz: PyReadonlyArray1<f64>,
        phase_rad: PyReadonlyArray1<f64>,
        covariance: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (tag, t, a, f, ph) =
            (tag.as_array(), time_s.as_array(), antenna.as_array(), frequency_hz.as_array(), phase_rad.as_array());
        let n = t.len();
        if [tag.len(), a.len(), f.len(), ph.len()].iter().any(|&l| l != n) {
            return Err(value_error("all columns must have the same length"));
        }
        if let Some(bad) = a.iter().position(|&x| x < 0 || x as usize >= self.antennas) {
            return Err(value_error(format!("row {bad}: antenna index {} out of range", a[bad])));
        }
        if tag.iter().any(|&x| x < 0) {
            return Err(value_error("tag indices must be non-negative"));
        }
        let (inner, tags, reads) = (&mut self.inner, &mut self.batch_tags, &mut self.batch_reads);
        // The views borrow the arrays, which the caller holds (and does not
        // change) for the call.
        let columns = py.detach(move || {
            tags.clear();
            tags.extend(tag.iter().map(|&k| k as usize));
            reads.clear();
            reads.extend((0..n).map(|i| {
                Measurement::Phase(PhaseRead { time_s: t[i], antenna: a[i] as usize, frequency_hz: f[i], phase_rad: ph[i] })
            }));
            // Nearly every read gives a row once its tag commits; the cap
            // keeps a whole in-memory recording from reserving it all at once.
            let mut c = Columns::with_capacity(n.min(1 << 20), !covariance);
            inner.run_batch(tags, reads, |i, e| c.push(i, e));
            if reads.capacity() > 1 << 18 {
                // A whole recording at once: not kept.
                (*tags, *reads) = (Vec::new(), Vec::new());
            }
            c
        });
        columns.into_dict(py)
    }

    /// Many wideband frames in time order. Frame `k` is tag `tag[k]` at
    /// `time_s[k]`, transmit antenna index `tx[k]`, and rows
    /// `frame_start[k]..frame_start[k+1]` of the row columns (receive
    /// antenna index, subcarrier Hz, channel re/im), sorted by receiver
    /// then frequency. Receivers must share one subcarrier set; a frame
    /// whose blocks differ is passed on malformed so the tracker declines
    /// (and counts) it. Returns the same columns as `run`, `row` being
    /// the frame index.
    #[allow(clippy::too_many_arguments)]
    fn run_frames<'py>(
        &mut self,
        py: Python<'py>,
        tag: PyReadonlyArray1<i64>,
        time_s: PyReadonlyArray1<f64>,
        tx: PyReadonlyArray1<i64>,
        frame_start: PyReadonlyArray1<i64>,
        rx: PyReadonlyArray1<i64>,
        frequency_hz: PyReadonlyArray1<f64>,
        h_re: PyReadonlyArray1<f64>,
        h_im: PyReadonlyArray1<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (tag, t, tx, start) = (tag.as_array().to_vec(), time_s.as_array().to_vec(), tx.as_array().to_vec(), frame_start.as_array().to_vec());
        let (rx, f, re, im) = (rx.as_array().to_vec(), frequency_hz.as_array().to_vec(), h_re.as_array().to_vec(), h_im.as_array().to_vec());
        let m = t.len();
        let n = rx.len();
        if tag.len() != m || tx.len() != m || start.len() != m + 1 {
            return Err(value_error("tag, time_s and tx need one entry per frame, frame_start one more"));
        }
        if f.len() != n || re.len() != n || im.len() != n {
            return Err(value_error("rx, frequency_hz, h_re and h_im must have the same length"));
        }
        if start.windows(2).any(|w| w[1] < w[0]) || start.first() != Some(&0) || start.last() != Some(&(n as i64)) {
            return Err(value_error("frame_start must rise from 0 to the number of rows"));
        }
        if tag.iter().any(|&x| x < 0) {
            return Err(value_error("tag indices must be non-negative"));
        }
        let antennas = self.antennas as i64;
        if let Some(bad) = rx.iter().chain(tx.iter()).find(|&&x| x < 0 || x >= antennas) {
            return Err(value_error(format!("antenna index {bad} out of range")));
        }
        let inner = &mut self.inner;
        let columns = py.detach(move || {
            let mut c = Columns::default();
            for k in 0..m {
                let rows = start[k] as usize..start[k + 1] as usize;
                let frame = frame_from_rows(t[k], tx[k] as usize, &rx[rows.clone()], &f[rows.clone()], &re[rows.clone()], &im[rows]);
                if let Some(e) = inner.step(tag[k] as usize, &Measurement::Wideband(frame)) {
                    c.push(k, &e);
                }
            }
            c
        });
        columns.into_dict(py)
    }

    /// Streams helper IQ through the real-time runtime (`scattertrack-runtime`):
    /// capture → per-antenna DSP workers → fusion (joint detection, tag
    /// channel, calibration, EMA) → this engine, with every reply's
    /// latency from arrival to output.
    ///
    /// Per reply k: `tag`, `time_s` (s), `tx_phase` (the window's first
    /// transmitter sample mod N, −1 unknown). The samples come from exactly
    /// one of `windows` (K, R, S) complex64 in memory, or `file` = (path,
    /// datatype "ci16_le" | "cf32_le", channels, scale, window_len,
    /// start_sample (K,)): an interleaved IQ file (SigMF data, stored =
    /// scale × baseband) that capture reads one reply at a time, when it is
    /// due. `dsp` the helper design and options; `tx` and `rx` (R) antenna
    /// indices in this engine's scene; `timing_reference` (R) per-rx D_r;
    /// `correction` (R, F) complex128; `speed` None: as fast as possible,
    /// else × the recording's timing; `layout` how antenna jobs meet
    /// threads: "team" (the default: `workers` threads, None one per core,
    /// that take any antenna's job and release the replies they complete),
    /// "per-antenna" (`workers` threads per antenna, None 1, and a fusion
    /// thread) or "shared" (one pool of `workers`, None one per core, and a
    /// fusion thread); see `scattertrack_runtime::Workers`; `prewake_s`
    /// (team, paced) how early the idle workers are woken to poll for a
    /// reply, s (0: they sleep until it arrives). Returns the columns of `run` plus `latency_ns`,
    /// `receivers` (per reply), `stage_ns` (K, 5; `stages` names the
    /// columns), `wall_s`, `declined` {reason: count}, `no_channel` and
    /// `unreadable` (file windows that could not be read).
    #[pyo3(signature = (tag, time_s, tx_phase, dsp, tx, rx, windows=None, file=None, timing_reference=None,
        correction=None, ema_alpha=None, workers=None, layout="team", queue_depth=64, speed=None, prewake_s=1e-3))]
    #[allow(clippy::too_many_arguments)]
    fn run_stream<'py>(
        &mut self,
        py: Python<'py>,
        tag: PyReadonlyArray1<i64>,
        time_s: PyReadonlyArray1<f64>,
        tx_phase: PyReadonlyArray1<i64>,
        dsp: PyRef<'py, dsp::OfdmDsp>,
        tx: usize,
        rx: Vec<usize>,
        windows: Option<PyReadonlyArray3<num_complex::Complex32>>,
        file: Option<(std::path::PathBuf, String, usize, f32, usize, PyReadonlyArray1<i64>)>,
        timing_reference: Option<Vec<usize>>,
        correction: Option<PyReadonlyArray2<'py, num_complex::Complex64>>,
        ema_alpha: Option<f64>,
        workers: Option<usize>,
        layout: &str,
        queue_depth: usize,
        speed: Option<f64>,
        prewake_s: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        use scattertrack_runtime::source::{IqFileReplies, SampleFormat, WindowSpec};
        use scattertrack_runtime::{InMemory, Reply};
        use scattertrack_runtime::Workers;
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        let workers = match layout {
            "team" => Workers::Team(workers.unwrap_or(cores).max(1)),
            "per-antenna" => Workers::PerAntenna(workers.unwrap_or(1).max(1)),
            "shared" => Workers::Shared(workers.unwrap_or(cores).max(1)),
            other => return Err(value_error(format!("layout '{other}' is not one of team, per-antenna, shared"))),
        };
        if !(prewake_s.is_finite() && (0.0..=1.0).contains(&prewake_s)) {
            return Err(value_error(format!("prewake_s must be in [0, 1] s, got {prewake_s}")));
        }
        let options = StreamOptions { tx, rx, timing_reference, correction, ema_alpha, workers, queue_depth, speed, prewake_s };
        match (windows, file) {
            (Some(windows), None) => {
                let array = windows.as_array();
                let (k, r, _) = array.dim();
                let headers = stream_headers(&tag, &time_s, &tx_phase, k)?;
                let replies: Vec<Reply> = headers
                    .iter()
                    .enumerate()
                    .map(|(i, h)| Reply {
                        tag: h.tag,
                        time_s: h.time_s,
                        tx_phase: h.tx_phase,
                        windows: (0..r).map(|a| array.slice(numpy::ndarray::s![i, a, ..]).to_vec()).collect(),
                    })
                    .collect();
                self.stream(py, InMemory::new(replies), r, &dsp.inner, options, None)
            }
            (None, Some((path, datatype, channels, scale, window_len, start_sample))) => {
                let format = match datatype.as_str() {
                    "ci16_le" => SampleFormat::ComplexI16,
                    "cf32_le" => SampleFormat::ComplexF32,
                    other => return Err(value_error(format!("unsupported datatype {other:?} (ci16_le or cf32_le)"))),
                };
                let starts = start_sample.as_array().to_vec();
                if starts.iter().any(|&x| x < 0) {
                    return Err(value_error("start_sample must be non-negative"));
                }
                let headers = stream_headers(&tag, &time_s, &tx_phase, starts.len())?;
                let specs = headers
                    .iter()
                    .zip(&starts)
                    .map(|(h, &start)| WindowSpec { start_sample: start as u64, tag: h.tag, time_s: h.time_s, tx_phase: h.tx_phase })
                    .collect();
                let replies = IqFileReplies::open(&path, format, channels, scale, window_len, specs)
                    .map_err(|e| PyErr::new::<pyo3::exceptions::PyOSError, _>(format!("{}: {e}", path.display())))?;
                let unreadable = replies.unreadable.clone();
                self.stream(py, replies, channels, &dsp.inner, options, Some(unreadable))
            }
            _ => Err(value_error("give exactly one of windows and file")),
        }
    }

    /// Smoothed (backtracked MAP) trajectory of tag `tag`: (time_s, position) pairs.
    fn trajectory(&self, tag: usize) -> Vec<(f64, [f64; 3])> {
        self.inner.trajectory(tag)
    }

    /// Counters of tag `tag`.
    fn stats<'py>(&self, py: Python<'py>, tag: usize) -> PyResult<Bound<'py, PyDict>> {
        stats_dict(py, &self.inner.stats(tag))
    }

    /// Live hypotheses of tag `tag`: [(position, normalised log-likelihood)].
    fn hypotheses(&self, tag: usize) -> Vec<([f64; 3], f64)> {
        self.inner.hypotheses(tag)
    }

    /// (count, mean_ns, max_ns) of `step` calls so far.
    fn latency(&self) -> (u64, f64, u64) {
        let l = self.inner.latency();
        (l.count, l.mean_ns(), l.max_ns)
    }

    /// Quantiles (0–1) of the per-step cost, ns.
    fn latency_percentiles(&self, quantiles: Vec<f64>) -> Vec<f64> {
        let l = self.inner.latency();
        quantiles.iter().map(|&q| l.percentile_ns(q)).collect()
    }

    /// `track.csv` rows as UTF-8 bytes (the GIL is released): row `i` is
    /// `time_s[i]`, `epc_cells[epc[i]]` (already quoted), then every column of
    /// `values` (n, k), each float with 6 decimals as Python's `"%.6f"`
    /// writes it (correctly rounded, half to even) and NaN as `nan`.
    #[staticmethod]
    fn format_track_rows<'py>(
        py: Python<'py>,
        time_s: PyReadonlyArray1<f64>,
        epc: PyReadonlyArray1<i64>,
        epc_cells: Vec<String>,
        values: PyReadonlyArray2<f64>,
    ) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
        let (t, e, v) = (time_s.as_array(), epc.as_array(), values.as_array());
        let n = t.len();
        if e.len() != n || v.nrows() != n {
            return Err(value_error("time_s, epc and values need one entry (row) per track row"));
        }
        if let Some(bad) = e.iter().position(|&k| k < 0 || k as usize >= epc_cells.len()) {
            return Err(value_error(format!("row {bad}: epc code {} out of range", e[bad])));
        }
        let (t, e, v) = (t.to_vec(), e.to_vec(), v.to_owned());
        let text = py.detach(move || {
            let mut out = String::with_capacity(n * (16 + 12 * v.ncols()));
            for i in 0..n {
                fixed::push(&mut out, t[i]);
                out.push(',');
                out.push_str(&epc_cells[e[i] as usize]);
                for x in v.row(i).iter() {
                    out.push(',');
                    fixed::push(&mut out, *x);
                }
                out.push('\n');
            }
            out
        });
        Ok(pyo3::types::PyBytes::new(py, text.as_bytes()))
    }
}

/// A reply's header as given from Python (validated).
struct StreamHeader {
    tag: usize,
    time_s: f64,
    tx_phase: Option<usize>,
}

fn stream_headers(
    tag: &PyReadonlyArray1<i64>,
    time_s: &PyReadonlyArray1<f64>,
    tx_phase: &PyReadonlyArray1<i64>,
    k: usize,
) -> PyResult<Vec<StreamHeader>> {
    let (tag, t, phase) = (tag.as_array().to_vec(), time_s.as_array().to_vec(), tx_phase.as_array().to_vec());
    if tag.len() != k || t.len() != k || phase.len() != k {
        return Err(value_error("tag, time_s and tx_phase need one entry per reply"));
    }
    if tag.iter().any(|&x| x < 0) {
        return Err(value_error("tag indices must be non-negative"));
    }
    Ok((0..k)
        .map(|i| StreamHeader { tag: tag[i] as usize, time_s: t[i], tx_phase: (phase[i] >= 0).then_some(phase[i] as usize) })
        .collect())
}

/// `run_stream`'s settings, handed to [`Engine::stream`] whichever the source.
struct StreamOptions<'py> {
    tx: usize,
    rx: Vec<usize>,
    timing_reference: Option<Vec<usize>>,
    correction: Option<PyReadonlyArray2<'py, num_complex::Complex64>>,
    ema_alpha: Option<f64>,
    workers: scattertrack_runtime::Workers,
    queue_depth: usize,
    speed: Option<f64>,
    prewake_s: f64,
}

impl Engine {
    /// Runs the runtime over `replies` (`r` rx windows each) and returns the
    /// dictionary of `run_stream`.
    fn stream<'py, S>(
        &mut self,
        py: Python<'py>,
        replies: S,
        r: usize,
        processor: &scattertrack_dsp::reply::ReplyProcessor,
        o: StreamOptions<'py>,
        unreadable: Option<std::sync::Arc<std::sync::atomic::AtomicU64>>,
    ) -> PyResult<Bound<'py, PyDict>>
    where
        S: scattertrack_runtime::ReplySource,
    {
        use scattertrack_runtime::dsp::DspSetup;
        use scattertrack_runtime::{Pacing, RuntimeConfig};
        if o.rx.len() != r {
            return Err(value_error(format!("{} rx antennas for windows of {r} rx", o.rx.len())));
        }
        if let Some(bad) = o.rx.iter().chain(std::iter::once(&o.tx)).find(|&&x| x >= self.antennas) {
            return Err(value_error(format!("antenna index {bad} out of range")));
        }
        if let Some(s) = o.speed {
            if !(s > 0.0 && s.is_finite()) {
                return Err(value_error(format!("speed must be > 0, got {s}")));
            }
        }
        let setup = DspSetup {
            config: processor.config().clone(),
            symbol: processor.symbol().clone(),
            options: processor.options().clone(),
            timing_reference: o.timing_reference,
            correction: o.correction.map(|c| c.as_array().iter().copied().collect()),
            ema_alpha: o.ema_alpha,
        };
        setup.validate(r).map_err(|e| value_error(e.to_string()))?;
        let pool = scattertrack_runtime::dsp::BufferPool::default();
        let mut fusion = setup.fusion(&pool).map_err(|e| value_error(e.to_string()))?;
        let workers = o.workers;
        let config = RuntimeConfig {
            workers,
            queue_depth: o.queue_depth,
            pacing: o.speed.map_or(Pacing::AsFastAsPossible, |speed| Pacing::Recorded { speed }),
            tx: o.tx,
            rx: o.rx,
            frequencies_hz: setup.config.subcarrier_frequencies(),
            prewake: std::time::Duration::from_secs_f64(o.prewake_s),
        };
        let inner = &mut self.inner;
        let report = py.detach(move || {
            scattertrack_runtime::run_source(replies, |_| setup.worker(&pool).expect("validated"), &mut fusion, inner, &config)
        });
        let mut c = Columns::default();
        for out in &report.outputs {
            if let Some(e) = &out.estimate {
                c.push(out.index as usize, e);
            }
        }
        let d = c.into_dict(py)?;
        let latency: Vec<u64> = report.outputs.iter().map(|o| o.latency_ns).collect();
        let receivers: Vec<i64> = report.outputs.iter().map(|o| o.receivers as i64).collect();
        let stages: Vec<u64> = report.stage_ns.iter().flat_map(|s| s.iter().copied()).collect();
        d.set_item("latency_ns", latency.into_pyarray(py))?;
        d.set_item("receivers", receivers.into_pyarray(py))?;
        d.set_item("stage_ns", stages.into_pyarray(py).reshape([report.stage_ns.len(), 5]).map_err(value_error)?)?;
        d.set_item("stages", scattertrack_runtime::STAGES.to_vec())?;
        d.set_item("wall_s", report.wall_s)?;
        d.set_item("no_channel", report.no_channel)?;
        d.set_item("unreadable", unreadable.map_or(0, |u| u.load(std::sync::atomic::Ordering::Relaxed)))?;
        let declined = PyDict::new(py);
        for (reason, count) in &report.declined {
            declined.set_item(reason, count)?;
        }
        d.set_item("declined", declined)?;
        Ok(d)
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Engine>()?;
    params::register(m)?;
    dsp::register(m)?;
    lora::register(m)?;
    geometry::register(m)?;
    locate::register(m)?;
    scene::register(m)?;
    Ok(())
}

