//! Thin PyO3 bindings over `scattertrack_dsp::lora` (Marvel's LoRa
//! backscatter pose sensing, docs/marvel.md section 7): argument conversion
//! and nothing else. Errors are raised as `DspError` (a `ValueError`) whose
//! message starts with the error kind. Type stubs:
//! `python/scattertrack/_core.pyi`.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    Complex32, Complex64, IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray4,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyComplex, PyDict};

use scattertrack_dsp::lora::{
    estimate_clock_error, music, solve_yaw, AngleCombine, ArrayGeometry, ChirpConfig, Corrections, EpochConfig,
    EpochProcessor, HeadingConfig, Mat3, MusicConfig, PairObservation, PeakFinder, PeakOptions, RangeCoherence,
    RangeWindow, Vec3, YawGeometry,
};
use scattertrack_dsp::Error;

use crate::dsp::DspError;

fn lora_error(e: Error) -> PyErr {
    DspError::new_err(format!("{}: {e}", e.kind()))
}

fn bad(message: impl Into<String>) -> PyErr {
    DspError::new_err(format!("bad-config: {}", message.into()))
}

fn vec3(a: Option<PyReadonlyArray1<f64>>, name: &str) -> PyResult<Option<Vec3>> {
    match a {
        None => Ok(None),
        Some(a) => {
            let v = a.as_array();
            if v.len() != 3 {
                return Err(bad(format!("{name} must have 3 entries")));
            }
            Ok(Some([v[0], v[1], v[2]]))
        }
    }
}

fn mat3(a: Option<PyReadonlyArray2<f64>>, name: &str) -> PyResult<Option<Mat3>> {
    match a {
        None => Ok(None),
        Some(a) => {
            let m = a.as_array();
            if m.shape() != [3, 3] {
                return Err(bad(format!("{name} must be 3 x 3")));
            }
            Ok(Some(std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))))
        }
    }
}

fn rows3(a: PyReadonlyArray2<f64>, name: &str) -> PyResult<Vec<Vec3>> {
    let m = a.as_array();
    if m.ncols() != 3 {
        return Err(bad(format!("{name} must be (n, 3)")));
    }
    Ok(m.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// One Marvel sensing epoch (`lora::EpochProcessor`).
#[pyclass(module = "scattertrack._core")]
pub struct LoraEpochProcessor {
    inner: EpochProcessor,
}

#[pymethods]
impl LoraEpochProcessor {
    #[new]
    #[pyo3(signature = (spreading_factor=12, bandwidth_hz=500e3, channels_hz=None, chirp_starts_s=None,
        tag_shifts_hz=None, tag_positions=None, array="triangle", array_elements=None, calibration_rad=None,
        range_min_m=0.0, range_max_m=150.0, range_threshold=0.5, range_coherence="per-tag", range_window_m=None,
        range_full=false, magnitude_weights=true, angle_combine="harmonic", music_grid_deg=3.0, music_focus=false,
        min_omega_rad_s=0.05, ignore_doppler=false, peak_search_hz=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        spreading_factor: u32,
        bandwidth_hz: f64,
        channels_hz: Option<(f64, f64)>,
        chirp_starts_s: Option<(f64, f64)>,
        tag_shifts_hz: Option<[f64; 4]>,
        tag_positions: Option<PyReadonlyArray2<f64>>,
        array: &str,
        array_elements: Option<PyReadonlyArray2<f64>>,
        calibration_rad: Option<PyReadonlyArray2<f64>>,
        range_min_m: f64,
        range_max_m: f64,
        range_threshold: f64,
        range_coherence: &str,
        range_window_m: Option<f64>,
        range_full: bool,
        magnitude_weights: bool,
        angle_combine: &str,
        music_grid_deg: f64,
        music_focus: bool,
        min_omega_rad_s: f64,
        ignore_doppler: bool,
        peak_search_hz: Option<f64>,
    ) -> PyResult<Self> {
        let mut c = EpochConfig::marvel();
        c.chirp = ChirpConfig::new(spreading_factor, bandwidth_hz).map_err(lora_error)?;
        c.chirp_starts_s = [0.0, c.chirp.duration_s()];
        if let Some((a, b)) = channels_hz {
            c.channels_hz = [a, b];
        }
        if let Some((a, b)) = chirp_starts_s {
            c.chirp_starts_s = [a, b];
        }
        if let Some(s) = tag_shifts_hz {
            c.tag_shifts_hz = s;
        }
        if let Some(t) = tag_positions {
            let rows = rows3(t, "tag_positions")?;
            if rows.len() != 4 {
                return Err(bad("tag_positions must be (4, 3)"));
            }
            c.tag_positions = [rows[0], rows[1], rows[2], rows[3]];
        }
        c.array = match (array, array_elements) {
            (_, Some(e)) => ArrayGeometry::new(rows3(e, "array_elements")?).map_err(lora_error)?,
            ("triangle", None) => ArrayGeometry::triangle(0.16),
            ("linear", None) => ArrayGeometry::linear(0.16, 3),
            (other, None) => return Err(bad(format!("array must be triangle or linear, got {other}"))),
        };
        c.music = MusicConfig {
            grid_step_rad: music_grid_deg.to_radians(),
            focus: music_focus,
            ..MusicConfig::for_array(&c.array)
        };
        if let Some(cal) = calibration_rad {
            let a = cal.as_array();
            if a.shape() != [c.array.len(), 8] {
                return Err(bad(format!("calibration_rad must be ({}, 8)", c.array.len())));
            }
            c.calibration_rad = a.iter().copied().collect();
        }
        c.range.min_m = range_min_m;
        c.range.max_m = range_max_m;
        c.range.threshold = range_threshold;
        c.range_coherence = match range_coherence {
            "per-tag" => RangeCoherence::PerTag,
            "pair-sums" => RangeCoherence::PairSums,
            "across-tags" => RangeCoherence::AcrossTags,
            other => {
                return Err(bad(format!("range_coherence must be per-tag, pair-sums or across-tags, got {other}")))
            }
        };
        let fringe = scattertrack_dsp::SPEED_OF_LIGHT / (2.0 * (c.channels_hz[1] - c.channels_hz[0]).abs());
        c.range_window = if range_full {
            RangeWindow::Full
        } else {
            RangeWindow::AroundTiming { half_width_m: range_window_m.unwrap_or(fringe) }
        };
        c.magnitude_weights = magnitude_weights;
        c.angle_combine = match angle_combine {
            "harmonic" => AngleCombine::HarmonicMean,
            "mean-direction" => AngleCombine::MeanDirection,
            other => return Err(bad(format!("angle_combine must be harmonic or mean-direction, got {other}"))),
        };
        c.heading = HeadingConfig { min_omega_rad_s, chirp_rate_hz_per_s: Some(c.chirp.chirp_rate_hz_per_s()) };
        c.ignore_doppler = ignore_doppler;
        c.peak = PeakOptions { search_hz: peak_search_hz, ..PeakOptions::default() };
        Ok(Self { inner: EpochProcessor::new(c).map_err(lora_error)? })
    }

    /// Samples per chirp `2^SF`.
    #[getter]
    fn samples_per_chirp(&self) -> usize {
        self.inner.config().chirp.samples()
    }

    /// Receive antennas `M`.
    #[getter]
    fn antennas(&self) -> usize {
        self.inner.config().antennas()
    }

    /// Reference time of the epoch's phases from the epoch origin, s.
    #[getter]
    fn reference_time_s(&self) -> f64 {
        self.inner.config().reference_time_s()
    }

    /// Received carriers `f_j + s_k/2`, Hz, (2, 4).
    fn carriers_hz<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = self.inner.config();
        let v: Vec<f64> = (0..2).flat_map(|j| (0..4).map(move |k| (j, k))).map(|(j, k)| c.carrier_hz(j, k)).collect();
        Ok(Array2::from_shape_vec((2, 4), v).expect("2 x 4").into_pyarray(py).into_any())
    }

    /// One epoch: `samples` complex64 (2, 4, M, N). Returns a dict (see the
    /// stubs); raises DspError.
    #[pyo3(signature = (samples, clock_error=0.0, velocity=None, direction=None, attitude=None, omega_body=None,
        epoch_time_s=None))]
    #[allow(clippy::too_many_arguments)]
    fn process<'py>(
        &mut self,
        py: Python<'py>,
        samples: PyReadonlyArray4<Complex32>,
        clock_error: f64,
        velocity: Option<PyReadonlyArray1<f64>>,
        direction: Option<PyReadonlyArray1<f64>>,
        attitude: Option<PyReadonlyArray2<f64>>,
        omega_body: Option<PyReadonlyArray1<f64>>,
        epoch_time_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let m = self.inner.config().antennas();
        let n = self.inner.config().chirp.samples();
        if samples.shape() != [2, 4, m, n] {
            return Err(DspError::new_err(format!(
                "shape: samples must be (2, 4, {m}, {n}), got {:?}",
                samples.shape()
            )));
        }
        let corrections = Corrections {
            clock_error,
            velocity: vec3(velocity, "velocity")?,
            direction: vec3(direction, "direction")?,
            attitude: mat3(attitude, "attitude")?,
            omega_body: vec3(omega_body, "omega_body")?,
            epoch_time_s,
        };
        let flat: Vec<Complex32> = match samples.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => samples.as_array().iter().copied().collect(),
        };
        let inner = &mut self.inner;
        let f = py.detach(move || inner.process(&flat, &corrections)).map_err(lora_error)?;

        let d = PyDict::new(py);
        let per_chirp = |g: &dyn Fn(&scattertrack_dsp::lora::Peak) -> f64| -> Array3<f64> {
            Array3::from_shape_vec((2, 4, m), f.peaks.iter().map(g).collect()).expect("2 x 4 x M")
        };
        d.set_item("frequency_hz", per_chirp(&|p| p.frequency_hz).into_pyarray(py))?;
        d.set_item("frequency_sigma_hz", per_chirp(&|p| p.frequency_sigma_hz).into_pyarray(py))?;
        d.set_item("phase_sigma_rad", per_chirp(&|p| p.phase_sigma_rad).into_pyarray(py))?;
        d.set_item("snr_db", per_chirp(&|p| 10.0 * p.snr.max(1e-30).log10()).into_pyarray(py))?;
        let amplitude: Vec<Complex64> = f.peaks.iter().map(|p| p.amplitude_centre).collect();
        d.set_item("amplitude", Array3::from_shape_vec((2, 4, m), amplitude).expect("shape").into_pyarray(py))?;
        let start: Vec<Complex64> = f.peaks.iter().map(|p| p.amplitude).collect();
        d.set_item("amplitude_start", Array3::from_shape_vec((2, 4, m), start).expect("shape").into_pyarray(py))?;
        d.set_item(
            "phase_rad",
            Array3::from_shape_vec((2, 4, m), f.phases_rad.clone()).expect("shape").into_pyarray(py),
        )?;
        d.set_item(
            "carriers_hz",
            Array2::from_shape_vec((2, 4), f.carriers_hz.clone()).expect("shape").into_pyarray(py),
        )?;
        d.set_item("reference_time_s", f.reference_time_s)?;
        d.set_item(
            "pair_mean_hz",
            Array3::from_shape_vec((2, m, 2), f.pair_mean_hz.clone()).expect("shape").into_pyarray(py),
        )?;
        d.set_item(
            "rotational_hz",
            Array3::from_shape_vec((2, m, 2), f.rotational_hz.clone()).expect("shape").into_pyarray(py),
        )?;
        d.set_item(
            "translational_hz",
            Array2::from_shape_vec((2, 4), f.translational_hz.clone()).expect("shape").into_pyarray(py),
        )?;
        d.set_item("timing_hz", f.timing_hz)?;
        d.set_item("timing_sigma_hz", f.timing_sigma_hz)?;
        d.set_item("timing_range_m", f.timing_range_m)?;
        d.set_item("timing_range_sigma_m", f.timing_range_sigma_m)?;
        d.set_item("range_m", f.range.range_m)?;
        d.set_item("range_sigma_m", f.range.sigma_m)?;
        d.set_item("range_peak_m", f.range.peak_range_m)?;
        d.set_item("range_power", f.range.power)?;
        d.set_item("range_ambiguity", f.range.ambiguity)?;
        d.set_item("range_resolution_m", f.range.resolution_m)?;
        d.set_item("antenna_ranges_m", Array1::from(f.antenna_ranges_m.clone()).into_pyarray(py))?;
        let tags = |g: &dyn Fn(&scattertrack_dsp::lora::MusicEstimate) -> f64| -> Bound<'py, PyArray1<f64>> {
            f.tag_angles.iter().map(g).collect::<Vec<f64>>().into_pyarray(py)
        };
        d.set_item("tag_azimuth", tags(&|e| e.azimuth))?;
        d.set_item("tag_elevation", tags(&|e| e.elevation))?;
        d.set_item("tag_spectrum_db", tags(&|e| e.spectrum_db))?;
        d.set_item("tag_used", f.tag_used.clone())?;
        d.set_item("angle_spread_rad", f.angle_spread_rad)?;
        d.set_item("range_spread_m", f.range_spread_m)?;
        d.set_item("azimuth", f.azimuth)?;
        d.set_item("elevation", f.elevation)?;
        d.set_item("direction", f.direction.to_vec().into_pyarray(py))?;
        d.set_item("yaw", f.heading.map(|h| h.yaw))?;
        d.set_item("yaw_sigma_rad", f.heading.map(|h| h.sigma_rad))?;
        d.set_item("yaw_condition", f.heading.map(|h| h.condition))?;
        d.set_item("yaw_residual_hz", f.heading.map(|h| h.residual_rms_hz))?;
        d.set_item("mean_snr_db", f.snr_db)?;
        d.set_item("min_snr_db", f.min_snr_db)?;
        Ok(d)
    }
}

/// The sampled LoRa upchirp (or downchirp), complex128 (2^SF,).
#[pyfunction]
#[pyo3(signature = (spreading_factor=12, bandwidth_hz=500e3, down=false))]
fn lora_chirp(
    py: Python<'_>,
    spreading_factor: u32,
    bandwidth_hz: f64,
    down: bool,
) -> PyResult<Bound<'_, PyArray1<Complex64>>> {
    let c = ChirpConfig::new(spreading_factor, bandwidth_hz).map_err(lora_error)?;
    Ok(if down { c.downchirp() } else { c.upchirp() }.into_pyarray(py))
}

/// Dechirp + FFT peak of one chirp, complex64 (2^SF,).
#[pyfunction]
#[pyo3(signature = (samples, spreading_factor=12, bandwidth_hz=500e3, search_hz=None))]
fn lora_peak<'py>(
    py: Python<'py>,
    samples: PyReadonlyArray1<Complex32>,
    spreading_factor: u32,
    bandwidth_hz: f64,
    search_hz: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let c = ChirpConfig::new(spreading_factor, bandwidth_hz).map_err(lora_error)?;
    let mut finder = PeakFinder::new(c, PeakOptions { search_hz, ..PeakOptions::default() }).map_err(lora_error)?;
    let s: Vec<Complex32> = samples.as_array().iter().copied().collect();
    let p = finder.process(&s).map_err(lora_error)?;
    let d = PyDict::new(py);
    d.set_item("frequency_hz", p.frequency_hz)?;
    d.set_item("amplitude", PyComplex::from_doubles(py, p.amplitude.re, p.amplitude.im))?;
    d.set_item("amplitude_centre", PyComplex::from_doubles(py, p.amplitude_centre.re, p.amplitude_centre.im))?;
    d.set_item("snr", p.snr)?;
    d.set_item("noise_power", p.noise_power)?;
    d.set_item("frequency_sigma_hz", p.frequency_sigma_hz)?;
    d.set_item("phase_sigma_rad", p.phase_sigma_rad)?;
    d.set_item("bin", p.bin)?;
    Ok(d)
}

/// MUSIC direction from phases (M, N) rad at carriers (N,) Hz; elements
/// (M, 3) m (default: the 16 cm triangle).
#[pyfunction]
#[pyo3(signature = (phases_rad, frequencies_hz, elements=None, grid_deg=3.0, focus=false, sources=1))]
fn lora_music<'py>(
    py: Python<'py>,
    phases_rad: PyReadonlyArray2<f64>,
    frequencies_hz: PyReadonlyArray1<f64>,
    elements: Option<PyReadonlyArray2<f64>>,
    grid_deg: f64,
    focus: bool,
    sources: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let geometry = match elements {
        Some(e) => ArrayGeometry::new(rows3(e, "elements")?).map_err(lora_error)?,
        None => ArrayGeometry::triangle(0.16),
    };
    let config =
        MusicConfig { grid_step_rad: grid_deg.to_radians(), focus, sources, ..MusicConfig::for_array(&geometry) };
    let phases: Vec<f64> = phases_rad.as_array().iter().copied().collect();
    let freqs: Vec<f64> = frequencies_hz.as_array().to_vec();
    let e = music(&geometry, &config, &phases, &freqs).map_err(lora_error)?;
    let d = PyDict::new(py);
    d.set_item("azimuth", e.azimuth)?;
    d.set_item("elevation", e.elevation)?;
    d.set_item("direction", e.direction.to_vec())?;
    d.set_item("spectrum_db", e.spectrum_db)?;
    d.set_item("eigenvalues", e.eigenvalues)?;
    Ok(d)
}

/// Yaw from pair differences (eqs. 7-8 in 3D); None when undefined.
#[pyfunction]
#[pyo3(signature = (differences_hz, carriers_hz, tags_a, tags_b, sigmas_hz, roll_pitch, omega_body, direction,
    velocity=None, range_m=None, chirp_rate_hz_per_s=Some(500e3 / 8.192e-3), min_omega_rad_s=0.05))]
#[allow(clippy::too_many_arguments)]
fn lora_heading<'py>(
    py: Python<'py>,
    differences_hz: PyReadonlyArray1<f64>,
    carriers_hz: PyReadonlyArray1<f64>,
    tags_a: PyReadonlyArray2<f64>,
    tags_b: PyReadonlyArray2<f64>,
    sigmas_hz: PyReadonlyArray1<f64>,
    roll_pitch: PyReadonlyArray2<f64>,
    omega_body: PyReadonlyArray1<f64>,
    direction: PyReadonlyArray1<f64>,
    velocity: Option<PyReadonlyArray1<f64>>,
    range_m: Option<f64>,
    chirp_rate_hz_per_s: Option<f64>,
    min_omega_rad_s: f64,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let (d, f, s) = (differences_hz.as_array(), carriers_hz.as_array(), sigmas_hz.as_array());
    let (a, b) = (rows3(tags_a, "tags_a")?, rows3(tags_b, "tags_b")?);
    let n = d.len();
    if f.len() != n || s.len() != n || a.len() != n || b.len() != n {
        return Err(DspError::new_err("shape: one carrier, sigma and tag pair per difference"));
    }
    let observations: Vec<PairObservation> = (0..n)
        .map(|i| PairObservation { tag_a: a[i], tag_b: b[i], carrier_hz: f[i], difference_hz: d[i], sigma_hz: s[i] })
        .collect();
    let geometry = YawGeometry {
        roll_pitch: mat3(Some(roll_pitch), "roll_pitch")?.expect("given"),
        omega_body: vec3(Some(omega_body), "omega_body")?.expect("given"),
        direction: vec3(Some(direction), "direction")?.expect("given"),
        velocity: vec3(velocity, "velocity")?,
        range_m,
    };
    let config = HeadingConfig { min_omega_rad_s, chirp_rate_hz_per_s };
    let Some(h) = solve_yaw(&observations, &geometry, &config) else { return Ok(None) };
    let out = PyDict::new(py);
    out.set_item("yaw", h.yaw)?;
    out.set_item("sigma_rad", h.sigma_rad)?;
    out.set_item("condition", h.condition)?;
    out.set_item("residual_rms_hz", h.residual_rms_hz)?;
    Ok(Some(out))
}

/// Tags' clock error from peaks at rest, (O, 4) Hz.
#[pyfunction]
#[pyo3(signature = (peaks_hz, tag_shifts_hz=[1e6, 2e6, 3e6, 4e6], pairs=[(0, 1), (2, 3)]))]
fn lora_clock_error<'py>(
    py: Python<'py>,
    peaks_hz: PyReadonlyArray2<f64>,
    tag_shifts_hz: [f64; 4],
    pairs: [(usize, usize); 2],
) -> PyResult<Bound<'py, PyDict>> {
    let p = peaks_hz.as_array();
    if p.ncols() != 4 {
        return Err(DspError::new_err("shape: peaks_hz must be (observations, 4)"));
    }
    let rows: Vec<[f64; 4]> = p.rows().into_iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
    let e = estimate_clock_error(&tag_shifts_hz, &pairs, &rows).map_err(lora_error)?;
    let d = PyDict::new(py);
    d.set_item("clock_error", e.clock_error)?;
    d.set_item("sigma", e.sigma)?;
    d.set_item("timing_hz", e.timing_hz)?;
    d.set_item("observations", e.observations)?;
    Ok(d)
}

/// Registers the LoRa classes and functions in the `_core` module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<LoraEpochProcessor>()?;
    m.add_function(wrap_pyfunction!(lora_chirp, m)?)?;
    m.add_function(wrap_pyfunction!(lora_peak, m)?)?;
    m.add_function(wrap_pyfunction!(lora_music, m)?)?;
    m.add_function(wrap_pyfunction!(lora_heading, m)?)?;
    m.add_function(wrap_pyfunction!(lora_clock_error, m)?)?;
    Ok(())
}
