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
    pub fn reads<'a>(&'a self, anchors: &'a [Vector3<f64>]) -> PhaseReads<'a> {
        PhaseReads { z: &self.z, k: &self.k, antenna: &self.antenna, anchors, count: Some(&self.count) }
    }
}

impl<'a> PhaseReads<'a> {
    /// Single reads (a count of one each).
    pub fn new(z: &'a [Complex<f64>], k: &'a [f64], antenna: &'a [usize], anchors: &'a [Vector3<f64>]) -> Self {
        PhaseReads { z, k, antenna, anchors, count: None }
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

    fn distance(&self, i: usize, p: &Vector3<f64>) -> f64 {
        (p - self.anchors[self.antenna[i]]).norm()
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
}
