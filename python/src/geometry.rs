//! Bindings of the scene geometry check (`scattertrack_core::geometry::ambiguity`):
//! one call for the whole analysis, one for the twins of one position.
//! Plain dicts and lists cross the boundary; the Python side words them.

use nalgebra::Vector3;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use scattertrack_core::geometry::ambiguity::{self, AmbiguityOptions, FamilyKind, LayoutKind};

use crate::scene::Scene;
use crate::value_error;

fn triple(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn options(evidence_reads: Option<f64>, remedies: bool) -> AmbiguityOptions {
    let mut o = AmbiguityOptions { remedies, ..AmbiguityOptions::default() };
    if let Some(n) = evidence_reads {
        o.tolerance.evidence_reads = n;
    }
    o
}

/// The scene's layout findings and twin families on the channels of
/// `read_frequencies` (Hz, most-read first; see `joint_frequencies`).
#[pyfunction]
#[pyo3(signature = (scene, read_frequencies, evidence_reads=None, remedies=true))]
fn analyse_scene<'py>(
    py: Python<'py>,
    scene: PyRef<'_, Scene>,
    read_frequencies: Vec<f64>,
    evidence_reads: Option<f64>,
    remedies: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let scene = &scene.inner;
    let opts = options(evidence_reads, remedies);
    let frequencies = ambiguity::joint_frequencies(scene, &read_frequencies);
    let report = py.detach(|| ambiguity::analyse_scene(scene, &frequencies, &opts)).map_err(value_error)?;
    let out = PyDict::new(py);
    let layout = PyList::empty(py);
    for f in &report.layout {
        let d = PyDict::new(py);
        d.set_item("kind", match f.kind { LayoutKind::Coincident => "coincident", LayoutKind::Collinear => "collinear", LayoutKind::Coplanar => "coplanar" })?;
        d.set_item("antennas", &f.antennas)?;
        d.set_item("deviation_m", f.deviation_m)?;
        d.set_item("plane", f.plane.map(|(p, n)| (triple(&p), triple(&n))))?;
        layout.append(d)?;
    }
    let families = PyList::empty(py);
    for f in &report.families {
        let d = PyDict::new(py);
        let kind = match f.kind {
            FamilyKind::Mirror => "mirror",
            FamilyKind::Line => "line",
            FamilyKind::AllAntennas => "all-antennas",
            FamilyKind::TooFewAntennas => "too-few-antennas",
            FamilyKind::Other => "other",
        };
        d.set_item("kind", kind)?;
        d.set_item("free", &f.free)?;
        d.set_item("line", &f.line)?;
        d.set_item("shifts", &f.shifts)?;
        d.set_item("share", f.share)?;
        d.set_item("median_m", f.median_m)?;
        d.set_item("min_m", f.min_m)?;
        d.set_item("max_m", f.max_m)?;
        d.set_item("residual_sigma", f.residual_sigma)?;
        d.set_item("exact", f.exact)?;
        d.set_item("warning", f.is_warning())?;
        let r = &f.remedy;
        d.set_item("move_antenna", r.move_antenna)?;
        d.set_item("away_from", &r.away_from)?;
        d.set_item("direction", triple(&r.direction))?;
        d.set_item("offset_m", r.offset_m)?;
        d.set_item("hopping_breaks", r.hopping_breaks)?;
        d.set_item("region_plane", r.region_plane.map(|(p, n)| (triple(&p), triple(&n))))?;
        families.append(d)?;
    }
    out.set_item("layout", layout)?;
    out.set_item("families", families)?;
    out.set_item("frequencies_hz", &report.frequencies_hz)?;
    out.set_item("samples", report.samples)?;
    out.set_item("shifts_tried", report.shifts_tried)?;
    out.set_item("bounds", (triple(&report.bounds.0), triple(&report.bounds.1)))?;
    out.set_item("region_given", report.region_given)?;
    out.set_item("inconclusive", report.inconclusive.clone())?;
    out.set_item("evidence_reads", opts.tolerance.evidence_reads)?;
    out.set_item("sigma_multiple", opts.tolerance.sigma_multiple)?;
    out.set_item("persistence_step_m", opts.persistence_step_m)?;
    out.set_item("max_single_shift", opts.max_single_shift)?;
    out.set_item("layout_tolerance_m", opts.layout_tolerance_m)?;
    Ok(out)
}

/// Twins of `position` (m) on `frequencies` (Hz, analysed jointly):
/// `[(position, shift, chi_square)]`, nearest first (full shift set).
#[pyfunction]
#[pyo3(signature = (scene, position, frequencies, evidence_reads=None))]
fn twin_positions(
    py: Python<'_>,
    scene: PyRef<'_, Scene>,
    position: [f64; 3],
    frequencies: Vec<f64>,
    evidence_reads: Option<f64>,
) -> PyResult<Vec<([f64; 3], Vec<i32>, f64)>> {
    let scene = &scene.inner;
    let opts = options(evidence_reads, false);
    let p = Vector3::from(position);
    let twins = py.detach(|| ambiguity::twin_positions(scene, &p, &frequencies, &opts)).map_err(value_error)?;
    Ok(twins.into_iter().map(|t| (triple(&t.position), t.shift, t.chi_square)).collect())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(analyse_scene, m)?)?;
    m.add_function(wrap_pyfunction!(twin_positions, m)?)?;
    Ok(())
}
