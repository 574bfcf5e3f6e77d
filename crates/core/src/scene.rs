//! The hardware set-up: antennas, reader phase conventions, calibration and
//! the region where tags can be (docs/formats.md section 1).
//!
//! Phase model (monostatic COTS reader), for a tag at distance `d` (m) from
//! antenna `a`, carrier `f` (Hz), wavelength `λ = c / f`:
//!
//! `φ = (s · 4π d / λ + θ_a + θ_ch(f) + noise) mod P`
//!
//! with `s = ±1` the phase sign and `P = 2π` (or `π` for readers that
//! report mod π). The `4π` is the round trip: the wave travels `2d`.

use nalgebra::Vector3;

use crate::angle::{wrap, TWO_PI};
use crate::error::{Error, Result};

/// Speed of light in vacuum, m/s.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// What an antenna does (docs/formats.md §1 `role`): a COTS reader's ports
/// transmit and receive; a localization helper has one transmit antenna
/// and several receive antennas (bistatic).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Role {
    #[default]
    TxRx,
    Tx,
    Rx,
}

/// One antenna port.
#[derive(Debug, Clone, PartialEq)]
pub struct Antenna {
    /// Port number as the reader reports it.
    pub id: i64,
    /// Phase centre in the world frame, metres.
    pub position: Vector3<f64>,
    /// Calibrated cable/port phase offset θ_a, radians.
    pub phase_offset_rad: f64,
    /// Transmit, receive or both.
    pub role: Role,
}

/// Axis-aligned box where tags can be, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
}

impl Region {
    /// Whether `p` (m) lies inside the box grown by `margin` (m) on every
    /// side; with `dimensions == 2` only x and y are checked (the tag is on
    /// the plane by construction).
    pub fn contains(&self, p: &Vector3<f64>, margin: f64, dimensions: usize) -> bool {
        (0..dimensions.min(3)).all(|i| p[i] >= self.min[i] - margin && p[i] <= self.max[i] + margin)
    }

    /// The point of the box grown by `margin` (m) nearest `p` (m), axis by
    /// axis; with `dimensions == 2` z is left as it is (as in `contains`).
    pub fn clamp(&self, p: &Vector3<f64>, margin: f64, dimensions: usize) -> Vector3<f64> {
        Vector3::from_fn(|i, _| if i < dimensions.min(3) { p[i].clamp(self.min[i] - margin, self.max[i] + margin) } else { p[i] })
    }

    /// Smallest and largest distance (m) from `point` to the box.
    pub fn distance_range(&self, point: &Vector3<f64>) -> (f64, f64) {
        let mut near = 0.0;
        let mut far = 0.0;
        for i in 0..3 {
            let (lo, hi) = (self.min[i] - point[i], self.max[i] - point[i]);
            let n = if lo > 0.0 { lo } else if hi < 0.0 { hi } else { 0.0 };
            let f = lo.abs().max(hi.abs());
            near += n * n;
            far += f * f;
        }
        (near.sqrt(), far.sqrt())
    }
}

/// A calibrated per-channel phase offset θ_ch(f).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelOffset {
    /// Carrier frequency, Hz (matched within 1 kHz).
    pub frequency_hz: f64,
    /// Offset, radians.
    pub phase_offset_rad: f64,
}

/// A reflector the user knows of (docs/formats.md section 1,
/// `[[reflectors]]`): it adds a path to every read
/// ([`crate::model::apparent_range`]). Γ is the signed amplitude
/// reflection coefficient, |Γ| ≤ 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reflector {
    /// A flat wall, floor or ceiling through `point` (m) with unit `normal`.
    Plane { point: Vector3<f64>, normal: Vector3<f64>, coefficient: f64 },
    /// A small scatterer at `position` (m).
    Point { position: Vector3<f64>, coefficient: f64 },
}

/// A monostatic reader set-up as the trackers see it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// 2: the tag moves in the plane z = `plane_z`; 3: free in space.
    pub dimensions: usize,
    /// Height of the motion plane for 2D scenes, metres.
    pub plane_z: f64,
    /// +1: phase grows with distance; −1: it shrinks.
    pub phase_sign: f64,
    /// Phase period P, radians: 2π, or π for readers that report mod π.
    pub phase_period: f64,
    /// Prior 1-sigma phase noise, radians (the papers assume 0.1).
    pub phase_noise_rad: f64,
    pub antennas: Vec<Antenna>,
    pub region: Option<Region>,
    pub channel_offsets: Vec<ChannelOffset>,
    /// Known reflectors (empty: the single-path model); set with
    /// [`Scene::with_reflectors`].
    pub reflectors: Vec<Reflector>,
}

impl Scene {
    /// The plus-shaped localization-helper layout the tests, benches and
    /// examples share: the transmitter at (0.4, 0.4, 0) m, four receivers
    /// 40 cm around it in z = 0, a region in front of the array, 0.1 rad
    /// phase noise. `dimensions` 2 tracks in the plane z = `plane_z`.
    pub fn plus_helper(dimensions: usize, plane_z: f64) -> Self {
        let layout = [((0.4, 0.4), Role::Tx), ((0.0, 0.4), Role::Rx), ((0.8, 0.4), Role::Rx), ((0.4, 0.0), Role::Rx), ((0.4, 0.8), Role::Rx)];
        let antennas = layout
            .iter()
            .enumerate()
            .map(|(i, ((x, y), role))| Antenna { id: i as i64, position: Vector3::new(*x, *y, 0.0), phase_offset_rad: 0.0, role: *role })
            .collect();
        let region = Region { min: Vector3::new(-1.0, -0.5, 0.05), max: Vector3::new(2.0, 3.0, 2.0) };
        Self::new(dimensions, plane_z, 1.0, TWO_PI, 0.1, antennas, Some(region), vec![]).expect("the plus layout is a valid scene")
    }

    /// A validated scene. Fails on no antennas, dimensions ∉ {2, 3}, a
    /// phase sign other than ±1, a period other than 2π or π, or an empty
    /// region.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dimensions: usize,
        plane_z: f64,
        phase_sign: f64,
        phase_period: f64,
        phase_noise_rad: f64,
        antennas: Vec<Antenna>,
        region: Option<Region>,
        channel_offsets: Vec<ChannelOffset>,
    ) -> Result<Self> {
        let bad = |m: &str| Err(Error::Scene(m.to_string()));
        if antennas.is_empty() {
            return bad("no antennas");
        }
        if dimensions != 2 && dimensions != 3 {
            return bad("dimensions must be 2 or 3");
        }
        if phase_sign != 1.0 && phase_sign != -1.0 {
            return bad("phase_sign must be +1 or -1");
        }
        let is_pi = (phase_period - std::f64::consts::PI).abs() < 1e-9;
        if !is_pi && (phase_period - TWO_PI).abs() > 1e-9 {
            return bad("phase_period must be 2π or π");
        }
        if !(phase_noise_rad > 0.0 && phase_noise_rad.is_finite()) {
            return bad("phase_noise_rad must be positive");
        }
        if let Some(r) = &region {
            if (0..3).any(|i| r.min[i] > r.max[i]) {
                return bad("region min > max");
            }
        }
        let finite = antennas.iter().all(|a| a.position.iter().all(|v| v.is_finite()));
        if !finite || !plane_z.is_finite() {
            return bad("non-finite antenna position or plane_z");
        }
        Ok(Self {
            dimensions,
            plane_z,
            phase_sign,
            phase_period: if is_pi { std::f64::consts::PI } else { TWO_PI },
            phase_noise_rad,
            antennas,
            region,
            channel_offsets,
            reflectors: Vec::new(),
        })
    }

    /// The scene with known `reflectors` (normals made unit). Fails on a
    /// non-finite value, a zero normal or |Γ| > 1 ([`checked_reflectors`]).
    pub fn with_reflectors(mut self, reflectors: Vec<Reflector>) -> Result<Self> {
        self.reflectors = checked_reflectors(reflectors)?;
        Ok(self)
    }

    /// Calibrated offset θ_ch(f) of the channel within 1 kHz of `frequency_hz`; 0 if none.
    pub fn channel_offset(&self, frequency_hz: f64) -> f64 {
        self.channel_offsets
            .iter()
            .find(|c| (c.frequency_hz - frequency_hz).abs() <= 1e3)
            .map_or(0.0, |c| c.phase_offset_rad)
    }

    /// Range per radian of round-trip phase, λ/4π (m/rad): σ_d = σ_φ λ/4π
    /// turns a phase error into a range error (the phase turns 4π per
    /// wavelength of range).
    #[inline]
    pub fn range_per_radian(frequency_hz: f64) -> f64 {
        SPEED_OF_LIGHT / (4.0 * std::f64::consts::PI * frequency_hz)
    }

    /// Distance ambiguity step `s = P λ / 4π` (m): λ/2 for 2π readers,
    /// λ/4 for mod-π readers. Round trip: phase advances 4π per λ of range.
    #[inline]
    pub fn candidate_spacing(&self, frequency_hz: f64) -> f64 {
        self.phase_period * SPEED_OF_LIGHT / (4.0 * std::f64::consts::PI * frequency_hz)
    }

    /// The distance residue `d0 ∈ [0, s)` (m) of a reading: every distance
    /// `d0 + n s` (n integer) explains the phase. Offsets are subtracted
    /// and the sign applied first: `ψ = s_φ (φ − θ_a − θ_ch) mod P`,
    /// `d0 = ψ λ / 4π`.
    #[inline]
    pub fn distance_residue(&self, antenna: usize, frequency_hz: f64, phase_rad: f64) -> f64 {
        let offset = self.antennas[antenna].phase_offset_rad + self.channel_offset(frequency_hz);
        let psi = wrap(self.phase_sign * (phase_rad - offset), self.phase_period);
        psi * SPEED_OF_LIGHT / (4.0 * std::f64::consts::PI * frequency_hz)
    }

    /// Distances (m) from antenna `antenna` that the region allows, or a
    /// generous default (0 – 15 m, beyond any passive-tag range) without one.
    pub fn distance_bounds(&self, antenna: usize) -> (f64, f64) {
        match &self.region {
            Some(r) => {
                let mut reg = r.clone();
                if self.dimensions == 2 {
                    reg.min[2] = self.plane_z;
                    reg.max[2] = self.plane_z;
                }
                reg.distance_range(&self.antennas[antenna].position)
            }
            None => (0.0, 15.0),
        }
    }

    /// Index of the helper's transmit antenna (`role = "tx"`), if any.
    pub fn transmitter(&self) -> Option<usize> {
        self.antennas.iter().position(|a| a.role == Role::Tx)
    }

    /// Indices of the helper's receive antennas (`role = "rx"`).
    pub fn receivers(&self) -> Vec<usize> {
        (0..self.antennas.len()).filter(|&i| self.antennas[i].role == Role::Rx).collect()
    }

    /// Phase (rad, in [0, P)) that an ideal reader reports for a tag at
    /// `distance` m: the forward model the simulators and tests share.
    pub fn ideal_phase(&self, antenna: usize, frequency_hz: f64, distance: f64) -> f64 {
        let lambda = SPEED_OF_LIGHT / frequency_hz;
        let offset = self.antennas[antenna].phase_offset_rad + self.channel_offset(frequency_hz);
        wrap(self.phase_sign * 4.0 * std::f64::consts::PI * distance / lambda + offset, self.phase_period)
    }
}

/// `reflectors` with their normals made unit. Fails on a non-finite value,
/// a zero normal or |Γ| > 1.
pub fn checked_reflectors(reflectors: Vec<Reflector>) -> Result<Vec<Reflector>> {
    let bad = |m: String| Err(Error::Scene(m));
    let finite = |v: &Vector3<f64>| v.iter().all(|c| c.is_finite());
    let mut out = Vec::with_capacity(reflectors.len());
    for (i, r) in reflectors.into_iter().enumerate() {
        let (coefficient, r) = match r {
            Reflector::Plane { point, normal, coefficient } => {
                let length = normal.norm();
                if !finite(&point) || !finite(&normal) || !(length > 1e-12) {
                    return bad(format!("reflector {i}: plane needs a finite point and a nonzero normal"));
                }
                (coefficient, Reflector::Plane { point, normal: normal / length, coefficient })
            }
            Reflector::Point { position, coefficient } => {
                if !finite(&position) {
                    return bad(format!("reflector {i}: non-finite position"));
                }
                (coefficient, r)
            }
        };
        if !(coefficient.abs() <= 1.0) {
            return bad(format!("reflector {i}: coefficient must be in [-1, 1]"));
        }
        out.push(r);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn glac_scene(dimensions: usize) -> Scene {
        let pos = [[0.0, 0.0], [0.0, 0.3], [0.0, 0.8], [0.8, 0.8]];
        let antennas = pos
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::new(p[0], p[1], 0.0), phase_offset_rad: 0.3 * i as f64, role: Default::default() })
            .collect();
        Scene::new(dimensions, 0.0, -1.0, TWO_PI, 0.1, antennas, None, vec![]).unwrap()
    }

    #[test]
    fn reflectors_are_validated_and_their_normals_made_unit() {
        let plane = |normal: Vector3<f64>, coefficient: f64| Reflector::Plane { point: Vector3::new(1.6, 0.0, 0.0), normal, coefficient };
        let scene = glac_scene(3).with_reflectors(vec![plane(Vector3::new(-2.0, 0.0, 0.0), 0.3)]).unwrap();
        match scene.reflectors[0] {
            Reflector::Plane { normal, .. } => assert!((normal - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-15),
            _ => unreachable!(),
        }
        assert!(glac_scene(3).with_reflectors(vec![plane(Vector3::zeros(), 0.3)]).is_err(), "zero normal");
        assert!(glac_scene(3).with_reflectors(vec![plane(Vector3::new(1.0, 0.0, 0.0), 1.5)]).is_err(), "|coefficient| > 1");
        assert!(glac_scene(3).with_reflectors(vec![plane(Vector3::new(1.0, 0.0, 0.0), f64::NAN)]).is_err(), "NaN coefficient");
        let point = Reflector::Point { position: Vector3::new(f64::INFINITY, 0.0, 0.0), coefficient: 0.1 };
        assert!(glac_scene(3).with_reflectors(vec![point]).is_err(), "non-finite position");
        assert!(glac_scene(3).reflectors.is_empty(), "none unless given");
    }

    #[test]
    fn residue_inverts_ideal_phase() {
        let scene = glac_scene(3);
        for k in 0..200 {
            let d = 0.2 + k as f64 * 0.0123;
            let f = 902.75e6 + (k % 50) as f64 * 0.5e6;
            let phi = scene.ideal_phase(1, f, d);
            let d0 = scene.distance_residue(1, f, phi);
            let s = scene.candidate_spacing(f);
            let n = ((d - d0) / s).round();
            assert!((d0 + n * s - d).abs() < 1e-9, "d={d} d0={d0}");
        }
    }

    #[test]
    fn region_clamp_is_the_nearest_point_that_contains_accepts() {
        let r = Region { min: Vector3::new(0.0, 0.0, 0.0), max: Vector3::new(1.0, 2.0, 0.0) };
        let p = Vector3::new(-0.5, 1.0, 0.7);
        let c = r.clamp(&p, 0.1, 3);
        assert_eq!(c, Vector3::new(-0.1, 1.0, 0.1));
        assert!(r.contains(&c, 0.1, 3) && !r.contains(&p, 0.1, 3));
        // In a planar scene z is not the region's to move.
        assert_eq!(r.clamp(&p, 0.1, 2), Vector3::new(-0.1, 1.0, 0.7));
        assert_eq!(r.clamp(&Vector3::new(0.5, 1.0, 0.0), 0.0, 3), Vector3::new(0.5, 1.0, 0.0));
    }

    #[test]
    fn region_distance_range() {
        let r = Region { min: Vector3::new(1.0, 0.0, 0.0), max: Vector3::new(2.0, 1.0, 1.0) };
        let (near, far) = r.distance_range(&Vector3::zeros());
        assert!((near - 1.0).abs() < 1e-12);
        assert!((far - 6f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn rejects_bad_scenes() {
        assert!(Scene::new(3, 0.0, 1.0, TWO_PI, 0.1, vec![], None, vec![]).is_err());
        let a = vec![Antenna { id: 1, position: Vector3::zeros(), phase_offset_rad: 0.0, role: Default::default() }];
        assert!(Scene::new(4, 0.0, 1.0, TWO_PI, 0.1, a.clone(), None, vec![]).is_err());
        assert!(Scene::new(3, 0.0, 0.5, TWO_PI, 0.1, a.clone(), None, vec![]).is_err());
        assert!(Scene::new(3, 0.0, 1.0, 1.0, 0.1, a, None, vec![]).is_err());
    }
}
