//! Trilateration EKF: the textbook baseline for a COTS reader's phase
//! reads. One extended Kalman filter on x = [p, v] (constant velocity, or
//! the random walk of `motion = "random-walk"`) whose measurements are
//! ranges unwrapped from each antenna's phase; no branching, no
//! re-seeding, no IMM, no bias states.
//!
//! 1. First fix: the reads of the first `init_window_s` (longer, up to
//!    `init_max_window_s`, until every antenna heard has read twice) are
//!    multilaterated by GLAC's initial search ([`initial_hypotheses`]:
//!    synchronised candidate ranges, sphere intersections, least squares
//!    and the region). On one channel a handful of positions explain a
//!    single instant equally well (whole-step twins), so each starts a
//!    filter of its own and the reads that follow decide: a filter is
//!    dropped when its normalised likelihood falls below `quick_stop`,
//!    it leaves the region by `region_margin_m`, it comes within
//!    `merge_distance_m` of a better one, or it gates
//!    `max_consecutive_outliers` reads in a row. The fix is the one left;
//!    from then on a single filter runs and estimates are reported.
//! 2. Continuous phase tracking per antenna and channel: a read's phase
//!    fixes the range up to whole ambiguity steps s = P λ / 4π (λ/2 mod
//!    2π). The step is chosen so that the range is nearest to where the
//!    phase track predicts it, the filter's predicted range plus the
//!    residual this antenna and channel were left with at their last read:
//!    the phase change since then, with the motion the filter has seen in
//!    between. A pair first read after the fix starts from the prediction.
//! 3. Update: the unwrapped range d with h(x) = |p − a| (GLAC eq. 4) and
//!    R = (σ_φ λ / 4π)², σ_φ the parameter `phase_noise_rad` or the
//!    scene's prior. A read whose innovation exceeds `gate_sigmas` is an
//!    outlier (skipped, counted); `max_consecutive_outliers` in a row, or
//!    no read for `reinit_gap_s`, start over from step 1.
//!
//! Its parameters are GLAC's table (the names above, `q`/`motion`, the
//! initial search's). Once fixed, an unwrapping slip is not undone until
//! the filter loses lock: that is the baseline's weakness, on purpose.

use std::collections::HashMap;

// Declared in the registry (`track::registry::trilateration_ekf`): paths from the crate root.
use crate::track::candidates::nearest_candidate;
use crate::track::initial::{initial_covariance, initial_hypotheses};
use crate::track::{Estimate, GlacParams, Measurement, Params, PhaseRead, Tracker, TrackerStats};
use crate::error::{Error, Result};
use crate::filter::{apply_scalar, innovation, log_gaussian, predict};
use crate::model::{range, StateMatrix, StateVector};
use crate::scene::Scene;

/// The registry's constructor of `trilateration-ekf` (GLAC's parameter table).
pub fn build(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    Ok(Box::new(TrilaterationEkf::new(scene.clone(), params.glac.clone())?))
}

/// One filter with its phase tracks.
#[derive(Debug, Clone)]
struct Filter {
    x: StateVector,
    p: StateMatrix,
    /// Time of `x`, seconds.
    time_s: f64,
    /// Per (antenna index, channel in kHz): the residual (m) of the
    /// unwrapped range against the filter's updated range at its last read.
    residual_m: HashMap<(usize, i64), f64>,
    consecutive_outliers: u32,
    /// Σ log N(ν; 0, S) since the first fix started (its weight while several run).
    log_likelihood: f64,
}

/// One read as the filters use it.
struct Read {
    time_s: f64,
    position: nalgebra::Vector3<f64>,
    key: (usize, i64),
    residue: f64,
    spacing: f64,
    r: f64,
}

impl Filter {
    /// Predicts to the read and updates with its unwrapped range; false
    /// when it gated the read (an outlier, skipped).
    fn step(&mut self, m: &Read, params: &GlacParams, axes: usize) -> bool {
        let dt = m.time_s - self.time_s;
        if dt > 0.0 {
            predict(&mut self.x, &mut self.p, &params.motion.transition(dt, axes));
            self.time_s = m.time_s;
        }
        let (h, jacobian) = range(&self.x, &m.position, axes, true);
        let jacobian = jacobian.expect("asked for");
        let reference = h + self.residual_m.get(&m.key).copied().unwrap_or(0.0);
        let z = nearest_candidate(m.residue, m.spacing, reference);
        let (u, b) = innovation(&self.p, z, h, &jacobian, m.r);
        let limit = params.gate_sigmas * u.variance.sqrt();
        if u.innovation.abs() > limit {
            // Charged as if at the gate: an outlier weighs against the filter.
            self.log_likelihood += log_gaussian(limit, u.variance);
            self.consecutive_outliers += 1;
            return false;
        }
        self.log_likelihood += log_gaussian(u.innovation, u.variance);
        self.consecutive_outliers = 0;
        apply_scalar(&mut self.x, &mut self.p, &u, &b);
        let updated = range(&self.x, &m.position, axes, false).0;
        self.residual_m.insert(m.key, z - updated);
        true
    }
}

pub struct TrilaterationEkf {
    scene: Scene,
    params: GlacParams,
    /// Moving axes: 2 (tag in the plane z = plane_z) or 3.
    axes: usize,
    /// Reads collected towards the first fix.
    buffer: Vec<PhaseRead>,
    /// The filters still in the running (one once fixed).
    filters: Vec<Filter>,
    fixed: bool,
    last_time_s: f64,
    stats: TrackerStats,
}

impl TrilaterationEkf {
    pub fn new(scene: Scene, params: GlacParams) -> Result<Self> {
        let positive = |name: &str, v: f64| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(Error::Parameter { name: name.into(), reason: format!("must be positive, got {v}") })
            }
        };
        positive("gate_sigmas", params.gate_sigmas)?;
        positive("reinit_gap_s", params.reinit_gap_s)?;
        positive("init_position_sigma_m", params.init_position_sigma_m)?;
        if let Some(noise) = params.phase_noise_rad {
            positive("phase_noise_rad", noise)?;
        }
        let axes = scene.dimensions;
        Ok(Self {
            scene,
            params,
            axes,
            buffer: Vec::new(),
            filters: Vec::new(),
            fixed: false,
            last_time_s: f64::NEG_INFINITY,
            stats: TrackerStats::default(),
        })
    }

    fn phase_noise(&self) -> f64 {
        self.params.phase_noise_rad.unwrap_or(self.scene.phase_noise_rad)
    }

    /// R (m²) of one read's range on carrier `frequency_hz`.
    fn range_variance(&self, frequency_hz: f64) -> f64 {
        let sigma = self.phase_noise() * Scene::range_per_radian(frequency_hz);
        sigma * sigma
    }

    fn restart(&mut self) {
        self.filters.clear();
        self.fixed = false;
        self.buffer.clear();
        self.stats.reinitialisations += 1;
    }

    fn read(&self, m: &PhaseRead) -> Read {
        Read {
            time_s: m.time_s,
            position: self.scene.antennas[m.antenna].position,
            key: (m.antenna, (m.frequency_hz / 1e3).round() as i64),
            residue: self.scene.distance_residue(m.antenna, m.frequency_hz, m.phase_rad),
            spacing: self.scene.candidate_spacing(m.frequency_hz),
            r: self.range_variance(m.frequency_hz),
        }
    }

    /// The initial search over the buffer (step 1); on success its
    /// positions start the filters and the reads after its time are
    /// replayed through them.
    fn try_start(&mut self) {
        let (first, last) = match (self.buffer.first(), self.buffer.last()) {
            (Some(f), Some(l)) => (f.time_s, l.time_s),
            _ => return,
        };
        let span = last - first;
        if span < self.params.init_window_s {
            return;
        }
        let mut counts = vec![0usize; self.scene.antennas.len()];
        for m in &self.buffer {
            counts[m.antenna] += 1;
        }
        if !counts.iter().all(|&c| c == 0 || c >= 2) && span < self.params.init_max_window_s {
            return;
        }
        let range_sigma = self.range_variance(self.buffer[0].frequency_hz).sqrt();
        let with_velocity = self.params.motion.has_velocity();
        let Some((t_x, initial)) = initial_hypotheses(&self.scene, &self.buffer, &self.params.initial, range_sigma, with_velocity)
        else {
            // No position explains the reads yet: slide the window.
            let keep_from = last - self.params.init_max_window_s;
            self.buffer.retain(|m| m.time_s >= keep_from);
            return;
        };
        let v_sigma = if with_velocity { self.params.init_velocity_sigma_m_s } else { 0.0 };
        let p = initial_covariance(self.axes, self.params.init_position_sigma_m, v_sigma);
        self.filters = initial
            .iter()
            .map(|h| {
                let mut x = h.state;
                if self.axes == 2 {
                    x[2] = self.scene.plane_z;
                    x[5] = 0.0;
                }
                if !with_velocity {
                    x.fixed_rows_mut::<3>(3).fill(0.0);
                }
                Filter { x, p, time_s: t_x, residual_m: HashMap::new(), consecutive_outliers: 0, log_likelihood: h.log_likelihood }
            })
            .collect();
        let replay: Vec<PhaseRead> = std::mem::take(&mut self.buffer).into_iter().filter(|m| m.time_s > t_x).collect();
        for m in &replay {
            self.track(m);
        }
    }

    /// Steps 2 and 3 for one read, on every filter still running.
    fn track(&mut self, m: &PhaseRead) {
        let read = self.read(m);
        let (params, axes) = (&self.params, self.axes);
        let mut updates = 0;
        for f in self.filters.iter_mut() {
            if f.step(&read, params, axes) {
                updates += 1;
            } else if self.fixed {
                self.stats.outliers += 1;
            }
        }
        self.stats.filter_updates += updates;
        if self.fixed {
            if self.filters[0].consecutive_outliers > self.params.max_consecutive_outliers {
                self.restart();
            }
        } else {
            self.resolve();
        }
    }

    /// Drops the filters the reads have ruled out (step 1); fixed when one is left.
    fn resolve(&mut self) {
        let (lost, margin) = (self.params.max_consecutive_outliers, self.params.region_margin_m);
        let (scene, axes) = (&self.scene, self.axes);
        self.filters.retain(|f| {
            let p = nalgebra::Vector3::new(f.x[0], f.x[1], f.x[2]);
            f.consecutive_outliers <= lost && scene.region.as_ref().is_none_or(|r| r.contains(&p, margin, axes))
        });
        if self.filters.is_empty() {
            self.restart();
            return;
        }
        self.filters.sort_by(|a, b| b.log_likelihood.total_cmp(&a.log_likelihood));
        let best = self.filters[0].log_likelihood;
        let floor = best + self.params.quick_stop.ln();
        self.filters.retain(|f| f.log_likelihood >= floor);
        let merge = self.params.merge_distance_m;
        let mut kept: Vec<Filter> = Vec::with_capacity(self.filters.len());
        for f in self.filters.drain(..) {
            let near = kept.iter().any(|k| (k.x.fixed_rows::<3>(0) - f.x.fixed_rows::<3>(0)).norm() < merge);
            if !near {
                kept.push(f);
            }
        }
        self.filters = kept;
        self.stats.max_hypotheses = self.stats.max_hypotheses.max(self.filters.len() as u64);
        self.fixed = self.filters.len() == 1;
    }

    fn estimate(&self, time_s: f64) -> Option<Estimate> {
        if !self.fixed {
            return None;
        }
        let f = &self.filters[0];
        let with_velocity = self.params.motion.has_velocity();
        let velocity = if with_velocity { [f.x[3], f.x[4], f.x[5]] } else { [f64::NAN; 3] };
        let mut covariance = Estimate::covariance_from(&f.p);
        if !with_velocity {
            for k in 3..6 {
                covariance[k * 6 + k] = f64::NAN;
            }
        }
        Some(Estimate { time_s, position: [f.x[0], f.x[1], f.x[2]], velocity, covariance, hypotheses: 1, weight: 1.0 })
    }

    fn step_read(&mut self, m: &PhaseRead) -> Option<Estimate> {
        self.stats.measurements += 1;
        let valid = m.antenna < self.scene.antennas.len()
            && m.time_s.is_finite()
            && m.phase_rad.is_finite()
            && m.frequency_hz.is_finite()
            && m.frequency_hz > 0.0;
        if !valid {
            self.stats.invalid += 1;
            return None;
        }
        if m.time_s < self.last_time_s {
            self.stats.out_of_order += 1;
            return None;
        }
        let gap = m.time_s - self.last_time_s;
        self.last_time_s = m.time_s;
        if !self.filters.is_empty() && gap > self.params.reinit_gap_s {
            self.restart();
        }
        if !self.fixed {
            self.stats.initialising += 1;
        }
        if self.filters.is_empty() {
            self.buffer.push(*m);
            self.try_start();
        } else {
            self.track(m);
        }
        self.estimate(m.time_s)
    }
}

impl Tracker for TrilaterationEkf {
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate> {
        match measurement {
            Measurement::Phase(m) => self.step_read(m),
            _ => self.stats.decline_invalid(),
        }
    }

    fn stats(&self) -> TrackerStats {
        self.stats
    }

    fn reset(&mut self) {
        self.filters.clear();
        self.fixed = false;
        self.buffer.clear();
        self.last_time_s = f64::NEG_INFINITY;
    }

    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        let best = self.filters.first().map_or(0.0, |f| f.log_likelihood);
        self.filters.iter().map(|f| ([f.x[0], f.x[1], f.x[2]], f.log_likelihood - best)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use crate::scene::{Antenna, Region};
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;

    const F: f64 = 915.25e6;

    /// Where the tag is at `t` (s) on a test trajectory.
    type Path = fn(f64) -> Vector3<f64>;

    /// The glac-3d-walls layout: two antennas on each of two walls, no four in a plane.
    fn scene() -> Scene {
        let positions = [[0.0, 0.3, 0.2], [0.0, 0.9, 1.1], [0.4, 0.0, 1.2], [1.0, 0.0, 0.2]];
        let antennas = positions
            .iter()
            .enumerate()
            .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::from(*p), phase_offset_rad: 0.3 * i as f64, role: Default::default() })
            .collect();
        let region = Region { min: Vector3::new(0.05, 0.05, 0.1), max: Vector3::new(1.2, 1.2, 1.4) };
        Scene::new(3, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, Some(region), vec![]).unwrap()
    }

    /// Reads at 120 /s round-robin over the antennas along `path`, with
    /// 0.1 rad white phase noise, hopping over `channels` (Hz) every 8 reads.
    fn reads(scene: &Scene, path: Path, duration_s: f64, seed: u64, channels: &[f64]) -> Vec<PhaseRead> {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = (duration_s * 120.0) as usize;
        (0..n)
            .map(|k| {
                let t = k as f64 / 120.0;
                let a = k % scene.antennas.len();
                let d = (path(t) - scene.antennas[a].position).norm();
                let noise: f64 = rng.sample(StandardNormal);
                let f = channels[(k / 8) % channels.len()];
                let phase = crate::angle::wrap(scene.ideal_phase(a, f, d) + 0.1 * noise, std::f64::consts::TAU);
                PhaseRead { time_s: t, antenna: a, frequency_hz: f, phase_rad: phase }
            })
            .collect()
    }

    /// Errors (m) and per-axis normalised squared errors of the estimates after `settle_s`.
    fn run(path: Path, duration_s: f64, settle_s: f64, seed: u64, channels: &[f64]) -> (Vec<f64>, [f64; 3], TrackerStats) {
        let scene = scene();
        let mut tracker = TrilaterationEkf::new(scene.clone(), GlacParams::default()).unwrap();
        let (mut errors, mut nees, mut rows) = (Vec::new(), [0.0; 3], 0.0);
        for m in reads(&scene, path, duration_s, seed, channels) {
            let Some(e) = tracker.step(&Measurement::Phase(m)) else { continue };
            if e.time_s < settle_s {
                continue;
            }
            let error = Vector3::from(e.position) - path(e.time_s);
            errors.push(error.norm());
            let sigma = e.position_sigma();
            for i in 0..3 {
                nees[i] += (error[i] / sigma[i]).powi(2);
            }
            rows += 1.0;
        }
        (errors, nees.map(|n| n / rows), tracker.stats())
    }

    fn median(mut v: Vec<f64>) -> f64 {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// A static tag on one channel has whole-step twins that no read
    /// tells apart; hopping over channels 6 MHz apart does.
    #[test]
    fn a_static_tag_hopping_channels_converges_within_millimetres_with_honest_sigmas() {
        let channels = [903.25e6, 927.25e6, 909.25e6, 921.25e6, 915.25e6];
        let (errors, nees, stats) = run(|_| Vector3::new(0.5, 0.4, 0.6), 8.0, 4.0, 1, &channels);
        // The constant-velocity model keeps a static tag's sigma at a few
        // millimetres (q = 0.02 m²/s³ at 120 reads/s): the error follows it.
        assert!(median(errors.clone()) < 5e-3, "median error {} m", median(errors.clone()));
        assert!(errors.iter().all(|&e| e < 0.015), "worst {}", errors.iter().copied().fold(0.0, f64::max));
        assert!(nees.iter().all(|&n| n > 0.3 && n < 2.0), "NEES per axis {nees:?}");
        assert_eq!((stats.reinitialisations, stats.invalid, stats.out_of_order), (0, 0, 0));
    }

    /// A tag moving 1.5 m (many ambiguity steps of 16 cm) stays locked:
    /// the phase tracks unwrap every step.
    #[test]
    fn a_moving_tag_is_unwrapped_over_many_wavelengths() {
        let path: Path = |t| Vector3::new(0.3 + 0.1 * t, 0.3 + 0.08 * t, 0.5 + 0.05 * (1.3 * t).sin());
        let (errors, nees, stats) = run(path, 8.0, 3.0, 2, &[F]);
        assert!(median(errors.clone()) < 3e-3, "median error {} m", median(errors));
        assert!(nees.iter().all(|&n| n < 3.0), "NEES per axis {nees:?}");
        assert_eq!(stats.reinitialisations, 0);
        assert!(stats.filter_updates > 800, "{stats:?}");
    }

    #[test]
    fn silent_until_fixed_and_declines_what_it_cannot_use() {
        let scene = scene();
        let mut tracker = TrilaterationEkf::new(scene.clone(), GlacParams::default()).unwrap();
        let path: Path = |t| Vector3::new(0.3 + 0.1 * t, 0.3 + 0.08 * t, 0.5);
        let reads = reads(&scene, path, 6.0, 3, &[F]);
        let first: Vec<bool> = reads[..10].iter().map(|m| tracker.step(&Measurement::Phase(*m)).is_some()).collect();
        assert!(first.iter().all(|&e| !e), "an estimate before the first fix");
        for m in &reads[10..] {
            tracker.step(&Measurement::Phase(*m));
        }
        let late = PhaseRead { time_s: 0.0, ..reads[0] };
        assert!(tracker.step(&Measurement::Phase(late)).is_none());
        let unknown = PhaseRead { antenna: 9, time_s: 2.0, ..reads[0] };
        assert!(tracker.step(&Measurement::Phase(unknown)).is_none());
        let s = tracker.stats();
        assert_eq!((s.out_of_order, s.invalid, s.measurements), (1, 1, reads.len() as u64 + 2));
        assert!(s.initialising >= 36 && s.initialising < 500, "{s:?}");
        assert!(s.max_hypotheses > 1, "{s:?}");
        assert_eq!(tracker.hypotheses().len(), 1);
    }

    #[test]
    fn rejects_invalid_parameters() {
        let bad = GlacParams { gate_sigmas: 0.0, ..GlacParams::default() };
        assert!(matches!(TrilaterationEkf::new(scene(), bad), Err(Error::Parameter { .. })));
    }
}
