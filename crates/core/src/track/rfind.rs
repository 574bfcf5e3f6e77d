//! RFind-style localisation of a static tag (the TurboTrack thesis's
//! baseline, §6 and Table 7.1, after its ref. [46]): the channel is
//! gathered over many frames — and over every frequency the helper hopped
//! to — for `rfind_window_s` seconds, assuming the tag does not move;
//! the coherent average per (receiver, frequency) is one wideband channel
//! per receiver whose strongest distance candidate gives an ellipsoid;
//! their intersections' centroid is refined by Gauss–Newton on all
//! receivers' path lengths. Motion during the window smears the average,
//! which is why the thesis finds RFind degrading "even at speeds as low as
//! 2 cm/s".

use std::collections::{BTreeMap, VecDeque};

use nalgebra::{Complex, Matrix3, Vector3};

use crate::error::{Error, Result};
use crate::geometry::{bistatic_distance, bistatic_intersections};
use crate::model::wideband::distance_candidates;
use crate::scene::{Role, Scene};

use super::bistatic::{tuple_gaussian, usable_subsets, HelperGeometry, Receiver};
use super::{Estimate, Measurement, Params, Tracker, TrackerStats, TurboTrackParams, WidebandFrame};

/// The registry's constructor of `rfind`.
pub fn build(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    Ok(Box::new(RFind::new(scene.clone(), params.turbotrack.clone())?))
}

/// Iterations of the least-squares fit (it stops earlier once converged).
const MAX_ITERATIONS: usize = 50;

/// Frequencies are pooled per 1 kHz bin.
fn bin(frequency_hz: f64) -> i64 {
    (frequency_hz / 1e3).round() as i64
}

/// Why a full window gave no position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NoFix {
    /// Fewer receivers with a usable pooled channel than a fix needs.
    NoChannel,
    /// The least-squares fit has no finite solution (singular geometry).
    NoFit,
}

/// The RFind-style static localiser.
pub struct RFind {
    scene: Scene,
    geometry: HelperGeometry,
    params: TurboTrackParams,
    /// Frames inside the window (time s, the frame).
    window: VecDeque<WidebandFrame>,
    /// Running sums per (receiver antenna, frequency bin): (Σh, count, f Hz).
    sums: BTreeMap<(usize, i64), (Complex<f64>, u32, f64)>,
    last_time_s: f64,
    stats: TrackerStats,
}

impl RFind {
    pub fn new(scene: Scene, params: TurboTrackParams) -> Result<Self> {
        let geometry = HelperGeometry::new(&scene).ok_or_else(|| {
            Error::Scene("a wideband tracker needs one antenna with role \"tx\" and at least 3 (2 for dimensions = 2) with role \"rx\"".into())
        })?;
        if !(params.rfind_window_s > 0.0) {
            return Err(Error::Parameter { name: "rfind_window_s".into(), reason: "must be positive".into() });
        }
        Ok(Self {
            scene,
            geometry,
            params,
            window: VecDeque::new(),
            sums: BTreeMap::new(),
            last_time_s: f64::NEG_INFINITY,
            stats: TrackerStats::default(),
        })
    }

    fn add(&mut self, frame: &WidebandFrame, sign: f64) {
        let f = frame.frequencies_hz.len();
        for (r, &antenna) in frame.rx.iter().enumerate() {
            for (k, &freq) in frame.frequencies_hz.iter().enumerate() {
                let h = frame.h[r * f + k];
                if !(h.re.is_finite() && h.im.is_finite()) {
                    continue;
                }
                let entry = self.sums.entry((antenna, bin(freq))).or_insert((Complex::new(0.0, 0.0), 0, freq));
                entry.0 += h * sign;
                if sign > 0.0 {
                    entry.1 += 1;
                } else {
                    entry.1 = entry.1.saturating_sub(1);
                }
            }
        }
        self.sums.retain(|_, v| v.1 > 0);
    }

    fn valid(&self, frame: &WidebandFrame) -> bool {
        let f = frame.frequencies_hz.len();
        frame.time_s.is_finite()
            && frame.tx == self.geometry.tx
            && f > 0
            && frame.h.len() == frame.rx.len() * f
            && frame.rx.iter().all(|&a| a < self.scene.antennas.len() && self.scene.antennas[a].role == Role::Rx)
    }

    /// Localises from the pooled channels: the strongest candidate of each
    /// receiver, intersected for a starting point, then the weighted
    /// least-squares fit of every receiver's path length.
    fn localise(&self) -> std::result::Result<(Vector3<f64>, Matrix3<f64>), NoFix> {
        let mut receivers = Vec::new();
        for &antenna in &self.scene.receivers() {
            let (freqs, h): (Vec<f64>, Vec<Complex<f64>>) = self
                .sums
                .range((antenna, i64::MIN)..=(antenna, i64::MAX))
                .map(|(_, (sum, count, f))| (*f, sum / *count as f64))
                .unzip();
            let (lo, hi) = self.geometry.bounds[antenna];
            if let Some(mut candidates) = distance_candidates(&freqs, &h, lo, hi, &self.params.candidates) {
                if let Some(s) = self.params.distance_sigma_m {
                    candidates.sigma_m = s;
                }
                receivers.push(Receiver { antenna, position: self.scene.antennas[antenna].position, candidates });
            }
        }
        if receivers.len() < self.geometry.needed() {
            return Err(NoFix::NoChannel);
        }
        let indices: Vec<i64> = receivers.iter().map(|r| r.candidates.best as i64).collect();
        let near = match &self.scene.region {
            Some(r) => (r.min + r.max) / 2.0,
            None => self.geometry.tx_position + Vector3::new(0.0, 0.0, 1.0),
        };
        let subset_list = usable_subsets(&self.geometry, &receivers);
        let tolerance = self.params.intersection_tolerance_m;
        // Starting point: the centroid of the subsets' intersections. When
        // the strongest candidates' loci do not all meet — the pooled
        // channel of a tag that moved during the window is a smear of
        // paths, and its strongest teeth need not be consistent — the
        // subsets that do meet, else the region's centre; the fit below
        // then finds the position that best explains those path lengths.
        let start = match tuple_gaussian(&self.geometry, &receivers, &indices, &subset_list, &near, tolerance) {
            Some(g) => g.mean,
            None => {
                let points: Vec<Vector3<f64>> = subset_list
                    .iter()
                    .filter_map(|subset| {
                        let positions: Vec<Vector3<f64>> = subset.iter().map(|&j| receivers[j].position).collect();
                        let distances: Vec<f64> = subset.iter().map(|&j| receivers[j].candidates.distance(indices[j])).collect();
                        bistatic_intersections(&self.geometry.tx_position, &positions, &distances, self.geometry.plane(), tolerance)
                            .into_iter()
                            .min_by(|a, b| (a - near).norm_squared().total_cmp(&(b - near).norm_squared()))
                    })
                    .collect();
                if points.is_empty() {
                    near
                } else {
                    points.iter().sum::<Vector3<f64>>() / points.len() as f64
                }
            }
        };
        let mut x = start;
        if self.scene.dimensions == 2 {
            x.z = self.scene.plane_z;
        }
        // Weighted least squares on every receiver's path length (weights
        // 1/σ_w²): Gauss–Newton, with Levenberg–Marquardt damping only when
        // a full step does not lower the cost (far starts, inconsistent
        // path lengths).
        let fit = |x: &Vector3<f64>| -> (f64, Matrix3<f64>, Vector3<f64>) {
            let mut cost = 0.0;
            let mut info = Matrix3::zeros();
            let mut gradient = Vector3::zeros();
            for (rx, &n) in receivers.iter().zip(&indices) {
                let (d, mut j) = bistatic_distance(x, &self.geometry.tx_position, &rx.position);
                if self.scene.dimensions == 2 {
                    j.z = 0.0;
                }
                let w = 1.0 / rx.candidates.sigma_m.powi(2);
                let residual = rx.candidates.distance(n) - d;
                cost += residual * residual * w;
                info += j * j.transpose() * w;
                gradient += j * (residual * w);
            }
            if self.scene.dimensions == 2 {
                info[(2, 2)] = 1.0;
            }
            (cost, info, gradient)
        };
        let (mut cost, mut info, mut gradient) = fit(&x);
        let mut damping = 0.0;
        for _ in 0..MAX_ITERATIONS {
            let damped = info + Matrix3::identity() * (damping * info.trace() / 3.0);
            let Some(inverse) = damped.try_inverse() else { break };
            let dx = inverse * gradient;
            let (c, i, g) = fit(&(x + dx));
            if c.is_finite() && c <= cost {
                x += dx;
                (cost, info, gradient) = (c, i, g);
                damping /= 10.0;
            } else if damping < 1e8 {
                damping = (damping * 10.0).max(1e-3);
            } else {
                break;
            }
            if dx.norm() < 1e-7 {
                break;
            }
        }
        let Some(mut covariance) = info.try_inverse() else { return Err(NoFix::NoFit) };
        if !(x.iter().all(|v| v.is_finite()) && covariance.iter().all(|v| v.is_finite())) {
            return Err(NoFix::NoFit);
        }
        // Path lengths that no position explains (a smeared window): widen
        // the reported covariance by the fit's reduced χ² (when above 1).
        let unknowns = if self.scene.dimensions == 2 { 2 } else { 3 };
        if receivers.len() > unknowns {
            covariance *= (cost / (receivers.len() - unknowns) as f64).max(1.0);
        }
        Ok((x, covariance))
    }

    fn step_frame(&mut self, frame: &WidebandFrame) -> Option<Estimate> {
        self.stats.measurements += 1;
        if !self.valid(frame) {
            self.stats.invalid += 1;
            return None;
        }
        if frame.time_s < self.last_time_s {
            self.stats.out_of_order += 1;
            return None;
        }
        self.last_time_s = frame.time_s;
        self.add(frame, 1.0);
        self.window.push_back(frame.clone());
        while self.window.front().is_some_and(|f| frame.time_s - f.time_s > self.params.rfind_window_s) {
            let old = self.window.pop_front().expect("non-empty");
            self.add(&old, -1.0);
        }
        // RFind needs the whole acquisition before it answers.
        let span = frame.time_s - self.window.front().map_or(frame.time_s, |f| f.time_s);
        if span < 0.9 * self.params.rfind_window_s {
            self.stats.initialising += 1;
            return None;
        }
        let (mut x, p) = match self.localise() {
            Ok(fix) => fix,
            Err(reason) => {
                // Declined, and counted: too few receivers with a usable
                // pooled channel (`invalid`), or no finite fit (`outliers`).
                match reason {
                    NoFix::NoChannel => self.stats.invalid += 1,
                    NoFix::NoFit => self.stats.outliers += 1,
                }
                return None;
            }
        };
        if self.scene.dimensions == 2 {
            x.z = self.scene.plane_z;
        }
        Some(Estimate::from_position(frame.time_s, &x, &p, [f64::NAN; 3], 1, 1.0))
    }
}

impl Tracker for RFind {
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate> {
        match measurement {
            Measurement::Wideband(frame) => self.step_frame(frame),
            Measurement::Phase(_) => self.stats.decline_invalid(),
        }
    }

    fn stats(&self) -> TrackerStats {
        self.stats
    }

    fn reset(&mut self) {
        self.window.clear();
        self.sums.clear();
        self.last_time_s = f64::NEG_INFINITY;
    }
}
