//! Far lobes: alternatives to the filter's lobe that the neighbouring-tooth
//! lattice of `lobes.rs` cannot express.
//!
//! `lobes.rs` compares the filter's lobe with the lobes one tooth away on
//! each receiver, located at linear order around the filter's fit. That
//! covers lobes a few tens of centimetres away. When the antennas are
//! nearly coplanar and the tag sits close to their plane, the path lengths
//! change slowly with the distance from the plane, and a shift of one tooth
//! on two receivers can move the lobe by more than a metre (dev seed 1124 of
//! `docs/notes/turbotrack-experiments.md`: shift (+1, 0, −1, 0), 1.35 m):
//! far outside the linear regime, so the lattice never evaluates it, and a
//! filter started there stays there with millimetre sigmas.
//!
//! The global tuple search of the initialisation (§5.3.1) does find such
//! lobes. This file keeps the best few of its fits as **alternatives**,
//! each a position, and every frame:
//!
//! 1. moves each alternative with the filter's lobe (`x_k ← x_k + Δx₀`,
//!    the tag's motion) and refits it by Gauss–Newton on its nearest teeth;
//! 2. adds its profile log-likelihood ratio against the filter's lobe,
//!    `λ_k = ℓ(x_k*) − ℓ(x₀*)` (eq. 5.2 at the two fits), to its evidence
//!    with the levels of `lobes.rs`: `L_k ← max(L_k + clamp(λ_k, −c, c), −B)`;
//! 3. switches the filter to the alternative whose `L_k` passes `h`.
//!
//! The alternatives of the first frame start at `L_k = 0` (no history
//! prefers the filter's lobe); lobes found later by the periodic search
//! start at `−B + c`, one frame above the level at which a lobe the filter
//! has been confirmed on protects it, so a correlated run of reflections is
//! no easier a switch than with the lattice (and a fresh fit displaces a
//! held alternative only once that one has sunk to the floor). Unresolved
//! alternatives widen the reported covariance as a mixture about the
//! reported state (`lobes::mixture_spread`, at tempered odds).

use nalgebra::{Matrix3, Vector3};

use super::bistatic::{mixture_log_likelihood, HelperGeometry, Receiver};
use super::lobes::{mixture_spread, path_length_step, LobeDecision, LobeFrame};

/// Alternatives kept at once (the best of the search's fits).
pub const SLOTS: usize = 4;

/// Two fits closer than this, m, are one lobe (neighbouring lobes are
/// 10-60 cm apart; as `JUMP_M` in `lobes.rs`).
const SAME_LOBE_M: f64 = 0.08;

/// `κ`: the reported spread weighs an alternative by `e^{κ L}`, not
/// `e^{L}`. Far lobes differ mostly along the poorly observed direction,
/// where the frames' errors are correlated (the fit drifts along it for tens
/// of frames), so the summed per-frame ratios overstate the odds: on our
/// in-line layout at 8 dB two such lobes traded places several times in
/// 2 s, each time with `L` near −10 for the lobe left, i.e. a spread of
/// nothing while the filter was 1.35 m off half the time. With κ = 1/4 a
/// lobe at −10 keeps 8 % of the weight (tens of centimetres of sigma), one
/// at −40 (20 frames of the full cap past a switch) none that shows.
const SPREAD_TEMPERING: f64 = 0.25;

/// Gauss–Newton steps per alternative and frame (warm-started from the
/// last frame's fit, which is already converged for a resting tag).
const STEPS: usize = 2;

/// One alternative lobe: its last fit, m, and accumulated evidence, nats.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alternative {
    pub position: Vector3<f64>,
    pub evidence: f64,
}

/// The alternatives and the filter's lobe fit of the previous frame.
#[derive(Debug, Clone, Default)]
pub struct FarLobes {
    alternatives: Vec<Alternative>,
    previous_x0: Option<Vector3<f64>>,
}

/// The lobe around `start`: `steps` Gauss–Newton steps, each on the teeth
/// nearest the current point (a lobe is where every receiver's path length
/// sits on a tooth), each step at most `MAX_STEP_M` (near the antennas'
/// plane the normal equations are nearly singular in the height) and
/// projected by `into_region` (a lobe whose best point lies outside the
/// region is represented by the nearest point inside). None when the
/// normal equations are singular.
pub fn fit_nearest_lobe(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    start: &Vector3<f64>,
    steps: usize,
    into_region: impl Fn(&Vector3<f64>) -> Vector3<f64>,
) -> Option<Vector3<f64>> {
    let mut x = into_region(start);
    if geometry.dimensions == 2 {
        x.z = geometry.plane_z;
    }
    for _ in 0..steps {
        let nearest = |_, rx: &Receiver, d| Some(rx.candidates.distance(rx.candidates.nearest_index(d)));
        let mut step = path_length_step(geometry, receivers, &x, nearest).filter(|s| s.iter().all(|v| v.is_finite()))?;
        if step.norm() > MAX_STEP_M {
            step *= MAX_STEP_M / step.norm();
        }
        let next = into_region(&(x + step));
        let moved = (next - x).norm();
        x = next;
        if moved < 1e-6 {
            break;
        }
    }
    Some(x)
}

/// Longest Gauss–Newton step, m (a quarter of the 33 cm tooth spacing
/// would do for a lobe's own basin; beyond it the linearisation is off).
const MAX_STEP_M: f64 = 0.1;

impl FarLobes {
    /// Forgets every alternative (a new start of the filter).
    pub fn reset(&mut self) {
        self.alternatives.clear();
        self.previous_x0 = None;
    }

    /// The alternatives now held.
    pub fn alternatives(&self) -> &[Alternative] {
        &self.alternatives
    }

    /// Offers the fits `candidates` (best first) as alternatives starting at
    /// `evidence` nats. A candidate within `SAME_LOBE_M` of `filter` (the
    /// filter's lobe, when known) or of a held alternative is the same lobe
    /// and is skipped; with every slot taken it replaces the weakest
    /// alternative when that one's evidence is below `evidence`.
    pub fn offer(&mut self, candidates: impl IntoIterator<Item = Vector3<f64>>, evidence: f64, filter: Option<&Vector3<f64>>) {
        for position in candidates {
            let same = |other: &Vector3<f64>| (other - position).norm() < SAME_LOBE_M;
            if filter.is_some_and(same) || self.alternatives.iter().any(|a| same(&a.position)) {
                continue;
            }
            let fresh = Alternative { position, evidence };
            if self.alternatives.len() < SLOTS {
                self.alternatives.push(fresh);
                continue;
            }
            let weakest = self.alternatives.iter().enumerate().min_by(|a, b| a.1.evidence.total_cmp(&b.1.evidence)).map(|(i, _)| i);
            if let Some(i) = weakest.filter(|&i| self.alternatives[i].evidence < evidence) {
                self.alternatives[i] = fresh;
            }
        }
    }

    /// Holds `position` as an alternative at `evidence` nats ahead of every
    /// other (the weakest-ranked one leaves when the slots are full), unless
    /// a held alternative is the same lobe: the state before a restart,
    /// which the restarted filter may have left for a wrong lobe.
    pub fn prefer(&mut self, position: Vector3<f64>, evidence: f64) {
        if self.alternatives.iter().any(|a| (a.position - position).norm() < SAME_LOBE_M) {
            return;
        }
        self.alternatives.insert(0, Alternative { position, evidence });
        self.alternatives.truncate(SLOTS);
    }

    /// One frame (module doc, steps 1–3) against the filter's estimate
    /// `estimate`, m; `into_region` projects a point onto the region.
    /// Returns the displacement to the winning alternative when one passed
    /// the switch level; the lobe left becomes an alternative, every
    /// evidence re-based on the new lobe (`L'_m = L_m − L_won`).
    pub fn update(&mut self, frame: &LobeFrame<'_>, estimate: &Vector3<f64>, into_region: impl Fn(&Vector3<f64>) -> Vector3<f64>) -> LobeDecision {
        let LobeFrame { geometry, receivers, weight_floor, levels } = *frame;
        if self.alternatives.is_empty() || receivers.is_empty() {
            self.previous_x0 = None;
            return LobeDecision::Stay;
        }
        let x0 = fit_nearest_lobe(geometry, receivers, estimate, 1, &into_region).unwrap_or(*estimate);
        // The tag's motion since the last frame, as the filter saw it; a
        // jump of the filter's own lobe (a lattice switch, a restart) is
        // not motion.
        let moved = self.previous_x0.map(|p| x0 - p).filter(|m| m.norm() <= SAME_LOBE_M).unwrap_or_else(Vector3::zeros);
        self.previous_x0 = Some(x0);
        let l0 = mixture_log_likelihood(geometry, receivers, &x0, weight_floor).0;
        let (cap, floor) = (levels.frame_cap_nats, levels.floor_nats);
        let mut kept: Vec<Alternative> = Vec::with_capacity(self.alternatives.len());
        for a in &self.alternatives {
            let Some(x) = fit_nearest_lobe(geometry, receivers, &(a.position + moved), STEPS, &into_region) else { continue };
            if (x - x0).norm() < SAME_LOBE_M || kept.iter().any(|k| (k.position - x).norm() < SAME_LOBE_M) {
                // Merged into the filter's lobe or a stronger alternative.
                continue;
            }
            let llr = mixture_log_likelihood(geometry, receivers, &x, weight_floor).0 - l0;
            let llr = if llr.is_nan() { -cap } else { llr };
            kept.push(Alternative { position: x, evidence: (a.evidence + llr.clamp(-cap, cap)).max(-floor) });
        }
        self.alternatives = kept;
        let winner = self
            .alternatives
            .iter()
            .enumerate()
            .filter(|(_, a)| a.evidence > levels.switch_nats)
            .max_by(|a, b| a.1.evidence.total_cmp(&b.1.evidence))
            .map(|(i, a)| (i, *a));
        let Some((i, won)) = winner else { return LobeDecision::Stay };
        self.alternatives.remove(i);
        for a in &mut self.alternatives {
            a.evidence = (a.evidence - won.evidence).max(-floor);
        }
        self.alternatives.push(Alternative { position: x0, evidence: (-won.evidence).max(-floor) });
        self.previous_x0 = None;
        LobeDecision::Switch(won.position - x0)
    }

    /// The alternatives' spread about `about` (m², `lobes::mixture_spread`)
    /// at tempered log-odds `κ L_k`, `κ = SPREAD_TEMPERING`.
    pub fn spread(&self, about: &Vector3<f64>) -> Matrix3<f64> {
        mixture_spread(self.alternatives.iter().map(|a| (a.position, SPREAD_TEMPERING * a.evidence)), about)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::geometry::bistatic_distance;
    use crate::track::lobes::tests::geometry;
    use crate::track::lobes::LobeLevels;

    /// The in-line layout (all antennas at z = 0): combs with a tooth on
    /// the path lengths of `tag`, 3 mm each, the envelope peaked on the
    /// true tooth with log-weight drop `sharpness` per tooth.
    fn receivers(tag: &Vector3<f64>, sharpness: f64) -> Vec<Receiver> {
        crate::track::lobes::tests::receivers(tag, 0.003, [0; 4], sharpness)
    }

    const LEVELS: LobeLevels = LobeLevels { switch_nats: 10.0, floor_nats: 200.0, frame_cap_nats: 2.0 };

    /// Seed 1124's pair: the truth near the antennas' plane and its lobe
    /// shifted (+1, 0, −1, 0) teeth, 1.35 m away.
    fn pair() -> (Vector3<f64>, Vector3<f64>) {
        let truth = Vector3::new(-0.112, 0.959, 0.138);
        let rx = receivers(&truth, 1.0);
        let wrong = fit_nearest_lobe(&geometry(), &rx, &Vector3::new(0.864, 0.508, 0.96), 6, |p| *p).unwrap();
        (truth, wrong)
    }

    #[test]
    fn the_far_lobe_exists_and_is_far() {
        let (truth, wrong) = pair();
        assert!((wrong - truth).norm() > 1.0, "{wrong}");
        let rx = receivers(&truth, 1.0);
        let g = geometry();
        // Every path length of the far lobe sits on a tooth.
        for r in &rx {
            let d = bistatic_distance(&wrong, &g.tx_position, &r.position).0;
            assert!((d - r.candidates.distance(r.candidates.nearest_index(d))).abs() < 1e-3);
        }
    }

    #[test]
    fn a_filter_on_the_far_lobe_moves_to_the_truth() {
        let (truth, wrong) = pair();
        let rx = receivers(&truth, 1.0);
        let mut far = FarLobes::default();
        far.offer([truth], 0.0, Some(&wrong));
        let mut switched = None;
        for frame in 0..20 {
            if let LobeDecision::Switch(d) = far.update(&LobeFrame { geometry: &geometry(), receivers: &rx, weight_floor: 1e-6, levels: &LEVELS }, &wrong, |p| *p) {
                switched = Some((frame, d));
                break;
            }
        }
        let (frame, d) = switched.expect("switches");
        // Capped at 2 nats a frame: the level 10 needs 6 frames.
        assert_eq!(frame, 5);
        assert!((wrong + d - truth).norm() < 1e-3);
        // The lobe left is now the alternative, well below.
        assert_eq!(far.alternatives().len(), 1);
        assert!((far.alternatives()[0].position - wrong).norm() < 1e-3);
        assert!(far.alternatives()[0].evidence < -10.0);
    }

    #[test]
    fn a_filter_on_the_truth_stays_and_the_spread_shrinks() {
        let (truth, wrong) = pair();
        let rx = receivers(&truth, 1.0);
        let mut far = FarLobes::default();
        far.offer([wrong], 0.0, Some(&truth));
        let initial = far.spread(&truth).trace();
        assert!(initial.sqrt() > 0.5, "an unresolved far lobe widens the covariance: {initial}");
        for _ in 0..5 {
            assert_eq!(far.update(&LobeFrame { geometry: &geometry(), receivers: &rx, weight_floor: 1e-6, levels: &LEVELS }, &truth, |p| *p), LobeDecision::Stay);
        }
        // At −10 nats the tempered spread still covers the far lobe (decimetres) ...
        let young = far.spread(&truth).trace().sqrt();
        assert!(young > 0.1 && young < initial.sqrt(), "{young}");
        // ... and after 60 frames at the cap (−120 nats) nothing of it shows.
        for _ in 0..55 {
            assert_eq!(far.update(&LobeFrame { geometry: &geometry(), receivers: &rx, weight_floor: 1e-6, levels: &LEVELS }, &truth, |p| *p), LobeDecision::Stay);
        }
        assert!(far.spread(&truth).trace().sqrt() < 1e-5);
    }

    #[test]
    fn offers_skip_the_same_lobe_and_replace_the_weakest() {
        let mut far = FarLobes::default();
        let filter = Vector3::zeros();
        far.offer([Vector3::new(0.01, 0.0, 0.0)], 0.0, Some(&filter));
        assert!(far.alternatives().is_empty());
        // Best first: with the slots full, later (worse) fits at the same level replace nothing.
        far.offer((1..=SLOTS + 2).map(|i| Vector3::new(i as f64, 0.0, 0.0)), 0.0, Some(&filter));
        assert_eq!(far.alternatives().len(), SLOTS);
        assert!(far.alternatives().iter().all(|a| a.position.x <= SLOTS as f64));
        far.alternatives[2].evidence = -50.0;
        far.offer([Vector3::new(0.0, 9.0, 0.0)], -200.0, Some(&filter));
        assert!(far.alternatives().iter().all(|a| a.position.y == 0.0), "a weaker newcomer replaces nothing");
        far.offer([Vector3::new(0.0, 9.0, 0.0)], -10.0, None);
        assert_eq!(far.alternatives()[2].position, Vector3::new(0.0, 9.0, 0.0));
    }

    #[test]
    fn a_fit_on_the_antennas_plane_survives() {
        // Every antenna at z = 0: on that plane the height is unobserved
        // (the path lengths' z-gradient vanishes) and undamped normal
        // equations are singular; the truth's lobe was lost that way.
        let (truth, wrong) = pair();
        let rx = receivers(&truth, 1.0);
        let on_plane = Vector3::new(truth.x, truth.y, 0.0);
        let floor = |p: &Vector3<f64>| Vector3::new(p.x, p.y, p.z.max(0.0));
        let fit = fit_nearest_lobe(&geometry(), &rx, &on_plane, STEPS, floor).expect("a fit");
        assert!((fit - truth).norm() < 0.2, "{fit}");
        let mut far = FarLobes::default();
        far.offer([on_plane], 0.0, Some(&wrong));
        far.update(&LobeFrame { geometry: &geometry(), receivers: &rx, weight_floor: 1e-6, levels: &LEVELS }, &wrong, floor);
        assert_eq!(far.alternatives().len(), 1);
    }

    #[test]
    fn a_preferred_state_displaces_the_last_ranked() {
        let mut far = FarLobes::default();
        far.offer((1..=SLOTS).map(|i| Vector3::new(i as f64, 0.0, 0.0)), 0.0, None);
        far.prefer(Vector3::new(0.0, 5.0, 0.0), 0.0);
        assert_eq!(far.alternatives().len(), SLOTS);
        assert_eq!(far.alternatives()[0].position, Vector3::new(0.0, 5.0, 0.0));
        assert!(far.alternatives().iter().all(|a| a.position.x < SLOTS as f64));
        far.prefer(Vector3::new(0.01, 5.0, 0.0), 0.0);
        assert_eq!(far.alternatives().iter().filter(|a| a.position.y == 5.0).count(), 1);
    }

    #[test]
    fn a_lobe_out_of_the_region_is_held_at_its_edge() {
        let (truth, wrong) = pair();
        let rx = receivers(&truth, 1.0);
        let mut far = FarLobes::default();
        far.offer([wrong], 0.0, Some(&truth));
        far.update(&LobeFrame { geometry: &geometry(), receivers: &rx, weight_floor: 1e-6, levels: &LEVELS }, &truth, |p| Vector3::new(p.x, p.y, p.z.min(0.5)));
        assert_eq!(far.alternatives().len(), 1);
        let held = far.alternatives()[0];
        assert!(held.position.z <= 0.5);
        // Off its teeth there: far less likely than the truth.
        assert!(held.evidence <= -LEVELS.frame_cap_nats);
    }
}
