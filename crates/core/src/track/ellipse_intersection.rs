//! Ellipse intersection: the TurboTrack thesis's first comparison scheme
//! (§7.2(a), after its refs [13, 14]). Every frame on its own: each
//! receiver's highest-weight distance candidate defines an ellipse
//! (ellipsoid) with foci tx and rx; the subsets' intersection points are
//! fused by their centroid (eq. 5.5). No memory across frames, so a wrong
//! candidate costs a wavelength-scale error in that frame only.
//!
//! Departure: the thesis lets this baseline pick the intersection closest
//! to the ground truth, which a causal tracker cannot; here the region and
//! the nearness to the other subsets' points pick it (the same rule as
//! the full method's pruning).

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::scene::Scene;

use super::bistatic::{frame_receivers, tuple_gaussian, usable_subsets, HelperGeometry};
use crate::model::wideband::CandidateWeighting;

use super::{Estimate, Measurement, Params, Tracker, TrackerStats, TurboTrackParams, WidebandFrame};

/// The registry's constructor of `ellipse-intersection`.
pub fn build(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    let mut w = params.turbotrack.clone();
    // §7.2(a): "weights obtained from the amplitude of the interpolated FFT".
    w.candidates.weighting = CandidateWeighting::Amplitude;
    Ok(Box::new(EllipseIntersection::new(scene.clone(), w)?))
}

/// The per-frame ellipse-intersection localiser.
pub struct EllipseIntersection {
    scene: Scene,
    geometry: HelperGeometry,
    params: TurboTrackParams,
    last_time_s: f64,
    stats: TrackerStats,
}

impl EllipseIntersection {
    /// Uses the candidate extraction, σ_w and tolerance settings of `params`.
    pub fn new(scene: Scene, params: TurboTrackParams) -> Result<Self> {
        let geometry = HelperGeometry::new(&scene).ok_or_else(|| {
            Error::Scene("a wideband tracker needs one antenna with role \"tx\" and at least 3 (2 for dimensions = 2) with role \"rx\"".into())
        })?;
        Ok(Self { scene, geometry, params, last_time_s: f64::NEG_INFINITY, stats: TrackerStats::default() })
    }

    fn step_frame(&mut self, frame: &WidebandFrame) -> Option<Estimate> {
        self.stats.measurements += 1;
        if frame.time_s < self.last_time_s {
            self.stats.out_of_order += 1;
            return None;
        }
        let Ok(mut receivers) = frame_receivers(&self.scene, &self.geometry, frame, &self.params.candidates) else {
            self.stats.invalid += 1;
            return None;
        };
        if let Some(s) = self.params.distance_sigma_m {
            receivers.iter_mut().for_each(|r| r.candidates.sigma_m = s);
        }
        self.last_time_s = frame.time_s;
        let indices: Vec<i64> = receivers.iter().map(|r| r.candidates.best as i64).collect();
        let subset_list = usable_subsets(&self.geometry, &receivers);
        // The mirror side: seed from the region's centre (or above the array).
        let seed = match &self.scene.region {
            Some(r) => (r.min + r.max) / 2.0,
            None => self.geometry.tx_position + Vector3::new(0.0, 0.0, 1.0),
        };
        let Some(g) = tuple_gaussian(&self.geometry, &receivers, &indices, &subset_list, &seed, self.params.intersection_tolerance_m)
        else {
            // The strongest candidates' loci do not meet: no fix this frame.
            self.stats.outliers += 1;
            return None;
        };
        Some(Estimate::from_position(frame.time_s, &g.mean, &g.covariance, [f64::NAN; 3], 1, 1.0))
    }
}

impl Tracker for EllipseIntersection {
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
        self.last_time_s = f64::NEG_INFINITY;
    }
}
