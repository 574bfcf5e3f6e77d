//! Scene geometry check: can this antenna layout fix a tag's position from
//! the phases a monostatic (COTS) reader reports?
//!
//! A read fixes a range only to `d0 + n s` (`s = P λ / 4π`, m). The integers
//! `n_a` are resolved by the layout, mobility and frequency diversity; some
//! layouts leave them free. A *twin* of a tag position `p` is a position
//! `p'` with `|p' − a| − |p − a| = n_a s(f)` for every antenna `a` and every
//! frequency `f` read (see [`super::twins`] for the solver and the χ² test
//! that accepts it within the noise). Known degenerate layouts:
//!
//! - three or more antennas on one line fix only the position along the line
//!   and the distance from it: rotating `p` about the line until a fourth
//!   antenna's range has moved by `k s` is an exact twin for every `k`;
//! - all antennas in one plane: the mirror image through it (`n = 0`);
//! - a flat layout: an all-antennas shift (`n_a = k` for all `a`) is nearly
//!   matched by moving `p` radially;
//! - coincident antennas add nothing;
//! - in 2D (tag in the plane `z = plane_z`) the same holds in the plane.
//!
//! [`analyse_scene`] reports the layout's structure ([`LayoutFinding`]) and
//! searches numerically for twin families ([`TwinFamily`]): it samples the
//! region on a cell-centred grid (`grid_points`, default 343 = 7³ in 3D,
//! 324 = 18² in 2D), tries every shift vector of [`shift_vectors`] at each
//! sample and keeps a twin only if it *persists*: the tag moved by 5 cm
//! along each axis still has a twin of the same shift (a twin that exists
//! only on a curve through the region does not survive motion, so the
//! tracker resolves it). Families are grouped by the set of antennas whose
//! integers are free. Bounds of the search (reported with the result): the
//! grid, shifts |n_a| ≤ 1 in every combination (≤ 2 non-zero entries above
//! 5 antennas), ±2 singly and all together, χ² ≤ 9 per
//! `evidence_reads` reads per antenna and channel. Twins beyond these
//! shifts (further away) are not searched: no finding means none within
//! these bounds.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::twins::{shift_vectors, Line, Twin, TwinSearch, TwinTolerance, DEFAULT_FREQUENCY_HZ};
use crate::error::{Error, Result};
use crate::scene::Scene;

/// The 50 US channels (Hz), 902.75 … 927.25 MHz in 0.5 MHz steps: the
/// hopping the "enable hopping" remedy is checked against.
pub fn us_channels_hz() -> Vec<f64> {
    (0..50).map(|k| 902.75e6 + 0.5e6 * k as f64).collect()
}

/// Antenna offsets (m) tried, in order, for the "move antenna" remedy.
const REMEDY_OFFSETS_M: [f64; 10] = [0.01, 0.02, 0.03, 0.05, 0.07, 0.10, 0.15, 0.20, 0.30, 0.50];

/// Bounds and tolerances of the analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbiguityOptions {
    /// Region samples (about; the grid is m³ or m² cells), default 343.
    pub grid_points: usize,
    /// Largest |n| of single-antenna and all-antennas shifts (default 2).
    pub max_single_shift: i32,
    pub tolerance: TwinTolerance,
    /// Antennas within this of one point / line / plane are coincident /
    /// collinear / coplanar (m, default 0.01).
    pub layout_tolerance_m: f64,
    /// Motion a twin must survive along each axis (m, default 0.10).
    pub persistence_step_m: f64,
    /// Without a `[region]`, the antennas' bounding box grown by this (m, default 1).
    pub no_region_margin_m: f64,
    /// Work out the remedies (offsets, hopping); off for a quick check.
    pub remedies: bool,
}

impl Default for AmbiguityOptions {
    fn default() -> Self {
        Self {
            grid_points: 343,
            max_single_shift: 2,
            tolerance: TwinTolerance::default(),
            layout_tolerance_m: 0.01,
            persistence_step_m: 0.20,
            no_region_margin_m: 1.0,
            remedies: true,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayoutKind {
    /// Antennas within the tolerance of one point.
    Coincident,
    /// Three or more antennas within the tolerance of one line.
    Collinear,
    /// All antennas (four or more) within the tolerance of one plane.
    Coplanar,
}

/// A structural fact about the layout (not by itself an ambiguity).
#[derive(Debug, Clone, PartialEq)]
pub struct LayoutFinding {
    pub kind: LayoutKind,
    /// Antenna indices (into `scene.antennas`).
    pub antennas: Vec<usize>,
    /// Largest distance of these antennas from the point / line / plane (m).
    pub deviation_m: f64,
    /// Collinear: the line; coplanar: a point of the plane and its normal.
    pub line: Option<Line>,
    pub plane: Option<(Vector3<f64>, Vector3<f64>)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FamilyKind {
    /// `n = 0`: the mirror image through the antennas' plane (2D: line).
    Mirror,
    /// The other antennas lie on one line (`TwinFamily::line`).
    Line,
    /// Every range shifted by the same integer, matched by a radial move.
    AllAntennas,
    /// No more antennas than unknowns (3 in 3D, 2 in 2D).
    TooFewAntennas,
    Other,
}

/// What would fix a family.
#[derive(Debug, Clone, PartialEq)]
pub struct Remedy {
    /// Move this antenna (index) ...
    pub move_antenna: Option<usize>,
    /// ... off the line / plane of these antennas ...
    pub away_from: Vec<usize>,
    /// ... along this unit direction ...
    pub direction: Vector3<f64>,
    /// ... by at least this much (m); `None` with `move_antenna` set: no
    /// offset up to 50 cm removed the family.
    pub offset_m: Option<f64>,
    /// Whether hopping over the 50 US channels with calibrated offsets
    /// removes it (`None`: not checked, e.g. already hopping or a mirror).
    pub hopping_breaks: Option<bool>,
    /// Mirror: a region bounded by this plane (point, unit normal towards
    /// the side kept is either way) excludes the twin side.
    pub region_plane: Option<(Vector3<f64>, Vector3<f64>)>,
}

/// A family of twins: one set of antennas whose integers are free.
#[derive(Debug, Clone, PartialEq)]
pub struct TwinFamily {
    pub kind: FamilyKind,
    /// Antennas whose integers are free (indices; empty for a mirror).
    pub free: Vec<usize>,
    /// The antennas whose line (or plane) explains it.
    pub line: Vec<usize>,
    /// Shift vectors seen (entries per antenna).
    pub shifts: Vec<Vec<i32>>,
    /// Share of the region samples that have a twin of this family (0–1).
    pub share: f64,
    /// Over those samples, the nearest twin's distance |p' − p| (m):
    /// median, smallest and largest.
    pub median_m: f64,
    pub min_m: f64,
    pub max_m: f64,
    /// Median per-read RMS phase mismatch of the twins, in σ (0: exact).
    pub residual_sigma: f64,
    /// Exact (`residual_sigma` ≤ [`EXACT_RESIDUAL_SIGMA`]): a degeneracy of
    /// the layout that no amount of reads on these channels resolves.
    pub exact: bool,
    pub remedy: Remedy,
}

/// Per-read residual (σ) below which a family counts as exact: far below
/// any phase noise, only the solver's rounding.
pub const EXACT_RESIDUAL_SIGMA: f64 = 1e-3;

/// Share of the region from which an approximate family is a warning
/// rather than a weak spot (motion through the rest resolves it).
pub const WEAK_SPOT_SHARE: f64 = 0.5;

impl TwinFamily {
    /// Whether to warn: exact families always, approximate ones (within
    /// the noise only) when they cover [`WEAK_SPOT_SHARE`] of the region.
    pub fn is_warning(&self) -> bool {
        self.exact || self.share >= WEAK_SPOT_SHARE
    }
}

/// The result of [`analyse_scene`], with the bounds of its search.
#[derive(Debug, Clone, PartialEq)]
pub struct AmbiguityReport {
    pub layout: Vec<LayoutFinding>,
    pub families: Vec<TwinFamily>,
    /// Channels considered jointly (Hz).
    pub frequencies_hz: Vec<f64>,
    /// Region samples searched, shift vectors tried.
    pub samples: usize,
    pub shifts_tried: usize,
    /// Box searched (m): the region, or the antennas' box grown without one.
    pub bounds: (Vector3<f64>, Vector3<f64>),
    pub region_given: bool,
    /// Why the search could not conclude (then `families` is no verdict).
    pub inconclusive: Option<String>,
}

/// The channels to analyse jointly: the distinct `read_frequencies_hz`
/// (1 kHz apart or more, first occurrence kept: pass the most-read first)
/// whose offsets the scene calibrates, when there are two or more; else the
/// first frequency read; with no reads, the scene's calibrated channels if
/// two or more, else [`DEFAULT_FREQUENCY_HZ`]. Uncalibrated channels are
/// left out because the trackers take their offset as 0: their phases do
/// not combine coherently across channels, so they cannot be relied on to
/// break a shift.
pub fn joint_frequencies(scene: &Scene, read_frequencies_hz: &[f64]) -> Vec<f64> {
    let calibrated = |f: f64| scene.channel_offsets.iter().any(|c| (c.frequency_hz - f).abs() <= 1e3);
    let mut distinct: Vec<f64> = Vec::new();
    for &f in read_frequencies_hz.iter().filter(|f| f.is_finite() && **f > 0.0) {
        if !distinct.iter().any(|d| (d - f).abs() <= 1e3) {
            distinct.push(f);
        }
    }
    let joint: Vec<f64> = distinct.iter().copied().filter(|&f| calibrated(f)).collect();
    if joint.len() >= 2 {
        return joint;
    }
    if let Some(&first) = distinct.first() {
        return vec![first];
    }
    let channels: Vec<f64> = scene.channel_offsets.iter().map(|c| c.frequency_hz).filter(|f| *f > 0.0).collect();
    if channels.len() >= 2 {
        channels
    } else {
        vec![DEFAULT_FREQUENCY_HZ]
    }
}

/// Centroid and the eigen-decomposition of the scatter matrix of `points`.
fn principal_axes(points: &[Vector3<f64>]) -> (Vector3<f64>, SymmetricEigen<f64, nalgebra::U3>) {
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len().max(1) as f64;
    let mut scatter = Matrix3::zeros();
    for p in points {
        let d = p - centroid;
        scatter += d * d.transpose();
    }
    (centroid, SymmetricEigen::new(scatter))
}

/// Best-fit line of `points` (direction of largest spread).
fn best_line(points: &[Vector3<f64>]) -> Line {
    let (centroid, eigen) = principal_axes(points);
    let i = eigen.eigenvalues.imax();
    Line { point: centroid, direction: eigen.eigenvectors.column(i).into_owned().normalize() }
}

/// Best-fit plane of `points`: centroid and unit normal (least spread).
fn best_plane(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let (centroid, eigen) = principal_axes(points);
    let i = eigen.eigenvalues.imin();
    (centroid, eigen.eigenvectors.column(i).into_owned().normalize())
}

fn line_distance(line: &Line, p: &Vector3<f64>) -> f64 {
    let v = p - line.point;
    (v - v.dot(&line.direction) * line.direction).norm()
}

/// Coincident groups, maximal collinear sets (≥ 3) and an all-antennas
/// plane (≥ 4), each within `tolerance_m` (m) of its point / line / plane.
pub fn layout_findings(scene: &Scene, tolerance_m: f64) -> Vec<LayoutFinding> {
    let points: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| a.position).collect();
    let n = points.len();
    let mut findings = Vec::new();
    let mut grouped = vec![false; n];
    for i in 0..n {
        if grouped[i] {
            continue;
        }
        let group: Vec<usize> = (i..n).filter(|&j| (points[j] - points[i]).norm() <= tolerance_m).collect();
        if group.len() > 1 {
            let deviation = group.iter().map(|&j| (points[j] - points[i]).norm()).fold(0.0, f64::max);
            group.iter().for_each(|&j| grouped[j] = true);
            findings.push(LayoutFinding { kind: LayoutKind::Coincident, antennas: group, deviation_m: deviation, line: None, plane: None });
        }
    }
    let mut lines: Vec<Vec<usize>> = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            if (points[j] - points[i]).norm() <= tolerance_m {
                continue;
            }
            let line = Line { point: points[i], direction: (points[j] - points[i]).normalize() };
            let set: Vec<usize> = (0..n).filter(|&k| line_distance(&line, &points[k]) <= tolerance_m).collect();
            if set.len() >= 3 && !lines.iter().any(|l| set.iter().all(|k| l.contains(k))) {
                lines.retain(|l| !l.iter().all(|k| set.contains(k)));
                lines.push(set);
            }
        }
    }
    for set in lines {
        let members: Vec<Vector3<f64>> = set.iter().map(|&k| points[k]).collect();
        let line = best_line(&members);
        let deviation = members.iter().map(|p| line_distance(&line, p)).fold(0.0, f64::max);
        findings.push(LayoutFinding { kind: LayoutKind::Collinear, antennas: set, deviation_m: deviation, line: Some(line), plane: None });
    }
    if n >= 4 {
        let (point, normal) = best_plane(&points);
        let deviation = points.iter().map(|p| (p - point).dot(&normal).abs()).fold(0.0, f64::max);
        let all_on_line = findings.iter().any(|f| f.kind == LayoutKind::Collinear && f.antennas.len() == n);
        if deviation <= tolerance_m && !all_on_line {
            findings.push(LayoutFinding { kind: LayoutKind::Coplanar, antennas: (0..n).collect(), deviation_m: deviation, line: None, plane: Some((point, normal)) });
        }
    }
    findings
}

/// The box searched (m): the region (its z replaced by the plane in 2D), or
/// without one the antennas' bounding box grown by `margin_m`.
fn search_bounds(scene: &Scene, margin_m: f64) -> (Vector3<f64>, Vector3<f64>) {
    let (mut lo, mut hi) = match &scene.region {
        Some(r) => (r.min, r.max),
        None => {
            let mut lo = Vector3::repeat(f64::INFINITY);
            let mut hi = Vector3::repeat(f64::NEG_INFINITY);
            for a in &scene.antennas {
                lo = lo.inf(&a.position);
                hi = hi.sup(&a.position);
            }
            (lo.add_scalar(-margin_m), hi.add_scalar(margin_m))
        }
    };
    if scene.dimensions == 2 {
        lo.z = scene.plane_z;
        hi.z = scene.plane_z;
    }
    (lo, hi)
}

/// Cell-centred grid of about `count` points in the box, without those
/// within 5 cm of an antenna (ranges there are degenerate).
fn grid(scene: &Scene, bounds: &(Vector3<f64>, Vector3<f64>), count: usize) -> Vec<Vector3<f64>> {
    let dims = scene.dimensions;
    let per_axis = ((count.max(1) as f64).powf(1.0 / dims as f64).round() as usize).max(1);
    let mut out = Vec::new();
    let total = per_axis.pow(dims as u32);
    for code in 0..total {
        let mut c = code;
        let mut p = Vector3::new(0.0, 0.0, scene.plane_z);
        for axis in 0..dims {
            let i = c % per_axis;
            c /= per_axis;
            p[axis] = bounds.0[axis] + (i as f64 + 0.5) * (bounds.1[axis] - bounds.0[axis]) / per_axis as f64;
        }
        if scene.antennas.iter().all(|a| (a.position - p).norm() > 0.05) {
            out.push(p);
        }
    }
    out
}

/// The twin search the analysis uses, for `shifts` (all by default).
/// Rotation lines: the antennas' best-fit line and every collinear set's;
/// mirror: the best-fit plane (3D) or the vertical plane through the
/// best-fit line of the antennas' projections (2D).
pub fn twin_search(scene: &Scene, frequencies_hz: &[f64], options: &AmbiguityOptions) -> Result<TwinSearch> {
    let points: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| a.position).collect();
    let layout = layout_findings(scene, options.layout_tolerance_m);
    let mut lines = vec![best_line(&points)];
    lines.extend(layout.iter().filter_map(|f| f.line));
    let mirror = if scene.dimensions == 3 {
        Some(best_plane(&points))
    } else {
        let flat: Vec<Vector3<f64>> = points.iter().map(|p| Vector3::new(p.x, p.y, 0.0)).collect();
        let line = best_line(&flat);
        let mut normal = Vector3::new(-line.direction.y, line.direction.x, 0.0);
        if normal.norm() < 1e-9 {
            normal = Vector3::x();
        }
        Some((line.point, normal.normalize()))
    };
    let bounds = search_bounds(scene, options.no_region_margin_m);
    let shifts = shift_vectors(points.len(), options.max_single_shift);
    TwinSearch::new(scene, frequencies_hz, bounds, shifts, lines, mirror, options.tolerance)
}

/// Every twin of the tag position `position` (m) in the region, nearest
/// first, with the full set of shift vectors: a convenience for one-off
/// use (about 2.5 ms for 4 antennas). A tracker calling it every step
/// should build [`twin_search`] once and restrict it with
/// [`TwinSearch::with_shifts`] to the shifts [`analyse_scene`] found
/// (about 75 µs per call on the paper layout).
pub fn twin_positions(scene: &Scene, position: &Vector3<f64>, frequencies_hz: &[f64], options: &AmbiguityOptions) -> Result<Vec<Twin>> {
    Ok(twin_search(scene, frequencies_hz, options)?.twins(position))
}

/// Whether the twin of `p` survives motion: moving `p` by `step` (m) along
/// each axis (one of ± inside the box; axes with neither are skipped) still
/// has a twin of the same shift, and the evidence summed over `p` and these
/// neighbours, `χ²_p + Σ_axis χ²_axis`, stays within the threshold. This is
/// the χ² a twin trajectory collects from a tag moving through the
/// neighbourhood with `evidence_reads` reads per antenna and channel at each
/// position: it rejects twins that exist only on a thin slab.
fn persists(search: &TwinSearch, p: &Vector3<f64>, twin: &Twin, step: f64, dims: usize) -> bool {
    let single = search.clone().with_shifts(vec![twin.shift.clone()]);
    let mut total = twin.chi_square;
    for axis in 0..dims {
        let mut best: Option<f64> = None;
        let mut tried = false;
        for sign in [1.0, -1.0] {
            let mut q = *p;
            q[axis] += sign * step;
            if !search.in_bounds(&q) {
                continue;
            }
            tried = true;
            let moved = twin.position + (q - p);
            for t in single.twins(&q) {
                if (t.position - moved).norm() < 4.0 * step + 0.2 {
                    best = Some(best.map_or(t.chi_square, |b: f64| b.min(t.chi_square)));
                }
            }
        }
        match (tried, best) {
            (false, _) => {}
            (true, None) => return false,
            (true, Some(chi_square)) => total += chi_square,
        }
    }
    total <= search.chi_square_max()
}

struct Occurrence {
    shifts: Vec<Vec<i32>>,
    samples: Vec<usize>,
    nearest_m: Vec<f64>,
    /// Per-read RMS phase mismatch of the nearest twin, in σ.
    residual_sigma: Vec<f64>,
}

/// Runs `search` over `samples`, keeping persistent twins, grouped by the
/// free antennas (sorted indices) in a deterministic order.
fn families(search: &TwinSearch, samples: &[Vector3<f64>], options: &AmbiguityOptions, dims: usize) -> Vec<(Vec<usize>, Occurrence)> {
    let mut groups: Vec<(Vec<usize>, Occurrence)> = Vec::new();
    for (index, p) in samples.iter().enumerate() {
        let mut nearest: Vec<(Vec<usize>, f64)> = Vec::new();
        for twin in search.twins(p) {
            let free: Vec<usize> = (0..twin.shift.len()).filter(|&a| twin.shift[a] != 0).collect();
            let slot = groups.iter().position(|(f, _)| *f == free);
            let known_shift = slot.is_some_and(|i| groups[i].1.shifts.contains(&twin.shift));
            let seen_here = nearest.iter().any(|(f, _)| *f == free);
            // Twins come nearest first: the first persistent one of a family
            // at this sample gives its distance; later ones only add shifts.
            if (seen_here && known_shift) || !persists(search, p, &twin, options.persistence_step_m, dims) {
                continue;
            }
            let slot = slot.unwrap_or_else(|| {
                groups.push((free.clone(), Occurrence { shifts: Vec::new(), samples: Vec::new(), nearest_m: Vec::new(), residual_sigma: Vec::new() }));
                groups.len() - 1
            });
            let group = &mut groups[slot].1;
            if !group.shifts.contains(&twin.shift) {
                group.shifts.push(twin.shift.clone());
            }
            if seen_here {
                continue;
            }
            let distance = (twin.position - p).norm();
            nearest.push((free, distance));
            group.samples.push(index);
            group.nearest_m.push(distance);
            group.residual_sigma.push(search.residual_sigma(&twin));
        }
    }
    groups.sort_by(|a, b| a.0.cmp(&b.0));
    groups
}

/// Share (0–1) of `samples` where `shifts` still have a persistent twin
/// in `scene` on `frequencies_hz`.
fn remaining_share(scene: &Scene, frequencies_hz: &[f64], shifts: &[Vec<i32>], samples: &[Vector3<f64>], options: &AmbiguityOptions) -> Result<f64> {
    let search = twin_search(scene, frequencies_hz, options)?.exploring(true).with_shifts(shifts.to_vec());
    let hit = families(&search, samples, options, scene.dimensions).iter().map(|(_, o)| o.samples.len()).max().unwrap_or(0);
    Ok(hit as f64 / samples.len().max(1) as f64)
}

/// Smallest of [`REMEDY_OFFSETS_M`] (m) at which moving `antenna` along
/// `direction` leaves no sample with a twin of the family.
fn remedy_offset(scene: &Scene, frequencies_hz: &[f64], antenna: usize, direction: &Vector3<f64>, shifts: &[Vec<i32>], samples: &[Vector3<f64>], options: &AmbiguityOptions) -> Result<Option<f64>> {
    for offset in REMEDY_OFFSETS_M {
        let mut moved = scene.clone();
        moved.antennas[antenna].position += offset * direction;
        if remaining_share(&moved, frequencies_hz, shifts, samples, options)? == 0.0 {
            return Ok(Some(offset));
        }
    }
    Ok(None)
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    let n = values.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// A unit vector perpendicular to `axis` (m-free), towards `towards` if it
/// has a perpendicular component, else any.
fn perpendicular(axis: &Vector3<f64>, towards: &Vector3<f64>) -> Vector3<f64> {
    let v = towards - towards.dot(axis) * axis;
    if v.norm() > 1e-6 {
        return v.normalize();
    }
    let helper = if axis.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    axis.cross(&helper).normalize()
}

/// The layout's structure and its twin families on the channels
/// `frequencies_hz` (Hz, see [`joint_frequencies`]; empty: the default
/// channel). Pure and deterministic; about 1–1.5 s for 4 antennas with the
/// remedies (they re-run the search for moved antennas and for hopping).
pub fn analyse_scene(scene: &Scene, frequencies_hz: &[f64], options: &AmbiguityOptions) -> Result<AmbiguityReport> {
    if options.grid_points == 0 || !(options.layout_tolerance_m >= 0.0) || !(options.persistence_step_m > 0.0) {
        return Err(Error::Parameter { name: "options".into(), reason: "grid_points and persistence_step_m must be positive".into() });
    }
    let frequencies: Vec<f64> = if frequencies_hz.is_empty() { vec![DEFAULT_FREQUENCY_HZ] } else { frequencies_hz.to_vec() };
    let dims = scene.dimensions;
    let layout = layout_findings(scene, options.layout_tolerance_m);
    let search = twin_search(scene, &frequencies, options)?.exploring(true);
    let bounds = search_bounds(scene, options.no_region_margin_m);
    let samples = grid(scene, &bounds, options.grid_points);
    let points: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| a.position).collect();
    let coplanar = layout.iter().find(|f| f.kind == LayoutKind::Coplanar).and_then(|f| f.plane);
    let mut out = Vec::new();
    for (free, mut occurrence) in families(&search, &samples, options, dims) {
        let all = points.len();
        let uniform = occurrence.shifts.iter().all(|s| s.iter().all(|&n| n == s[0]));
        let others: Vec<usize> = (0..all).filter(|a| !free.contains(a)).collect();
        let line_of_others = dims == 3
            && others.len() >= 3
            && layout.iter().any(|f| f.kind == LayoutKind::Collinear && others.iter().all(|a| f.antennas.contains(a)));
        let (kind, line) = if free.is_empty() {
            (FamilyKind::Mirror, (0..all).collect())
        } else if line_of_others {
            (FamilyKind::Line, others.clone())
        } else if all <= dims {
            (FamilyKind::TooFewAntennas, vec![])
        } else if free.len() == all && uniform {
            (FamilyKind::AllAntennas, (0..all).collect())
        } else {
            (FamilyKind::Other, vec![])
        };
        let family_samples: Vec<Vector3<f64>> = occurrence.samples.iter().map(|&i| samples[i]).collect();
        let mut remedy = Remedy { move_antenna: None, away_from: vec![], direction: Vector3::zeros(), offset_m: None, hopping_breaks: None, region_plane: None };
        match kind {
            FamilyKind::Line => {
                let members: Vec<Vector3<f64>> = line.iter().map(|&a| points[a]).collect();
                let fit = best_line(&members);
                let middle = *line.iter().min_by(|&&a, &&b| (points[a] - fit.point).norm().total_cmp(&(points[b] - fit.point).norm())).unwrap_or(&line[0]);
                let free_centroid = free.iter().map(|&a| points[a]).sum::<Vector3<f64>>() / free.len() as f64;
                remedy.move_antenna = Some(middle);
                remedy.away_from = line.clone();
                remedy.direction = perpendicular(&fit.direction, &(free_centroid - fit.point));
            }
            FamilyKind::Mirror => {
                remedy.region_plane = if dims == 3 { coplanar } else { search_mirror(scene) };
                if dims == 3 {
                    if let Some((point, normal)) = coplanar {
                        let far = (0..all).max_by(|&a, &b| (points[a] - point).norm().total_cmp(&(points[b] - point).norm())).unwrap_or(0);
                        remedy.move_antenna = Some(far);
                        remedy.away_from = (0..all).collect();
                        remedy.direction = normal;
                    }
                }
            }
            FamilyKind::AllAntennas => {
                if let Some((point, normal)) = coplanar {
                    let near = (0..all).min_by(|&a, &b| (points[a] - point).norm().total_cmp(&(points[b] - point).norm())).unwrap_or(0);
                    remedy.move_antenna = Some(near);
                    remedy.away_from = (0..all).collect();
                    let inside = 0.5 * (bounds.0 + bounds.1) - point;
                    remedy.direction = if inside.dot(&normal) >= 0.0 { -normal } else { normal };
                }
            }
            _ => {}
        }
        if options.remedies {
            if let Some(antenna) = remedy.move_antenna {
                remedy.offset_m = remedy_offset(scene, &frequencies, antenna, &remedy.direction, &occurrence.shifts, &family_samples, options)?;
                if kind != FamilyKind::Line {
                    // Off a plane any antenna may be the one to move; the
                    // first choice can fail (antenna 4 of the paper layout
                    // keeps a mirror plane with the line 1-2-3): keep the
                    // smallest offset over all antennas.
                    for other in (0..all).filter(|&a| a != antenna) {
                        let offset = remedy_offset(scene, &frequencies, other, &remedy.direction, &occurrence.shifts, &family_samples, options)?;
                        if let Some(x) = offset {
                            if remedy.offset_m.is_none_or(|best| x < best) {
                                remedy.offset_m = Some(x);
                                remedy.move_antenna = Some(other);
                            }
                        }
                    }
                }
            }
            if kind != FamilyKind::Mirror && frequencies.len() < 2 {
                remedy.hopping_breaks = Some(remaining_share(scene, &us_channels_hz(), &occurrence.shifts, &family_samples, options)? == 0.0);
            }
        }
        let min_m = occurrence.nearest_m.iter().copied().fold(f64::INFINITY, f64::min);
        let max_m = occurrence.nearest_m.iter().copied().fold(0.0, f64::max);
        out.push(TwinFamily {
            kind,
            free,
            line,
            shifts: occurrence.shifts.clone(),
            share: occurrence.samples.len() as f64 / samples.len().max(1) as f64,
            median_m: median(&mut occurrence.nearest_m),
            min_m,
            max_m,
            residual_sigma: median(&mut occurrence.residual_sigma.clone()),
            exact: median(&mut occurrence.residual_sigma) <= EXACT_RESIDUAL_SIGMA,
            remedy,
        });
    }
    let inconclusive = samples.is_empty().then(|| "no region sample lies 5 cm or more from every antenna".to_string());
    Ok(AmbiguityReport {
        layout,
        families: out,
        frequencies_hz: frequencies,
        samples: samples.len(),
        shifts_tried: search.shifts().len(),
        bounds,
        region_given: scene.region.is_some(),
        inconclusive,
    })
}

/// The 2D mirror line as a (point, in-plane unit normal) pair.
fn search_mirror(scene: &Scene) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let flat: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| Vector3::new(a.position.x, a.position.y, 0.0)).collect();
    let line = best_line(&flat);
    let normal = Vector3::new(-line.direction.y, line.direction.x, 0.0);
    (normal.norm() > 1e-9).then(|| (Vector3::new(line.point.x, line.point.y, scene.plane_z), normal.normalize()))
}

#[cfg(test)]
#[path = "ambiguity_tests.rs"]
mod tests;
