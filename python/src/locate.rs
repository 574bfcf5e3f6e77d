//! Bindings of the static-tag phase search (`scattertrack_core::locate`):
//! one call per tag for its candidates, one per antenna for its hop range.

use nalgebra::{Complex, Vector3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use scattertrack_core::locate::{self, PhaseReads};

use crate::value_error;

fn phasors(re: &PyReadonlyArray1<f64>, im: &PyReadonlyArray1<f64>) -> PyResult<Vec<Complex<f64>>> {
    let (re, im) = (re.as_slice()?, im.as_slice()?);
    if re.len() != im.len() {
        return Err(value_error("z_re and z_im must have one entry per read"));
    }
    Ok(re.iter().zip(im).map(|(a, b)| Complex::new(*a, *b)).collect())
}

/// Candidates of one tag inside the box [low, high]: positions (c, 3) m and
/// their coherence (c,), best first.
#[pyfunction]
#[pyo3(signature = (z_re, z_im, k, antenna, anchors, low, high, axes, max_points=100_000, max_seeds=20))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn locate_search<'py>(
    py: Python<'py>,
    z_re: PyReadonlyArray1<f64>,
    z_im: PyReadonlyArray1<f64>,
    k: PyReadonlyArray1<f64>,
    antenna: PyReadonlyArray1<i64>,
    anchors: PyReadonlyArray2<f64>,
    low: [f64; 3],
    high: [f64; 3],
    axes: usize,
    max_points: usize,
    max_seeds: usize,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
    let z = phasors(&z_re, &z_im)?;
    let k = k.as_slice()?.to_vec();
    let anchors_array = anchors.as_array();
    if anchors_array.ncols() != 3 {
        return Err(value_error("anchors must be (m, 3)"));
    }
    let anchor_points: Vec<Vector3<f64>> = anchors_array.rows().into_iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect();
    let antenna: Vec<usize> = antenna
        .as_slice()?
        .iter()
        .map(|&a| usize::try_from(a).ok().filter(|&a| a < anchor_points.len()).ok_or_else(|| value_error(format!("antenna index {a} is not an anchor"))))
        .collect::<PyResult<_>>()?;
    if k.len() != z.len() || antenna.len() != z.len() {
        return Err(value_error("z, k and antenna must have one entry per read"));
    }
    if !(axes == 2 || axes == 3) {
        return Err(value_error("axes must be 2 or 3"));
    }
    let found = py.detach(|| {
        let reads = PhaseReads { z: &z, k: &k, antenna: &antenna, anchors: &anchor_points };
        locate::search(&reads, Vector3::from(low), Vector3::from(high), axes, max_points, max_seeds)
    });
    let positions = numpy::ndarray::Array2::from_shape_fn((found.len(), 3), |(i, j)| found[i].0[j]);
    let coherence: Vec<f64> = found.iter().map(|c| c.1).collect();
    Ok((positions.into_pyarray(py), coherence.into_pyarray(py)))
}

/// One antenna's (range m, 1-sigma m) from its reads over several channels, or None.
#[pyfunction]
fn locate_hop_range(z_re: PyReadonlyArray1<f64>, z_im: PyReadonlyArray1<f64>, k: PyReadonlyArray1<f64>, max_range_m: f64) -> PyResult<Option<(f64, f64)>> {
    let z = phasors(&z_re, &z_im)?;
    let k = k.as_slice()?;
    if k.len() != z.len() {
        return Err(value_error("z and k must have one entry per read"));
    }
    Ok(locate::hop_range(&z, k, max_range_m))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(locate_search, m)?)?;
    m.add_function(wrap_pyfunction!(locate_hop_range, m)?)?;
    Ok(())
}
