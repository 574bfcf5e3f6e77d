//! A static tag's position from carrier phase: the search behind
//! `scattertrack locate` (Python `scattertrack.locate`, docs/calibration.md).
//!
//! Each read k of one tag leaves, after the calibrated offsets, the unit
//! phasor z_k ≈ exp(j (k_k d_k(p) + θ)) with k_k = m s 4π f_k / c (rad/m,
//! m = 2π/P) and θ the tag's own offset. Profiling θ out, a position p
//! explains the reads as well as their coherence
//!
//!   R(p) = |Σ_k z_k exp(−j k_k d_k(p))| / n,
//!
//! whose local maxima are the candidates. Steps, one file each:
//!
//! 1. **Hop ranging** (several channels, [`hop_range`]): per antenna, the
//!    phase slope against k is its range; multilaterated
//!    ([`hop_centre`]), a centre and its covariance bound the box to search.
//! 2. **Grid** over the box at a quarter of the lattice step 2π/k̄
//!    ([`search`]), R evaluated through per-antenna envelope tables
//!    ([`coherence::Envelopes`]); the best points at least half a step apart
//!    are the seeds.
//! 3. **Refinement** of each seed by Gauss–Newton on the wrapped residuals
//!    with θ re-profiled ([`refine`]).
//! 4. **Candidates** ([`candidates`]): weights from the coherence, the
//!    Fisher covariance at the noise the fit shows plus the consider
//!    covariance of a per-antenna phase bias.
//!
//! [`batch`] runs step 4 for many tags on every core, results in tag order.
//!
//! **Known reflectors** ([`Paths`]): a wall adds to each read the excess
//! phase of its reflected path, which changes across the band and bends
//! the hop ranges by decimetres (docs/calibration.md). With the scene's
//! reflectors, d_k(p) above is the *apparent* range
//! ([`crate::model::apparent_range`]). The excess depends on where p is,
//! not on its range alone, so the per-antenna envelope tables hold the
//! direct model only: they still rank the grid (the excess moves a peak
//! by millimetres), but every lattice cell of the box gets a seed, the
//! seeds climb on the full model, and the hop ranges that bound the box
//! carry the reflectors' largest bias ([`hop_centre`]).

pub mod batch;
pub mod candidates;
pub mod coherence;
pub mod hop_centre;
pub mod hop_range;
pub mod refine;
pub mod search;

pub use batch::locate_batch;
pub use candidates::{phase_candidates, Candidate, Settings};
pub use coherence::coherence;
pub use hop_centre::hop_centre;
pub use hop_range::hop_range;
pub use refine::refine;
pub use search::search;

use nalgebra::{Complex, Vector3};

use crate::model::{apparent_range_at, ReflectedPath};

/// The scene's known reflectors as each antenna sees them.
#[derive(Clone, Copy)]
pub struct Paths<'a> {
    /// Per anchor (indexed as `anchors`): its reflected paths
    /// ([`crate::model::reflected_paths`]); empty for none.
    pub per_anchor: &'a [Vec<ReflectedPath>],
    /// m in k = m s 4π f / c (2 for a mod-π reader): the carrier's
    /// wavenumber 2π f / c is |k| / (2 m).
    pub phase_multiplier: f64,
}

/// One tag's reads for the phase search, one entry a read or a group of
/// reads on one antenna and channel ([`PhaseReads::grouped`]).
pub struct PhaseReads<'a> {
    /// Phasors z_k (offsets removed): unit for a read, the sum of its reads' for a group.
    pub z: &'a [Complex<f64>],
    /// Wavenumbers k_k = m s 4π f_k / c, rad/m.
    pub k: &'a [f64],
    /// Antenna of each entry (an index into `anchors`).
    pub antenna: &'a [usize],
    /// Antenna positions, m.
    pub anchors: &'a [Vector3<f64>],
    /// Reads in each entry (`None`: one each).
    pub count: Option<&'a [f64]>,
    /// Known reflectors (`None`: the direct path alone).
    pub paths: Option<Paths<'a>>,
}

/// Reads summed per antenna and channel: R(p) and every sum over reads
/// below are the same over groups (the reads of a group share k and d), at
/// a cost set by antennas × channels instead of the reads' number.
pub struct Grouped {
    pub z: Vec<Complex<f64>>,
    pub k: Vec<f64>,
    pub antenna: Vec<usize>,
    pub count: Vec<f64>,
}

impl Grouped {
    /// The groups as reads, with the anchors and reflectors of `like`.
    pub fn reads<'a>(&'a self, like: &PhaseReads<'a>) -> PhaseReads<'a> {
        PhaseReads { z: &self.z, k: &self.k, antenna: &self.antenna, anchors: like.anchors, count: Some(&self.count), paths: like.paths }
    }
}

impl<'a> PhaseReads<'a> {
    /// Single reads (a count of one each).
    pub fn new(z: &'a [Complex<f64>], k: &'a [f64], antenna: &'a [usize], anchors: &'a [Vector3<f64>]) -> Self {
        PhaseReads { z, k, antenna, anchors, count: None, paths: None }
    }

    /// The same reads under known reflectors (none of them: unchanged).
    pub fn with_paths(self, paths: Paths<'a>) -> Self {
        let any = paths.per_anchor.iter().any(|p| !p.is_empty());
        PhaseReads { paths: any.then_some(paths), ..self }
    }

    /// Whether any antenna has a reflected path.
    pub fn has_reflectors(&self) -> bool {
        self.paths.is_some()
    }

    /// The entries summed per (antenna, k).
    pub fn grouped(&self) -> Grouped {
        let mut order: Vec<usize> = (0..self.z.len()).collect();
        order.sort_unstable_by(|&a, &b| (self.antenna[a], self.k[a].to_bits()).cmp(&(self.antenna[b], self.k[b].to_bits())));
        let mut grouped = Grouped { z: Vec::new(), k: Vec::new(), antenna: Vec::new(), count: Vec::new() };
        for i in order {
            let same = grouped.antenna.last() == Some(&self.antenna[i]) && grouped.k.last().map(|k| k.to_bits()) == Some(self.k[i].to_bits());
            if same {
                *grouped.z.last_mut().expect("a group") += self.z[i];
                *grouped.count.last_mut().expect("a group") += self.count(i);
            } else {
                grouped.z.push(self.z[i]);
                grouped.k.push(self.k[i]);
                grouped.antenna.push(self.antenna[i]);
                grouped.count.push(self.count(i));
            }
        }
        grouped
    }

    /// Reads in entry i.
    pub fn count(&self, i: usize) -> f64 {
        self.count.map_or(1.0, |c| c[i])
    }

    /// Reads in all.
    pub fn total(&self) -> f64 {
        self.count.map_or(self.z.len() as f64, |c| c.iter().sum())
    }

    /// The range entry i's phase reports from p, m: the distance, or the
    /// apparent range under known reflectors.
    fn distance(&self, i: usize, p: &Vector3<f64>) -> f64 {
        match self.reflected(i) {
            Some((paths, wavenumber)) => apparent_range_at(p, &self.anchors[self.antenna[i]], paths, wavenumber, false).0,
            None => (p - self.anchors[self.antenna[i]]).norm(),
        }
    }

    /// That range and its gradient with respect to p (the unit vector from
    /// the antenna without reflectors).
    fn distance_gradient(&self, i: usize, p: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let anchor = &self.anchors[self.antenna[i]];
        match self.reflected(i) {
            Some((paths, wavenumber)) => {
                let (d, gradient) = apparent_range_at(p, anchor, paths, wavenumber, true);
                (d, gradient.expect("asked for the gradient"))
            }
            None => {
                let offset = p - anchor;
                let d = offset.norm();
                (d, offset / d.max(1e-9))
            }
        }
    }

    /// Entry i's antenna's reflected paths and the carrier's wavenumber
    /// (rad/m), when it has any.
    fn reflected(&self, i: usize) -> Option<(&'a [ReflectedPath], f64)> {
        let paths = self.paths?;
        let own = paths.per_anchor.get(self.antenna[i]).filter(|p| !p.is_empty())?;
        Some((own.as_slice(), self.k[i].abs() / (2.0 * paths.phase_multiplier)))
    }

    /// The anchors that have reads, in index order.
    fn used_anchors(&self) -> Vec<usize> {
        let mut used = vec![false; self.anchors.len()];
        for &a in self.antenna {
            used[a] = true;
        }
        (0..self.anchors.len()).filter(|&a| used[a]).collect()
    }
}

/// e^{−jφ}: the phasor that removes a phase φ.
fn rotation(phase: f64) -> Complex<f64> {
    let (s, c) = phase.sin_cos();
    Complex::new(c, -s)
}

#[cfg(test)]
pub(crate) mod fixtures {
    use nalgebra::{Complex, Vector3};

    pub const C: f64 = 299_792_458.0;

    /// Noise-free reads of a tag at `truth`, every antenna on every frequency.
    pub fn reads_at(truth: Vector3<f64>, anchors: &[Vector3<f64>], frequencies: &[f64]) -> (Vec<Complex<f64>>, Vec<f64>, Vec<usize>) {
        let (mut z, mut k, mut antenna) = (Vec::new(), Vec::new(), Vec::new());
        for (a, anchor) in anchors.iter().enumerate() {
            for f in frequencies {
                let kk = 4.0 * std::f64::consts::PI * f / C;
                let phase = kk * (truth - anchor).norm() + 0.7; // 0.7: the tag's own offset
                z.push(Complex::new(phase.cos(), phase.sin()));
                k.push(kk);
                antenna.push(a);
            }
        }
        (z, k, antenna)
    }

    pub fn layout() -> Vec<Vector3<f64>> {
        vec![Vector3::new(0.0, 0.3, 0.2), Vector3::new(0.0, 0.9, 1.1), Vector3::new(0.4, 0.0, 1.2), Vector3::new(1.0, 0.0, 0.2)]
    }

    pub fn us_band() -> Vec<f64> {
        (0..50).map(|i| 902.75e6 + 0.5e6 * i as f64).collect()
    }

    /// A wall at x = 1.6 m facing the antennas (Γ = `coefficient`), as each
    /// of `anchors` sees it.
    pub fn wall_paths(anchors: &[Vector3<f64>], coefficient: f64) -> Vec<Vec<crate::model::ReflectedPath>> {
        let wall = [crate::scene::Reflector::Plane { point: Vector3::new(1.6, 0.0, 0.0), normal: Vector3::new(-1.0, 0.0, 0.0), coefficient }];
        anchors.iter().map(|a| crate::model::reflected_paths(a, &wall)).collect()
    }

    /// Noise-free reads of a tag at `truth` whose phases carry the paths'
    /// excess: the apparent range in place of the distance (sign +1;
    /// `multiplier` 1 for mod 2π, 2 for a mod-π reader's doubled phases).
    pub fn reads_under(truth: Vector3<f64>, anchors: &[Vector3<f64>], paths: &[Vec<crate::model::ReflectedPath>], frequencies: &[f64], multiplier: f64) -> (Vec<Complex<f64>>, Vec<f64>, Vec<usize>) {
        let (mut z, mut k, mut antenna) = (Vec::new(), Vec::new(), Vec::new());
        for (a, anchor) in anchors.iter().enumerate() {
            for f in frequencies {
                let kk = multiplier * 4.0 * std::f64::consts::PI * f / C;
                let (apparent, _) = crate::model::apparent_range_at(&truth, anchor, &paths[a], kk / (2.0 * multiplier), false);
                let phase = kk * apparent + 0.7;
                z.push(Complex::new(phase.cos(), phase.sin()));
                k.push(kk);
                antenna.push(a);
            }
        }
        (z, k, antenna)
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::{layout, reads_at, us_band, wall_paths};
    use super::*;

    #[test]
    fn the_range_gradient_matches_finite_differences_under_a_wall() {
        let anchors = layout();
        let paths = wall_paths(&anchors, 0.4);
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors).with_paths(Paths { per_anchor: &paths, phase_multiplier: 1.0 });
        let p = Vector3::new(0.47, 0.63, 0.71);
        let h = 1e-7;
        for i in [0, 17, 60, 133, 199] {
            let (d, gradient) = reads.distance_gradient(i, &p);
            assert!((d - reads.distance(i, &p)).abs() < 1e-15);
            for axis in 0..3 {
                let step = Vector3::from_fn(|r, _| if r == axis { h } else { 0.0 });
                let numeric = (reads.distance(i, &(p + step)) - reads.distance(i, &(p - step))) / (2.0 * h);
                assert!((numeric - gradient[axis]).abs() < 1e-6, "read {i} axis {axis}: {numeric} vs {}", gradient[axis]);
            }
            // The wall moves the range by millimetres, not by nothing.
            assert!((d - (p - anchors[antenna[i]]).norm()).abs() > 1e-5);
        }
    }

    #[test]
    fn no_reflected_path_leaves_the_reads_on_the_direct_model() {
        let anchors = layout();
        let none: Vec<Vec<crate::model::ReflectedPath>> = vec![Vec::new(); anchors.len()];
        let (z, k, antenna) = reads_at(Vector3::new(0.5, 0.6, 0.7), &anchors, &us_band());
        let reads = PhaseReads::new(&z, &k, &antenna, &anchors).with_paths(Paths { per_anchor: &none, phase_multiplier: 1.0 });
        assert!(!reads.has_reflectors());
    }
}
