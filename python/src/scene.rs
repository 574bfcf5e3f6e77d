//! `_core.Scene`: a Python `scattertrack.io.Scene` read once, attribute by
//! attribute, into the core's scene (`scattertrack_core::scene::Scene`),
//! which `Engine`, `analyse_scene` and `twin_positions` then take as is.
//!
//! What is read: `dimensions`, `plane_z` (None → 0), `reader.phase_sign`,
//! `reader.period_rad`, `reader.phase_noise_rad` (None or 0 →
//! [`DEFAULT_PHASE_NOISE_RAD`]), `reader.kind`, and per antenna `id`,
//! `position`, `phase_offset_rad`; `region` (`min`, `max`) when not None.
//! A monostatic reader's scene (every kind but `sdr-helper`) also brings
//! its `channel_offsets` (`frequency_hz`, `phase_offset_rad`) and treats
//! every antenna as transmit-and-receive; a localization helper's scene
//! (`sdr-helper`) brings each antenna's `role` ("tx", "rx" or "txrx") for
//! the bistatic trackers, and no channel offsets (its frames are
//! calibrated per subcarrier). A monostatic scene's `reflectors` (when
//! the attribute exists: `kind` "plane" with `point`, `normal`, or "point"
//! with `position`; and `coefficient`) become the core's known reflectors.
//! A scene the core rejects is a ValueError with the core's message.

use nalgebra::Vector3;
use pyo3::prelude::*;

use scattertrack_core::scene::{Antenna, ChannelOffset, Reflector, Region, Role, Scene as CoreScene};

use crate::value_error;

/// The filter's prior phase noise when the scene states none
/// (docs/formats.md section 1), radians.
pub const DEFAULT_PHASE_NOISE_RAD: f64 = 0.1;

/// A scene as the core sees it, built once from a `scattertrack.io.Scene`.
#[pyclass(module = "scattertrack._core", name = "Scene", frozen)]
pub struct Scene {
    pub inner: CoreScene,
}

/// Three floats from a position-like attribute (array, list or tuple).
fn triple(value: &Bound<'_, PyAny>, what: &str) -> PyResult<Vector3<f64>> {
    let v: Vec<f64> = value.extract().map_err(|_| value_error(format!("{what} must be 3 numbers")))?;
    match v.as_slice() {
        [x, y, z] => Ok(Vector3::new(*x, *y, *z)),
        _ => Err(value_error(format!("{what} must have 3 entries, got {}", v.len()))),
    }
}

fn role(text: &str) -> PyResult<Role> {
    match text {
        "txrx" => Ok(Role::TxRx),
        "tx" => Ok(Role::Tx),
        "rx" => Ok(Role::Rx),
        other => Err(value_error(format!("antenna role must be txrx, tx or rx, got {other}"))),
    }
}

/// The core scene of a Python `scattertrack.io.Scene`.
pub fn core_scene(scene: &Bound<'_, PyAny>) -> PyResult<CoreScene> {
    // A negative count is the core's "dimensions must be 2 or 3", not an overflow.
    let dimensions = usize::try_from(scene.getattr("dimensions")?.extract::<i64>()?).unwrap_or(0);
    let plane_z: Option<f64> = scene.getattr("plane_z")?.extract()?;
    let reader = scene.getattr("reader")?;
    let kind: String = reader.getattr("kind")?.extract()?;
    let helper = kind == "sdr-helper";
    let phase_sign: f64 = reader.getattr("phase_sign")?.extract()?;
    let phase_period: f64 = reader.getattr("period_rad")?.extract()?;
    let noise: Option<f64> = reader.getattr("phase_noise_rad")?.extract()?;
    let phase_noise_rad = match noise {
        Some(n) if n != 0.0 => n,
        _ => DEFAULT_PHASE_NOISE_RAD,
    };
    let mut antennas = Vec::new();
    for a in scene.getattr("antennas")?.try_iter()? {
        let a = a?;
        let id: i64 = a.getattr("id")?.extract()?;
        let position = triple(&a.getattr("position")?, &format!("antenna {id} position"))?;
        let phase_offset_rad: f64 = a.getattr("phase_offset_rad")?.extract()?;
        let role = if helper { role(&a.getattr("role")?.extract::<String>()?)? } else { Role::TxRx };
        antennas.push(Antenna { id, position, phase_offset_rad, role });
    }
    let region = scene.getattr("region")?;
    let region = if region.is_none() {
        None
    } else {
        Some(Region { min: triple(&region.getattr("min")?, "region min")?, max: triple(&region.getattr("max")?, "region max")? })
    };
    let mut channels = Vec::new();
    if !helper {
        for c in scene.getattr("channel_offsets")?.try_iter()? {
            let c = c?;
            channels.push(ChannelOffset {
                frequency_hz: c.getattr("frequency_hz")?.extract()?,
                phase_offset_rad: c.getattr("phase_offset_rad")?.extract()?,
            });
        }
    }
    let reflectors = if helper { Vec::new() } else { reflectors(scene)? };
    CoreScene::new(dimensions, plane_z.unwrap_or(0.0), phase_sign, phase_period, phase_noise_rad, antennas, region, channels)
        .and_then(|s| s.with_reflectors(reflectors))
        .map_err(value_error)
}

/// The scene's `reflectors` (none when it has no such attribute).
pub(crate) fn reflectors(scene: &Bound<'_, PyAny>) -> PyResult<Vec<Reflector>> {
    let mut out = Vec::new();
    if !scene.hasattr("reflectors")? {
        return Ok(out);
    }
    for (i, r) in scene.getattr("reflectors")?.try_iter()?.enumerate() {
        let r = r?;
        let kind: String = r.getattr("kind")?.extract()?;
        let coefficient: f64 = r.getattr("coefficient")?.extract()?;
        out.push(match kind.as_str() {
            "plane" => Reflector::Plane {
                point: triple(&r.getattr("point")?, &format!("reflector {i} point"))?,
                normal: triple(&r.getattr("normal")?, &format!("reflector {i} normal"))?,
                coefficient,
            },
            "point" => Reflector::Point { position: triple(&r.getattr("position")?, &format!("reflector {i} position"))?, coefficient },
            other => return Err(value_error(format!("reflector {i}: kind must be plane or point, got {other}"))),
        });
    }
    Ok(out)
}

#[pymethods]
impl Scene {
    /// Reads `scene` (a `scattertrack.io.Scene`) once; ValueError for a
    /// scene the core rejects.
    #[new]
    fn new(scene: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self { inner: core_scene(scene)? })
    }

    /// 2 or 3.
    #[getter]
    fn dimensions(&self) -> usize {
        self.inner.dimensions
    }

    /// Number of antennas (trackers index them 0..n in the scene's order).
    #[getter]
    fn antennas(&self) -> usize {
        self.inner.antennas.len()
    }

    /// The prior phase noise the trackers use, radians (the scene's, or the default).
    #[getter]
    fn phase_noise_rad(&self) -> f64 {
        self.inner.phase_noise_rad
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene(dimensions={}, antennas={}, phase_noise_rad={}, region={}, channel_offsets={}, reflectors={})",
            self.inner.dimensions,
            self.inner.antennas.len(),
            self.inner.phase_noise_rad,
            self.inner.region.is_some(),
            self.inner.channel_offsets.len(),
            self.inner.reflectors.len()
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add("DEFAULT_PHASE_NOISE_RAD", DEFAULT_PHASE_NOISE_RAD)?;
    Ok(())
}
