//! A bank of GLAC trackers that differ only in the correlated-error level
//! `bias_sigma_rad` (multiple-model adaptive estimation on the noise
//! level, issue 15): every member takes every read; each read a member
//! tracks adds its log evidence log p(z_k | z_1:k−1, σ_b) (the normaliser
//! of its hypothesis weights); the member with the larger accumulated
//! evidence is reported, switching only when another is ahead by
//! `bank_switch_nats`, and a member behind the best by `bank_drop_nats`
//! is dropped, so that a converged tag costs one tracker again.
//!
//! The evidence is summed over the reads every live member tracked (a
//! member still searching, or searching again after losing lock, has no
//! evidence for a read, and that read counts for nobody), so that the
//! sums compare the same data.

use std::collections::VecDeque;

use super::{Estimate, Glac, GlacParams, Measurement, Tracker, TrackerStats};
use crate::error::Result;
use crate::scene::Scene;

/// Unmatched evidence kept per member (reads the others have not tracked
/// yet): about 30 s of reads at 100/s; older entries are dropped.
const MAX_QUEUED: usize = 4096;

struct Member {
    glac: Glac,
    /// Accumulated log evidence over the matched reads, relative to the
    /// best member (kept near 0).
    log_evidence: f64,
    /// Evidence of reads the other members have not tracked yet.
    queue: VecDeque<(f64, f64)>,
    /// The estimate of the latest step.
    result: Option<Estimate>,
}

/// GLAC over several bias levels, reporting the likeliest (see the module).
pub struct GlacBank {
    members: Vec<Option<Member>>,
    /// What the members were built from (a reset rebuilds dropped ones).
    scene: Scene,
    params: Vec<GlacParams>,
    /// The reported member.
    leader: usize,
    switch_nats: f64,
    drop_nats: f64,
    /// Counters of the dropped members' work: filter updates, and the
    /// most one read cost them.
    dropped_updates: u64,
    dropped_expanded: u64,
    measurements: u64,
    switches: u64,
}

impl GlacBank {
    /// One member per level of `levels` (σ_b, rad), the first reported
    /// until the evidence says otherwise.
    #[cfg(test)]
    pub fn new(scene: Scene, params: GlacParams, levels: &[f64], switch_nats: f64, drop_nats: f64) -> Result<Self> {
        let members: Vec<GlacParams> =
            levels.iter().map(|&sigma| GlacParams { bias_sigma_rad: sigma, bank_sigma_rad: None, ..params.clone() }).collect();
        Self::of(scene, members, switch_nats, drop_nats)
    }

    /// One member per parameter set, the first reported until the
    /// evidence says otherwise.
    pub fn of(scene: Scene, params: Vec<GlacParams>, switch_nats: f64, drop_nats: f64) -> Result<Self> {
        let members = params.iter().map(|p| Self::member(&scene, p).map(Some)).collect::<Result<Vec<_>>>()?;
        Ok(Self { members, scene, params, leader: 0, switch_nats, drop_nats, dropped_updates: 0, dropped_expanded: 0, measurements: 0, switches: 0 })
    }

    fn member(scene: &Scene, params: &GlacParams) -> Result<Member> {
        let mut glac = Glac::new(scene.clone(), params.clone())?;
        glac.record_evidence();
        Ok(Member { glac, log_evidence: 0.0, queue: VecDeque::new(), result: None })
    }

    /// Live members' levels (σ_b, rad) and accumulated log evidence.
    #[cfg(test)]
    pub fn levels(&self) -> Vec<(f64, f64)> {
        self.members.iter().flatten().map(|m| (m.glac.params().bias_sigma_rad, m.log_evidence)).collect()
    }

    /// The reported member's σ_b, rad.
    #[cfg(test)]
    pub fn reported_level(&self) -> f64 {
        self.leader().glac.params().bias_sigma_rad
    }

    /// Times the reported member changed.
    #[cfg(test)]
    pub fn switches(&self) -> u64 {
        self.switches
    }

    fn leader(&self) -> &Member {
        self.members[self.leader].as_ref().expect("the leader is live")
    }

    /// Adds the evidence of the reads every live member has tracked.
    fn match_evidence(&mut self) {
        for m in self.members.iter_mut().flatten() {
            m.queue.extend(m.glac.take_evidence());
            while m.queue.len() > MAX_QUEUED {
                m.queue.pop_front();
            }
        }
        if self.members.iter().flatten().count() < 2 {
            for m in self.members.iter_mut().flatten() {
                m.queue.clear();
            }
            return;
        }
        loop {
            let fronts: Vec<Option<f64>> = self.members.iter().flatten().map(|m| m.queue.front().map(|e| e.0)).collect();
            if fronts.iter().any(|f| f.is_none()) {
                break;
            }
            let latest = fronts.iter().flatten().copied().fold(f64::NEG_INFINITY, f64::max);
            let mut all = true;
            for m in self.members.iter_mut().flatten() {
                // Reads before `latest` some member never tracked: dropped.
                while m.queue.front().is_some_and(|e| e.0 < latest) {
                    m.queue.pop_front();
                }
                all &= m.queue.front().is_some_and(|e| e.0 == latest);
            }
            if !all {
                continue;
            }
            for m in self.members.iter_mut().flatten() {
                let (_, e) = m.queue.pop_front().expect("matched");
                m.log_evidence += e;
            }
        }
        let best = self.members.iter().flatten().map(|m| m.log_evidence).fold(f64::NEG_INFINITY, f64::max);
        for m in self.members.iter_mut().flatten() {
            m.log_evidence -= best;
        }
    }

    /// Switches the reported member when another leads by the switch
    /// margin; drops members behind the best by the drop margin.
    fn select(&mut self) {
        let lead = self.leader().log_evidence;
        let (best, best_evidence) = self
            .members
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.as_ref().map(|m| (i, m.log_evidence)))
            .fold((self.leader, lead), |a, b| if b.1 > a.1 { b } else { a });
        if best != self.leader && best_evidence > lead + self.switch_nats {
            self.leader = best;
            self.switches += 1;
        }
        for (i, slot) in self.members.iter_mut().enumerate() {
            if i != self.leader && slot.as_ref().is_some_and(|m| m.log_evidence < -self.drop_nats) {
                let m = slot.take().expect("checked");
                self.dropped_updates += m.glac.stats().filter_updates;
                self.dropped_expanded += m.glac.stats().max_expanded_per_read;
            }
        }
    }
}

impl Tracker for GlacBank {
    fn step(&mut self, measurement: &Measurement) -> Option<Estimate> {
        self.measurements += 1;
        for m in self.members.iter_mut().flatten() {
            m.result = m.glac.step(measurement);
        }
        self.match_evidence();
        self.select();
        self.leader().result.clone()
    }

    /// The reported member's counters, with the work of all members (the
    /// most one read cost: the sum of every member's most, a bound).
    fn stats(&self) -> TrackerStats {
        let mut stats = self.leader().glac.stats();
        stats.filter_updates = self.dropped_updates + self.members.iter().flatten().map(|m| m.glac.stats().filter_updates).sum::<u64>();
        stats.max_expanded_per_read =
            self.dropped_expanded + self.members.iter().flatten().map(|m| m.glac.stats().max_expanded_per_read).sum::<u64>();
        stats.measurements = self.measurements;
        stats
    }

    /// Every level again, the first reported (counters kept).
    fn reset(&mut self) {
        for (slot, params) in self.members.iter_mut().zip(&self.params) {
            match slot {
                Some(m) => {
                    m.glac.reset();
                    m.queue.clear();
                    m.log_evidence = 0.0;
                    m.result = None;
                }
                None => *slot = Some(Self::member(&self.scene, params).expect("built once before")),
            }
        }
        self.leader = 0;
    }

    fn hypotheses(&self) -> Vec<([f64; 3], f64)> {
        self.leader().glac.hypotheses()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::PhaseRead;
    use nalgebra::Vector3;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;

    fn scene() -> Scene {
        crate::track::glac::tests::planar_scene(0.02)
    }

    /// 30 reads/s round the four antennas for `seconds`, a tag on a slow
    /// circle; each phase gets white noise `white` (rad) and a per-antenna
    /// AR(1) bias of stationary 1-sigma `bias` (rad), correlation time 1 s.
    fn reads(scene: &Scene, seconds: f64, white: f64, bias: f64, seed: u64) -> Vec<Measurement> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut b = [0.0f64; 4];
        let dt: f64 = 1.0 / 30.0;
        let rho: f64 = (-4.0 * dt / 1.0).exp(); // each antenna is read every 4 dt
        let n = (seconds / dt) as usize;
        for v in b.iter_mut() {
            *v = bias * rng.sample::<f64, _>(StandardNormal);
        }
        (0..n)
            .map(|k| {
                let t = dt * k as f64;
                let p = Vector3::new(0.7 + 0.2 * (0.5 * t).cos(), 0.4 + 0.2 * (0.5 * t).sin(), 0.0);
                let a = k % 4;
                b[a] = rho * b[a] + bias * (1.0 - rho * rho).sqrt() * rng.sample::<f64, _>(StandardNormal);
                let d = (p - scene.antennas[a].position).norm();
                let noise = white * rng.sample::<f64, _>(StandardNormal) + b[a];
                let phase = crate::angle::wrap(scene.ideal_phase(a, 915.25e6, d) + noise, std::f64::consts::TAU);
                Measurement::Phase(PhaseRead { time_s: t, antenna: a, frequency_hz: 915.25e6, phase_rad: phase })
            })
            .collect()
    }

    fn bank(scene: &Scene) -> GlacBank {
        let params = GlacParams { phase_noise_rad: Some(0.02), bias_time_s: 1.0, ..GlacParams::default() };
        GlacBank::new(scene.clone(), params, &[0.05, 0.4], 3.0, 20.0).unwrap()
    }

    #[test]
    fn white_reads_keep_the_small_level_and_drop_the_large() {
        let scene = scene();
        let mut bank = bank(&scene);
        for m in reads(&scene, 10.0, 0.02, 0.0, 1) {
            bank.step(&m);
        }
        assert_eq!(bank.reported_level(), 0.05);
        assert_eq!(bank.levels().len(), 1, "the large level is dropped: {:?}", bank.levels());
    }

    #[test]
    fn reads_with_a_large_slow_bias_pick_the_large_level() {
        let scene = scene();
        let mut bank = bank(&scene);
        for m in reads(&scene, 10.0, 0.02, 0.4, 2) {
            bank.step(&m);
        }
        assert_eq!(bank.reported_level(), 0.4, "{:?}", bank.levels());
        assert!(bank.switches() >= 1);
    }

    #[test]
    fn a_dropped_level_costs_no_more_work() {
        let scene = scene();
        let data = reads(&scene, 12.0, 0.02, 0.0, 3);
        let mut bank = bank(&scene);
        let mut single =
            Glac::new(scene.clone(), GlacParams { phase_noise_rad: Some(0.02), bias_time_s: 1.0, bias_sigma_rad: 0.05, ..GlacParams::default() })
                .unwrap();
        let half = data.len() / 2;
        for m in &data[..half] {
            bank.step(m);
            single.step(m);
        }
        assert_eq!(bank.levels().len(), 1, "dropped by half time: {:?}", bank.levels());
        let (bank_before, single_before) = (bank.stats().filter_updates, single.stats().filter_updates);
        for m in &data[half..] {
            bank.step(m);
            single.step(m);
        }
        let bank_work = bank.stats().filter_updates - bank_before;
        let single_work = single.stats().filter_updates - single_before;
        assert_eq!(bank_work, single_work, "the survivor is the lone tracker's twin");
        bank.reset();
        assert_eq!(bank.levels().len(), 2, "a reset brings every level back");
        assert_eq!(bank.reported_level(), 0.05);
    }
}
