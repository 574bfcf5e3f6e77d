//! Shared by the wideband (localization helper) trackers: a frame's
//! distance candidates per receive antenna, and the Gaussian that one
//! tuple of candidates implies for the tag position (TurboTrack thesis
//! §5.3.1 steps 1–3: intersections, geometric linearisation eq. 5.4,
//! centroid approximation eq. 5.5).

use nalgebra::{Matrix2, Matrix3, Vector3};

use crate::geometry::{bistatic_distance, bistatic_intersections};
use crate::model::wideband::{distance_candidates, CandidateParams, Candidates};
use crate::scene::Scene;

use super::WidebandFrame;

/// The helper geometry of a scene: one transmitter, the receivers, and
/// the path-length interval each receiver can see inside the region.
#[derive(Debug, Clone)]
pub struct HelperGeometry {
    /// Transmit antenna index and position (m).
    pub tx: usize,
    pub tx_position: Vector3<f64>,
    /// Path-length bounds `[min, max]` (m) per antenna index (receivers only
    /// are meaningful).
    pub bounds: Vec<(f64, f64)>,
    /// 2: the tag is on the plane `z = plane_z`; 3: free.
    pub dimensions: usize,
    pub plane_z: f64,
}

impl HelperGeometry {
    /// None when the scene has no transmit antenna or fewer receivers
    /// than a fix needs (2 in a plane, 3 in space).
    pub fn new(scene: &Scene) -> Option<Self> {
        let tx = scene.transmitter()?;
        let needed = if scene.dimensions == 2 { 2 } else { 3 };
        if scene.receivers().len() < needed {
            return None;
        }
        let txp = scene.antennas[tx].position;
        let bounds = scene
            .antennas
            .iter()
            .map(|a| {
                let baseline = (a.position - txp).norm();
                match &scene.region {
                    // The path length is convex in the tag position, so its
                    // maximum over the box is at a corner.
                    Some(r) => {
                        let (zlo, zhi) = if scene.dimensions == 2 { (scene.plane_z, scene.plane_z) } else { (r.min.z, r.max.z) };
                        let mut far: f64 = 0.0;
                        for &x in &[r.min.x, r.max.x] {
                            for &y in &[r.min.y, r.max.y] {
                                for &z in &[zlo, zhi] {
                                    far = far.max(bistatic_distance(&Vector3::new(x, y, z), &txp, &a.position).0);
                                }
                            }
                        }
                        (baseline, far)
                    }
                    None => (baseline, baseline + 15.0),
                }
            })
            .collect();
        Some(Self { tx, tx_position: txp, bounds, dimensions: scene.dimensions, plane_z: scene.plane_z })
    }

    /// Receivers one intersection needs: 2 in a plane, 3 in space.
    pub fn needed(&self) -> usize {
        if self.dimensions == 2 {
            2
        } else {
            3
        }
    }

    /// `Some(plane_z)` for planar scenes, the argument of the intersection routine.
    pub fn plane(&self) -> Option<f64> {
        (self.dimensions == 2).then_some(self.plane_z)
    }
}

/// One receive antenna's candidates within a frame.
#[derive(Debug, Clone)]
pub struct Receiver {
    /// Antenna index in the scene.
    pub antenna: usize,
    /// Antenna position, m.
    pub position: Vector3<f64>,
    pub candidates: Candidates,
}

/// Why a frame (or one receiver block of it) was declined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decline {
    /// Malformed: wrong tx, unknown rx, sizes that do not match, bad time.
    Invalid,
    /// Fewer receivers with a usable channel (finite, non-zero) than a fix needs.
    NoChannel,
}

/// Candidates for every receiver of `frame` whose channel is usable.
/// Receiver blocks that are all NaN or zero are skipped; the frame is
/// declined when fewer than `geometry.needed()` remain.
pub fn frame_receivers(
    scene: &Scene,
    geometry: &HelperGeometry,
    frame: &WidebandFrame,
    params: &CandidateParams,
) -> Result<Vec<Receiver>, Decline> {
    let f = frame.frequencies_hz.len();
    if !frame.time_s.is_finite() || frame.tx != geometry.tx || f == 0 || frame.h.len() != frame.rx.len() * f {
        return Err(Decline::Invalid);
    }
    let mut receivers = Vec::with_capacity(frame.rx.len());
    for (r, &antenna) in frame.rx.iter().enumerate() {
        if antenna >= scene.antennas.len() || scene.antennas[antenna].role != crate::scene::Role::Rx {
            return Err(Decline::Invalid);
        }
        let (lo, hi) = geometry.bounds[antenna];
        if let Some(candidates) = distance_candidates(&frame.frequencies_hz, &frame.h[r * f..(r + 1) * f], lo, hi, params) {
            receivers.push(Receiver { antenna, position: scene.antennas[antenna].position, candidates });
        }
    }
    if receivers.len() < geometry.needed() {
        return Err(Decline::NoChannel);
    }
    Ok(receivers)
}

/// A Gaussian over the tag position, m and m².
#[derive(Debug, Clone, Copy)]
pub struct PositionGaussian {
    pub mean: Vector3<f64>,
    pub covariance: Matrix3<f64>,
    /// Mean pairwise distance between the subset intersections, the
    /// pruning statistic r(s) of §5.3.1 step 1, m.
    pub perimeter_m: f64,
}

/// All index subsets of size `k` of `0..n` (n ≤ 8 here).
pub fn subsets(n: usize, k: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    let mut current = Vec::with_capacity(k);
    fn go(start: usize, n: usize, k: usize, current: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
        if current.len() == k {
            out.push(current.clone());
            return;
        }
        for i in start..n {
            current.push(i);
            go(i + 1, n, k, current, out);
            current.pop();
        }
    }
    go(0, n, k, &mut current, &mut out);
    out
}

/// The subsets of `receivers` whose loci can meet in isolated points: in
/// space, the receivers' offsets from the transmitter must not all lie on
/// one line (collinear antennas give a circle of solutions, not a point);
/// in a plane, not all parallel. Subsets that fail are left out of the
/// fusion rather than failing it (the outside example has three receivers
/// in a row with the transmitter).
pub fn usable_subsets(geometry: &HelperGeometry, receivers: &[Receiver]) -> Vec<Vec<usize>> {
    subsets(receivers.len(), geometry.needed())
        .into_iter()
        .filter(|subset| {
            let offsets: Vec<Vector3<f64>> = subset
                .iter()
                .map(|&j| {
                    let mut a = receivers[j].position - geometry.tx_position;
                    if geometry.dimensions == 2 {
                        a.z = 0.0;
                    }
                    a
                })
                .collect();
            let scale = offsets.iter().map(|a| a.norm()).fold(0.0, f64::max).max(1e-9);
            let mut spread: f64 = 0.0;
            for a in 0..offsets.len() {
                for b in a + 1..offsets.len() {
                    spread = spread.max(offsets[a].cross(&offsets[b]).norm());
                }
            }
            spread > 1e-6 * scale * scale
        })
        .collect()
}

/// Covariance of one subset intersection point (eq. 5.4, linearised):
/// with `G` the Jacobian of the subset's path lengths at `p` (rows:
/// ellipsoid normals), `δd = G δp`, so `Σ = σ² G⁻¹ G⁻ᵀ` for independent
/// distance errors σ. (The thesis writes `A V Aᵀ` with the normals as
/// axes; the inverse is the exact linearisation when the normals are not
/// orthogonal.) Planar scenes use the xy block and a unit z variance that
/// the trackers never sample (z is fixed).
fn intersection_covariance(
    p: &Vector3<f64>,
    tx: &Vector3<f64>,
    receivers: &[&Receiver],
    sigmas: &[f64],
    planar: bool,
) -> Option<Matrix3<f64>> {
    if planar {
        let mut g = Matrix2::zeros();
        for (row, rx) in receivers.iter().enumerate() {
            let (_, grad) = bistatic_distance(p, tx, &rx.position);
            g[(row, 0)] = grad.x / sigmas[row];
            g[(row, 1)] = grad.y / sigmas[row];
        }
        let info = g.transpose() * g;
        let c = info.try_inverse()?;
        let mut m = Matrix3::zeros();
        m.fixed_view_mut::<2, 2>(0, 0).copy_from(&c);
        m[(2, 2)] = 1.0;
        Some(m)
    } else {
        let mut g = Matrix3::zeros();
        for (row, rx) in receivers.iter().enumerate() {
            let (_, grad) = bistatic_distance(p, tx, &rx.position);
            for k in 0..3 {
                g[(row, k)] = grad[k] / sigmas[row];
            }
        }
        (g.transpose() * g).try_inverse()
    }
}

/// The position covariance (m²) that a per-receiver calibration residual
/// of 1-sigma `sigma_m` on each path sum puts on a fix at `p` from the
/// receivers at `receivers` (m; every receive antenna of the scene: the
/// filter's fix draws on all of them over its frames): `σ² (JᵀJ)⁻¹`, J the gradients of the path sums
/// |p − tx| + |p − rxᵢ| (a least-squares fix moves by (JᵀJ)⁻¹Jᵀ b for
/// path biases b). Such a bias is the same on every frame, so no number of
/// frames averages it away; the filter's own spread does not contain it.
/// Planar scenes get z = 0. None when the receivers cannot fix `p`.
pub fn calibration_covariance(geometry: &HelperGeometry, receivers: &[Vector3<f64>], p: &Vector3<f64>, sigma_m: f64) -> Option<Matrix3<f64>> {
    let planar = geometry.dimensions == 2;
    let mut information = Matrix3::zeros();
    for rx in receivers {
        let (_, mut gradient) = bistatic_distance(p, &geometry.tx_position, rx);
        if planar {
            gradient.z = 0.0;
        }
        information += gradient * gradient.transpose();
    }
    Some(information_covariance(&information, planar)? * (sigma_m * sigma_m))
}

/// The covariance of an information matrix, m² per unit of information:
/// its inverse, or in planar scenes the inverse of the x–y block with z
/// left at 0. None when singular or not finite.
pub fn information_covariance(information: &Matrix3<f64>, planar: bool) -> Option<Matrix3<f64>> {
    let c = if planar {
        let block = information.fixed_view::<2, 2>(0, 0).into_owned().try_inverse()?;
        let mut c = Matrix3::zeros();
        c.fixed_view_mut::<2, 2>(0, 0).copy_from(&block);
        c
    } else {
        information.try_inverse()?
    };
    c.iter().all(|v| v.is_finite()).then_some(c)
}

/// The Gaussian of one candidate tuple `indices` (candidate index per
/// receiver, see [`Candidates::distance`]): every subset of `needed`
/// receivers is intersected (eq. 5.4), the solution nearest `near` kept
/// (this picks the region's side of a planar array's mirror pair), and
/// the points fused by their centroid (eq. 5.5):
/// `μ = mean(xᵢ)`, `Σ = (1/m²) Σᵢ Σᵢ`. None if any subset has no point.
pub fn tuple_gaussian(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    indices: &[i64],
    subset_list: &[Vec<usize>],
    near: &Vector3<f64>,
    tolerance_m: f64,
) -> Option<PositionGaussian> {
    fuse_subsets(geometry, receivers, indices, subset_list, near, tolerance_m, true)
}

/// [`tuple_gaussian`] over the subsets whose loci meet, None only when
/// none does. For seeding (which refits the point on every receiver):
/// near the truth a pair of ellipses can be nearly tangent, and at low SNR
/// noise pushes them apart by more than the tangency tolerance, which
/// would drop the true tuple for one ill-conditioned subset.
pub fn tuple_gaussian_lenient(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    indices: &[i64],
    subset_list: &[Vec<usize>],
    near: &Vector3<f64>,
    tolerance_m: f64,
) -> Option<PositionGaussian> {
    fuse_subsets(geometry, receivers, indices, subset_list, near, tolerance_m, false)
}

fn fuse_subsets(
    geometry: &HelperGeometry,
    receivers: &[Receiver],
    indices: &[i64],
    subset_list: &[Vec<usize>],
    near: &Vector3<f64>,
    tolerance_m: f64,
    require_all: bool,
) -> Option<PositionGaussian> {
    let tx = geometry.tx_position;
    let planar = geometry.dimensions == 2;
    let mut points: Vec<Vector3<f64>> = Vec::with_capacity(subset_list.len());
    let mut covariance = Matrix3::zeros();
    let mut positions = Vec::with_capacity(3);
    let mut distances = Vec::with_capacity(3);
    let mut members: Vec<&Receiver> = Vec::with_capacity(3);
    let mut sigmas = Vec::with_capacity(3);
    for subset in subset_list {
        positions.clear();
        distances.clear();
        members.clear();
        sigmas.clear();
        for &j in subset {
            positions.push(receivers[j].position);
            distances.push(receivers[j].candidates.distance(indices[j]));
            members.push(&receivers[j]);
            sigmas.push(receivers[j].candidates.sigma_m);
        }
        let solutions = bistatic_intersections(&tx, &positions, &distances, geometry.plane(), tolerance_m);
        let p = solutions.into_iter().min_by(|a, b| (a - near).norm_squared().total_cmp(&(b - near).norm_squared()));
        let Some((p, c)) = p.and_then(|p| Some((p, intersection_covariance(&p, &tx, &members, &sigmas, planar)?))) else {
            if require_all {
                return None;
            }
            continue;
        };
        covariance += c;
        points.push(p);
    }
    let m = points.len();
    if m == 0 {
        return None;
    }
    let mean = points.iter().sum::<Vector3<f64>>() / m as f64;
    let covariance = covariance / (m * m) as f64;
    let mut perimeter = 0.0;
    let mut pairs = 0usize;
    for a in 0..m {
        for b in a + 1..m {
            perimeter += (points[a] - points[b]).norm();
            pairs += 1;
        }
    }
    let perimeter_m = if pairs > 0 { perimeter / pairs as f64 } else { 0.0 };
    Some(PositionGaussian { mean, covariance, perimeter_m })
}

/// `log N(d; μ, σ²)` of a scalar.
#[inline]
pub fn log_normal(d: f64, mean: f64, sigma: f64) -> f64 {
    let z = (d - mean) / sigma;
    -0.5 * z * z - sigma.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
}

/// Log of the mixture-of-Gaussians likelihood (eqs. 5.1–5.2) of the tag
/// at `p`: `Σ_j log Σ_n w_j(n) N(dist_j(p); d_j(n), σ_j²)`. Candidates are a
/// wavelength (≫ σ) apart, so only the nearest comb tooth contributes
/// measurably; candidates outside the kept list get `weight_floor`.
/// Also returns the χ² of those nearest teeth (for outlier detection).
pub fn mixture_log_likelihood(geometry: &HelperGeometry, receivers: &[Receiver], p: &Vector3<f64>, weight_floor: f64) -> (f64, f64) {
    let mut log_l = 0.0;
    let mut chi2 = 0.0;
    for rx in receivers {
        let d = bistatic_distance(p, &geometry.tx_position, &rx.position).0;
        let c = &rx.candidates;
        let n = c.nearest_index(d);
        let z = (d - c.distance(n)) / c.sigma_m;
        chi2 += z * z;
        log_l += c.weight(n, weight_floor).ln() + log_normal(d, c.distance(n), c.sigma_m);
    }
    (log_l, chi2)
}

/// The logarithms [`mixture_log_likelihood`] takes per receiver, once per
/// frame: `ln w_j(n)` of each kept candidate, `ln σ_j` and `ln floor`. A
/// particle's likelihood then needs no logarithm (with 100 particles and 4
/// receivers that is 800 logarithms a frame, a third of the step).
#[derive(Debug, Clone, Default)]
pub struct MixtureLogs {
    log_weights: Vec<Vec<f64>>,
    log_sigma: Vec<f64>,
    log_floor: f64,
}

impl MixtureLogs {
    pub fn new(receivers: &[Receiver], weight_floor: f64) -> Self {
        Self {
            log_weights: receivers.iter().map(|r| r.candidates.weights.iter().map(|w| w.ln()).collect()).collect(),
            log_sigma: receivers.iter().map(|r| r.candidates.sigma_m.ln()).collect(),
            log_floor: weight_floor.ln(),
        }
    }
}

/// [`mixture_log_likelihood`] with the frame's logarithms tabulated
/// (`logs` built from the same `receivers` and floor): the same numbers,
/// bit for bit (`ln max(w, f) = max(ln w, ln f)`, the same operations in the
/// same order).
pub fn mixture_log_likelihood_with(geometry: &HelperGeometry, receivers: &[Receiver], logs: &MixtureLogs, p: &Vector3<f64>) -> (f64, f64) {
    let half_log_two_pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    let mut log_l = 0.0;
    let mut chi2 = 0.0;
    for (j, rx) in receivers.iter().enumerate() {
        let d = bistatic_distance(p, &geometry.tx_position, &rx.position).0;
        let c = &rx.candidates;
        let n = c.nearest_index(d);
        let z = (d - c.distance(n)) / c.sigma_m;
        chi2 += z * z;
        let log_w = if n >= 0 && (n as usize) < c.weights.len() { logs.log_weights[j][n as usize].max(logs.log_floor) } else { logs.log_floor };
        log_l += log_w + (-0.5 * z * z - logs.log_sigma[j] - half_log_two_pi);
    }
    (log_l, chi2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn collinear_subsets_are_left_out() {
        use crate::model::wideband::Candidates;
        let candidates = Candidates { distances_m: vec![2.0], weights: vec![1.0], spacing_m: 0.33, sigma_m: 0.003, best: 0, residual_coherence: 0.0 };
        let geometry = HelperGeometry { tx: 0, tx_position: Vector3::new(0.6, 0.0, 0.0), bounds: vec![], dimensions: 3, plane_z: 0.0 };
        let at = |x: f64, y: f64| Receiver { antenna: 1, position: Vector3::new(x, y, 0.0), candidates: candidates.clone() };
        // The outside example's layout: three receivers in a row with tx, one off the line.
        let receivers = vec![at(0.0, 0.0), at(0.4, 0.0), at(0.8, 0.0), at(0.6, 0.4)];
        let usable = usable_subsets(&geometry, &receivers);
        assert_eq!(usable.len(), 3);
        assert!(!usable.contains(&vec![0, 1, 2]));
    }

    #[test]
    fn subsets_are_all_combinations() {
        assert_eq!(subsets(4, 3), vec![vec![0, 1, 2], vec![0, 1, 3], vec![0, 2, 3], vec![1, 2, 3]]);
        assert_eq!(subsets(3, 2).len(), 3);
        assert_eq!(subsets(5, 3).len(), 10);
    }

    #[test]
    fn tabulated_logarithms_give_the_same_likelihood() {
        use crate::model::wideband::Candidates;
        let geometry = HelperGeometry { tx: 0, tx_position: Vector3::new(0.6, 0.0, 0.0), bounds: vec![], dimensions: 3, plane_z: 0.0 };
        let receivers: Vec<Receiver> = [[0.0, 0.0], [0.4, 0.0], [0.8, 0.0], [0.6, 0.4]]
            .iter()
            .enumerate()
            .map(|(j, p)| Receiver {
                antenna: j + 1,
                position: Vector3::new(p[0], p[1], 0.0),
                candidates: Candidates {
                    distances_m: vec![2.0 + 0.1 * j as f64, 2.33 + 0.1 * j as f64, 2.66 + 0.1 * j as f64],
                    weights: vec![0.2, 0.7, 0.1],
                    spacing_m: 0.33,
                    sigma_m: 0.003 + 0.001 * j as f64,
                    best: 1,
                    residual_coherence: 0.0,
                },
            })
            .collect();
        let logs = MixtureLogs::new(&receivers, 1e-3);
        for k in 0..200 {
            let p = Vector3::new(0.3 + 0.01 * k as f64, 1.0 - 0.003 * k as f64, 0.5 + 0.002 * k as f64);
            let a = mixture_log_likelihood(&geometry, &receivers, &p, 1e-3);
            let b = mixture_log_likelihood_with(&geometry, &receivers, &logs, &p);
            assert_eq!(a.0.to_bits(), b.0.to_bits(), "{k}");
            assert_eq!(a.1.to_bits(), b.1.to_bits());
        }
    }

    #[test]
    fn log_normal_integrates_to_one() {
        let (mean, sigma) = (0.3, 0.01);
        let step = 1e-4;
        let total: f64 = (-1000..1000).map(|k| log_normal(mean + k as f64 * step, mean, sigma).exp() * step).sum();
        assert!((total - 1.0).abs() < 1e-6, "{total}");
    }
}
