//! Thin PyO3 bindings over `scattertrack-dsp` (the helper's one-shot
//! wideband channel estimation): argument conversion and nothing else.
//! Errors from the DSP are raised as `DspError` (a `ValueError`) whose
//! message starts with the error kind (`"no-preamble: ..."`), so callers can
//! count skips by kind. Type stubs: `python/scattertrack/_core.pyi`.

use numpy::{
    Complex32, Complex64, IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3,
};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use scattertrack_dsp::backscatter::{preamble_chips, reply_chips, Encoding};
use scattertrack_dsp::detect::{DetectionOptions, Feature};
use scattertrack_dsp::estimate::{Calibration, Ema};
use scattertrack_dsp::ofdm::{KnownSymbol, OfdmConfig};
use scattertrack_dsp::reply::{ReplyOptions, ReplyProcessor};
use scattertrack_dsp::Error;

create_exception!(
    _core,
    DspError,
    PyValueError,
    "A DSP error; the message starts with its kind, e.g. 'no-preamble: ...'."
);

fn dsp_error(e: Error) -> PyErr {
    DspError::new_err(format!("{}: {e}", e.kind()))
}

/// One reply's processing for all rx antennas (`reply::ReplyProcessor`).
#[pyclass(module = "scattertrack._core")]
pub struct OfdmDsp {
    pub(crate) inner: ReplyProcessor,
}

#[pymethods]
impl OfdmDsp {
    #[new]
    #[pyo3(signature = (bandwidth_hz, subcarriers, centre_hz, blf_hz, symbol, encoding="fm0", trext=false,
        threshold=0.5, blf_tolerance=0.05, guard_symbols=1.0, feature="projection", use_payload=true,
        payload_bits=17, decision_margin=0.5))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        bandwidth_hz: f64,
        subcarriers: usize,
        centre_hz: f64,
        blf_hz: f64,
        symbol: PyReadonlyArray1<Complex64>,
        encoding: &str,
        trext: bool,
        threshold: f64,
        blf_tolerance: f64,
        guard_symbols: f64,
        feature: &str,
        use_payload: bool,
        payload_bits: usize,
        decision_margin: f64,
    ) -> PyResult<Self> {
        let config = OfdmConfig::new(bandwidth_hz, subcarriers, centre_hz, blf_hz).map_err(dsp_error)?;
        let symbol = KnownSymbol::from_frequency(symbol.as_array().to_vec()).map_err(dsp_error)?;
        let options = ReplyOptions {
            encoding: Encoding::parse(encoding).map_err(dsp_error)?,
            trext,
            detection: DetectionOptions { threshold, blf_tolerance },
            feature: Feature::parse(feature).map_err(dsp_error)?,
            guard_symbols,
            use_payload,
            payload_bits,
            decision_margin,
        };
        Ok(Self { inner: ReplyProcessor::new(config, symbol, options).map_err(dsp_error)? })
    }

    /// Active subcarrier frequencies, Hz, ascending (N − 1, DC dropped).
    fn subcarrier_frequencies<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.config().subcarrier_frequencies().into_pyarray(py)
    }

    /// Per-rx timing reference (see `ReplyProcessor::process`), or None.
    #[getter]
    fn timing_reference(&self) -> Option<Vec<usize>> {
        self.inner.timing_reference().map(|r| r.to_vec())
    }

    #[setter]
    fn set_timing_reference(&mut self, reference: Option<Vec<usize>>) -> PyResult<()> {
        self.inner.set_timing_reference(reference).map_err(dsp_error)
    }

    /// One reply: `windows` (R, L) complex64, `tx_phase` the tx stream index
    /// of the windows' first sample mod N (or None). Returns a dict (see the
    /// stubs); raises DspError for a reply-level failure.
    #[pyo3(signature = (windows, tx_phase=None))]
    fn process<'py>(
        &mut self,
        py: Python<'py>,
        windows: PyReadonlyArray2<Complex32>,
        tx_phase: Option<usize>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let array = windows.as_array();
        let rows: Vec<Vec<Complex32>> = array.rows().into_iter().map(|r| r.to_vec()).collect();
        let inner = &mut self.inner;
        let result = py.detach(move || {
            let refs: Vec<&[Complex32]> = rows.iter().map(|r| r.as_slice()).collect();
            inner.process(&refs, tx_phase)
        });
        let e = result.map_err(dsp_error)?;
        let (r, f, j) = (e.antennas, e.subcarriers, e.symbols);
        let d = PyDict::new(py);
        let reshape = |v: Vec<Complex64>| e_reshape(py, v, r, f);
        d.set_item("tag_channel", reshape(e.tag_channel)?)?;
        d.set_item(
            "variance",
            e.variance.into_pyarray(py).reshape([r, f]).map_err(|x| PyValueError::new_err(x.to_string()))?,
        )?;
        d.set_item(
            "antenna_errors",
            e.antenna_errors.iter().map(|x| x.as_ref().map(|x| format!("{}: {x}", x.kind()))).collect::<Vec<_>>(),
        )?;
        d.set_item("start_sample", e.start_sample)?;
        d.set_item("start_symbol", e.detection.start_symbol)?;
        d.set_item("chip_symbols", e.detection.chip_symbols)?;
        d.set_item("blf_hz", e.blf_hz)?;
        d.set_item("score", e.detection.score)?;
        d.set_item("correlations", e.detection.correlations.clone())?;
        d.set_item("first_samples", e.first_samples.clone())?;
        d.set_item("payload_chips", e.payload_chips)?;
        d.set_item("symbols", j)?;
        let states: Vec<u8> = e.states.iter().map(|s| *s as u8).collect();
        d.set_item(
            "states",
            states.into_pyarray(py).reshape([r, j]).map_err(|x| PyValueError::new_err(x.to_string()))?,
        )?;
        let counts = PyDict::new(py);
        counts.set_item("high", e.counts.iter().map(|c| c.high).collect::<Vec<_>>())?;
        counts.set_item("low", e.counts.iter().map(|c| c.low).collect::<Vec<_>>())?;
        counts.set_item("edge", e.counts.iter().map(|c| c.edge).collect::<Vec<_>>())?;
        counts.set_item("outside", e.counts.iter().map(|c| c.outside).collect::<Vec<_>>())?;
        counts.set_item("invalid", e.counts.iter().map(|c| c.invalid).collect::<Vec<_>>())?;
        d.set_item("counts", counts)?;
        Ok(d)
    }
}

fn e_reshape(
    py: Python<'_>,
    v: Vec<Complex64>,
    rows: usize,
    columns: usize,
) -> PyResult<Bound<'_, PyArray2<Complex64>>> {
    v.into_pyarray(py).reshape([rows, columns]).map_err(|x| PyValueError::new_err(x.to_string()))
}

/// Exponential moving average across replies (`estimate::Ema`).
#[pyclass(module = "scattertrack._core")]
pub struct DspEma {
    inner: Ema,
}

#[pymethods]
impl DspEma {
    #[new]
    fn new(alpha: f64) -> PyResult<Self> {
        Ok(Self { inner: Ema::new(alpha).map_err(dsp_error)? })
    }

    /// Adds one reply's channel (R, F) and returns the smoothed state (R, F).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        h: PyReadonlyArray2<Complex64>,
    ) -> PyResult<Bound<'py, PyArray2<Complex64>>> {
        let array = h.as_array();
        let (rows, columns) = (array.nrows(), array.ncols());
        let values: Vec<Complex64> = array.iter().copied().collect();
        let state = self.inner.update(&values).map_err(dsp_error)?.to_vec();
        e_reshape(py, state, rows, columns)
    }

    /// Replies averaged so far.
    #[getter]
    fn updates(&self) -> usize {
        self.inner.updates()
    }

    /// Updates negated to match the running polarity.
    #[getter]
    fn flips(&self) -> usize {
        self.inner.flips()
    }
}

/// The known symbol X (N,) complex128, FFT order, DC = 0, from a seed.
#[pyfunction]
fn dsp_known_symbol<'py>(py: Python<'py>, subcarriers: usize, seed: u64) -> PyResult<Bound<'py, PyArray1<Complex64>>> {
    Ok(KnownSymbol::generate(subcarriers, seed).map_err(dsp_error)?.frequency.into_pyarray(py))
}

/// Validates an OFDM configuration (design rule N < B/(2 BLF)); returns the
/// active subcarrier frequencies, Hz, ascending.
#[pyfunction]
fn dsp_subcarrier_frequencies<'py>(
    py: Python<'py>,
    bandwidth_hz: f64,
    subcarriers: usize,
    centre_hz: f64,
    blf_hz: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let config = OfdmConfig::new(bandwidth_hz, subcarriers, centre_hz, blf_hz).map_err(dsp_error)?;
    Ok(config.subcarrier_frequencies().into_pyarray(py))
}

/// Chip levels (uint8, 0/1, one per half BLF period) of a whole reply
/// (`bits` given) or of the preamble alone (`bits` None).
#[pyfunction]
#[pyo3(signature = (encoding, trext, bits=None))]
fn dsp_reply_chips<'py>(
    py: Python<'py>,
    encoding: &str,
    trext: bool,
    bits: Option<Vec<u8>>,
) -> PyResult<Bound<'py, PyArray1<u8>>> {
    let encoding = Encoding::parse(encoding).map_err(dsp_error)?;
    let chips = match bits {
        Some(bits) => reply_chips(encoding, trext, &bits),
        None => preamble_chips(encoding, trext),
    }
    .map_err(dsp_error)?;
    Ok(chips.into_pyarray(py))
}

/// Calibration correction C (R, F) from measured tag channels (K, R, F) of
/// a tag at a known position and the reference channel there (R, F).
#[pyfunction]
fn dsp_calibration<'py>(
    py: Python<'py>,
    measured: PyReadonlyArray3<Complex64>,
    reference: PyReadonlyArray2<Complex64>,
) -> PyResult<Bound<'py, PyArray2<Complex64>>> {
    let (m, r) = (measured.as_array(), reference.as_array());
    let (antennas, subcarriers) = (r.nrows(), r.ncols());
    let replies: Vec<Vec<Complex64>> = m.outer_iter().map(|x| x.iter().copied().collect()).collect();
    let refs: Vec<&[Complex64]> = replies.iter().map(|x| x.as_slice()).collect();
    let reference: Vec<Complex64> = r.iter().copied().collect();
    let c = Calibration::from_measurements(&refs, &reference, antennas, subcarriers).map_err(dsp_error)?;
    e_reshape(py, c.correction, antennas, subcarriers)
}

/// Registers the DSP classes and functions in the `_core` module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<OfdmDsp>()?;
    m.add_class::<DspEma>()?;
    m.add("DspError", m.py().get_type::<DspError>())?;
    m.add_function(wrap_pyfunction!(dsp_known_symbol, m)?)?;
    m.add_function(wrap_pyfunction!(dsp_subcarrier_frequencies, m)?)?;
    m.add_function(wrap_pyfunction!(dsp_reply_chips, m)?)?;
    m.add_function(wrap_pyfunction!(dsp_calibration, m)?)?;
    Ok(())
}
