//! The named variants of GLAC and TurboTrack: each is the base tracker
//! with the settings that define it set on top of the given parameters
//! (GLAC sec. 5.2.2–5.2.3; TurboTrack thesis §7.2). The registry
//! ([`super::registry::METHODS`]) names these constructors; the base
//! methods' own are `build` in their files.

use super::{Glac, GlacParams, Inference, InitialSampling, Params, Proposal, Tracker, TurboTrack, WidebandLikelihood};
use crate::error::Result;
use crate::model::wideband::CandidateWeighting;
use crate::scene::Scene;

/// 1-sigma of the Gaussian-PF baseline's single-Gaussian likelihood, m:
/// "a large standard deviation" (§7.2(a)) — a quarter of the 100 MHz
/// range resolution (c / B = 3 m), wide enough to cover the envelope's
/// wavelength-scale ambiguity.
pub const GAUSSIAN_PF_SIGMA_M: f64 = 0.3;

fn glac_with(scene: &Scene, params: &Params, variant: impl FnOnce(&mut GlacParams)) -> Result<Box<dyn Tracker>> {
    let mut p = params.glac.clone();
    variant(&mut p);
    Ok(Box::new(Glac::new(scene.clone(), p)?))
}

/// `glac-no-velocity`: a position random walk instead of constant
/// velocity (sec. 5.2.2, scheme 2).
pub fn glac_no_velocity(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    glac_with(scene, params, GlacParams::motion_model_no_velocity)
}

/// `glac-sync`: each group of reads covering every antenna is one
/// trilaterated measurement (sec. 5.2.2, scheme 3).
pub fn glac_sync(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    glac_with(scene, params, |p| p.inference = Inference::Synchronous)
}

/// `glac-sync-no-velocity`: both of the above (sec. 5.2.2).
pub fn glac_sync_no_velocity(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    glac_with(scene, params, |p| {
        p.inference = Inference::Synchronous;
        p.motion_model_no_velocity();
    })
}

/// `glac-naive`: no nearest-neighbour pruning or quick stop (sec. 5.2.3).
pub fn glac_naive(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    glac_with(scene, params, |p| p.inference = Inference::Naive)
}

/// `gaussian-pf` (§7.2(a)).
pub fn gaussian_pf(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    let mut w = params.turbotrack.clone();
    // §7.2(a): one broad Gaussian around the strongest candidate,
    // a bootstrap (prior) proposal.
    w.likelihood = WidebandLikelihood::SingleGaussian { sigma_m: GAUSSIAN_PF_SIGMA_M };
    w.proposal = Proposal::Prior;
    // §7.2(a): the strongest candidate by FFT amplitude.
    w.candidates.weighting = CandidateWeighting::Amplitude;
    // The thesis's baselines have one random walk, no static mode.
    w.static_entry_probability = 0.0;
    Ok(Box::new(TurboTrack::new(scene.clone(), w)?))
}

/// `uniform-pf` (§7.2(b)).
pub fn uniform_pf(scene: &Scene, params: &Params) -> Result<Box<dyn Tracker>> {
    let mut w = params.turbotrack.clone();
    // §7.2(b): particles spread uniformly over the region, the
    // prior as proposal, the same mixture likelihood.
    w.initial_sampling = InitialSampling::Uniform;
    w.proposal = Proposal::Prior;
    w.static_entry_probability = 0.0;
    Ok(Box::new(TurboTrack::new(scene.clone(), w)?))
}
