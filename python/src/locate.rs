//! Bindings of the static-tag phase search (`scattertrack_core::locate`):
//! one call for every tag's candidates (threaded in the core), one per
//! antenna for its hop range.

use nalgebra::{Complex, Vector3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use scattertrack_core::locate::{self, batch::TagBatch, Paths, Settings};
use scattertrack_core::model::reflected_paths;
use scattertrack_core::scene::checked_reflectors;

use crate::scene::reflectors;
use crate::value_error;

fn phasors(re: &PyReadonlyArray1<f64>, im: &PyReadonlyArray1<f64>) -> PyResult<Vec<Complex<f64>>> {
    let (re, im) = (re.as_slice()?, im.as_slice()?);
    if re.len() != im.len() {
        return Err(value_error("z_re and z_im must have one entry per read"));
    }
    Ok(re.iter().zip(im).map(|(a, b)| Complex::new(*a, *b)).collect())
}

fn points(array: &PyReadonlyArray2<f64>, what: &str) -> PyResult<Vec<Vector3<f64>>> {
    let view = array.as_array();
    if view.ncols() != 3 {
        return Err(value_error(format!("{what} must be (n, 3)")));
    }
    Ok(view.rows().into_iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect())
}

/// Every tag's phase candidates (`scattertrack_core::locate::phase_candidates`),
/// tags in rows `bounds[t]..bounds[t+1]`, each searched in its box
/// `low[t]..high[t]`, on `threads` threads (0: every core). Returns flat
/// arrays over all candidates — positions (c, 3) m, covariances (c, 3, 3)
/// m², weights (c,), coherences (c,) — and `candidate_bounds` (tags + 1,):
/// tag t's candidates, best first, are rows `candidate_bounds[t]..[t+1]`.
/// `scene`: an object whose `reflectors` (a `scattertrack.io.Scene`'s)
/// enter the phase model, with `phase_multiplier` m of k = m s 4π f / c.
#[pyfunction]
#[pyo3(signature = (z_re, z_im, k, time_s, antenna, anchors, bounds, low, high, axes, *, temperature, bias_sigma_rad, correlation_s, max_candidates, min_weight, hopping_spread_hz, max_points=100_000, threads=0, scene=None, phase_multiplier=1.0))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn locate_batch<'py>(
    py: Python<'py>,
    z_re: PyReadonlyArray1<f64>,
    z_im: PyReadonlyArray1<f64>,
    k: PyReadonlyArray1<f64>,
    time_s: PyReadonlyArray1<f64>,
    antenna: PyReadonlyArray1<i64>,
    anchors: PyReadonlyArray2<f64>,
    bounds: PyReadonlyArray1<i64>,
    low: PyReadonlyArray2<f64>,
    high: PyReadonlyArray2<f64>,
    axes: usize,
    temperature: f64,
    bias_sigma_rad: f64,
    correlation_s: f64,
    max_candidates: usize,
    min_weight: f64,
    hopping_spread_hz: f64,
    max_points: usize,
    threads: usize,
    scene: Option<Bound<'py, PyAny>>,
    phase_multiplier: f64,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, numpy::PyArray3<f64>>, Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<i64>>)> {
    let z = phasors(&z_re, &z_im)?;
    let (k, time_s) = (k.as_slice()?, time_s.as_slice()?);
    let anchor_points = points(&anchors, "anchors")?;
    let antenna = anchor_indices(antenna.as_slice()?, anchor_points.len())?;
    if k.len() != z.len() || time_s.len() != z.len() || antenna.len() != z.len() {
        return Err(value_error("z, k, time_s and antenna must have one entry per read"));
    }
    let bounds: Vec<usize> = bounds.as_slice()?.iter().map(|&b| usize::try_from(b).unwrap_or(usize::MAX)).collect();
    if bounds.first().is_some_and(|&b| b != 0) || bounds.windows(2).any(|w| w[0] > w[1]) || bounds.last().is_some_and(|&b| b != z.len()) {
        return Err(value_error("bounds must rise from 0 to the number of reads"));
    }
    let (low, high) = (points(&low, "low")?, points(&high, "high")?);
    let tags = bounds.len().saturating_sub(1);
    if low.len() != tags || high.len() != tags {
        return Err(value_error("low and high need one row per tag"));
    }
    if !(axes == 2 || axes == 3) {
        return Err(value_error("axes must be 2 or 3"));
    }
    let known = match &scene {
        Some(scene) => checked_reflectors(reflectors(scene)?).map_err(value_error)?,
        None => Vec::new(),
    };
    if !(phase_multiplier == 1.0 || phase_multiplier == 2.0) {
        return Err(value_error("phase_multiplier must be 1 (mod 2π) or 2 (mod π)"));
    }
    // Antennas without a path (or no reflectors at all) keep the direct model (`PhaseReads::with_paths`).
    let per_anchor: Vec<_> = anchor_points.iter().map(|a| reflected_paths(a, &known)).collect();
    let settings = Settings { temperature, bias_sigma_rad, correlation_s, max_candidates, min_weight, hopping_spread_hz, max_points };
    let threads = if threads == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { threads };
    let found = py.detach(|| {
        let batch = TagBatch { z: &z, k, time_s, antenna: &antenna, anchors: &anchor_points, bounds: &bounds, low: &low, high: &high, paths: Some(Paths { per_anchor: &per_anchor, phase_multiplier }) };
        locate::locate_batch(&batch, axes, &settings, threads)
    });
    let all: Vec<&locate::Candidate> = found.iter().flatten().collect();
    let positions = numpy::ndarray::Array2::from_shape_fn((all.len(), 3), |(i, j)| all[i].position[j]);
    let covariances = numpy::ndarray::Array3::from_shape_fn((all.len(), 3, 3), |(i, r, c)| all[i].covariance[(r, c)]);
    let weights: Vec<f64> = all.iter().map(|c| c.weight).collect();
    let coherences: Vec<f64> = all.iter().map(|c| c.coherence).collect();
    let mut candidate_bounds = vec![0i64];
    for tag in &found {
        candidate_bounds.push(candidate_bounds.last().copied().unwrap_or(0) + tag.len() as i64);
    }
    Ok((positions.into_pyarray(py), covariances.into_pyarray(py), weights.into_pyarray(py), coherences.into_pyarray(py), candidate_bounds.into_pyarray(py)))
}

fn anchor_indices(antenna: &[i64], anchors: usize) -> PyResult<Vec<usize>> {
    antenna
        .iter()
        .map(|&a| usize::try_from(a).ok().filter(|&a| a < anchors).ok_or_else(|| value_error(format!("antenna index {a} is not an anchor"))))
        .collect()
}

/// One antenna's (range m, 1-sigma m) from its reads over several channels, or None.
#[pyfunction]
fn locate_hop_range(z_re: PyReadonlyArray1<f64>, z_im: PyReadonlyArray1<f64>, k: PyReadonlyArray1<f64>, max_range_m: f64) -> PyResult<Option<(f64, f64)>> {
    let z = phasors(&z_re, &z_im)?;
    let k = k.as_slice()?;
    if k.len() != z.len() {
        return Err(value_error("z and k must have one entry per read"));
    }
    Ok(locate::hop_range(&z, k, None, max_range_m))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(locate_batch, m)?)?;
    m.add_function(wrap_pyfunction!(locate_hop_range, m)?)?;
    Ok(())
}
