//! Twin positions: other tag positions that fit every phase a monostatic
//! reader reports for a tag at `p`, up to the phase noise.
//!
//! A read on antenna `a` at carrier `f` fixes the range only modulo the
//! candidate spacing `s(f) = P λ / 4π` (m). A position `p'` is a twin of `p`
//! for the integer shift vector `n` when, for every antenna `a`,
//!
//! `Δ_a = |p' − a| − |p − a| = n_a s(f)`
//!
//! on every frequency `f` read. The phase mismatch a twin leaves on a read is
//!
//! `z_{a,f} = wrap_±(4π Δ_a / λ_f, P) / σ_φ`   (in units of the noise σ_φ),
//!
//! and over `N` independent reads per antenna and channel its evidence
//! against the twin is `χ² = N Σ_a Σ_f z²_{a,f}`. A twin is accepted when
//! `χ² ≤ k²` (`k` = 3 by default: the data cannot tell it from `p` at 3σ)
//! and `|p' − p|` exceeds a minimum separation (1 cm).
//!
//! `p'` is found by Levenberg–Marquardt on `Σ_a (|p' − a| − t_a)²` with
//! targets `t_a = |p − a| + n_a s̄`, `s̄ = P Σ_f k_f / Σ_f k_f²`, `k_f = 4π/λ_f`
//! (the least-squares common shift over the frequencies), from a few starts:
//! `p` itself (a nearby twin), `p` mirrored through the antennas' best-fit
//! plane (3D) or line (2D), `p` rotated about the antennas' best-fit line and
//! about every line that three or more antennas lie on, and, for an
//! all-antennas shift, `p` moved radially by `n s̄`.

use nalgebra::{Matrix3, Vector3};

use crate::angle::wrap_signed;
use crate::error::{Error, Result};
use crate::scene::{Scene, SPEED_OF_LIGHT};

/// Carrier (Hz) assumed when nothing says which one is read: the middle of
/// the US 902–928 MHz band, the simulator's fixed channel.
pub const DEFAULT_FREQUENCY_HZ: f64 = 915.25e6;

/// Reads per antenna and channel counted at each position by default: a
/// 20 s recording at 12 reads/s per antenna (the scenarios' rate), spread
/// over a position and its six neighbours of the persistence test (240/7).
pub const DEFAULT_EVIDENCE_READS: f64 = 34.0;

/// One twin of a tag position.
#[derive(Debug, Clone, PartialEq)]
pub struct Twin {
    /// The twin position, metres.
    pub position: Vector3<f64>,
    /// Integer shift `n_a` of each antenna's range, in candidate spacings.
    pub shift: Vec<i32>,
    /// Evidence against the twin, `χ² = N Σ z²` (unitless; 0: exact twin).
    pub chi_square: f64,
}

/// A line `c + t u` (m; `u` unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    pub point: Vector3<f64>,
    pub direction: Vector3<f64>,
}

/// Everything a twin search needs, precomputed once per scene and channel
/// set so that [`TwinSearch::twins`] is cheap (see its cost).
#[derive(Debug, Clone)]
pub struct TwinSearch {
    antennas: Vec<Vector3<f64>>,
    dimensions: usize,
    plane_z: f64,
    /// Box a twin must lie in (m): the scene's region, or the search box.
    bounds: (Vector3<f64>, Vector3<f64>),
    /// `k_f = 4π f / c` per channel (rad/m).
    wavenumbers: Vec<f64>,
    period: f64,
    /// Least-squares common candidate spacing s̄ (m).
    spacing: f64,
    phase_noise_rad: f64,
    evidence_reads: f64,
    /// χ² threshold k² (unitless).
    chi_square_max: f64,
    min_separation_m: f64,
    /// Shift vectors tried, one entry per antenna.
    shifts: Vec<Vec<i32>>,
    lines: Vec<Line>,
    /// Mirror (3D: plane point and unit normal; 2D: in-plane line).
    mirror: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Extra starts `p ± 15 cm` along each axis (the scene analysis only).
    explore: bool,
}

/// The knobs of a twin search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwinTolerance {
    /// `k`: a twin is accepted at `χ² ≤ k²` (unitless, default 3).
    pub sigma_multiple: f64,
    /// Independent reads per antenna and channel counted as evidence at a
    /// position (default [`DEFAULT_EVIDENCE_READS`]).
    pub evidence_reads: f64,
    /// Twins closer than this to `p` are `p` itself (m, default 0.01).
    pub min_separation_m: f64,
}

impl Default for TwinTolerance {
    fn default() -> Self {
        Self { sigma_multiple: 3.0, evidence_reads: DEFAULT_EVIDENCE_READS, min_separation_m: 0.01 }
    }
}

/// Shift vectors of a full search over `antennas` antennas: every vector
/// with entries in {−1, 0, 1} (not all zero) up to 5 antennas, else those
/// with at most two non-zero entries; plus each single antenna and all
/// antennas together shifted by ±2 … ±`max_single_shift`; plus the zero
/// vector (mirror and rotation twins). Deterministic order.
pub fn shift_vectors(antennas: usize, max_single_shift: i32) -> Vec<Vec<i32>> {
    let mut out = vec![vec![0; antennas]];
    if antennas == 0 {
        return out;
    }
    let full = antennas <= 5;
    let count = 3usize.pow(antennas.min(12) as u32);
    if full {
        for code in 0..count {
            let mut c = code;
            let v: Vec<i32> = (0..antennas)
                .map(|_| {
                    let digit = (c % 3) as i32 - 1;
                    c /= 3;
                    digit
                })
                .collect();
            if v.iter().any(|&x| x != 0) {
                out.push(v);
            }
        }
    } else {
        for i in 0..antennas {
            for si in [-1, 1] {
                let mut v = vec![0; antennas];
                v[i] = si;
                out.push(v.clone());
                for j in i + 1..antennas {
                    for sj in [-1, 1] {
                        let mut w = v.clone();
                        w[j] = sj;
                        out.push(w);
                    }
                }
            }
        }
        for s in [-1, 1] {
            out.push(vec![s; antennas]);
        }
    }
    for k in 2..=max_single_shift.max(1) {
        for s in [-k, k] {
            for i in 0..antennas {
                let mut v = vec![0; antennas];
                v[i] = s;
                out.push(v);
            }
            if antennas > 1 {
                out.push(vec![s; antennas]);
            }
        }
    }
    let mut unique: Vec<Vec<i32>> = Vec::with_capacity(out.len());
    for v in out {
        if !unique.contains(&v) {
            unique.push(v);
        }
    }
    unique
}

impl TwinSearch {
    /// A search over `shifts` for the scene's antennas and the channels
    /// `frequencies_hz` (Hz, all read with calibrated offsets; empty: the
    /// default channel). `bounds` (m) is the box twins must lie in, `lines`
    /// the lines to rotate about, `mirror` the plane (3D) or line (2D) to
    /// mirror through. Fails on a non-positive frequency or a shift vector
    /// of the wrong length.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scene: &Scene,
        frequencies_hz: &[f64],
        bounds: (Vector3<f64>, Vector3<f64>),
        shifts: Vec<Vec<i32>>,
        lines: Vec<Line>,
        mirror: Option<(Vector3<f64>, Vector3<f64>)>,
        tolerance: TwinTolerance,
    ) -> Result<Self> {
        let frequencies: Vec<f64> = if frequencies_hz.is_empty() { vec![DEFAULT_FREQUENCY_HZ] } else { frequencies_hz.to_vec() };
        if frequencies.iter().any(|f| !(f.is_finite() && *f > 0.0)) {
            return Err(Error::Parameter { name: "frequencies_hz".into(), reason: "must be positive".into() });
        }
        let antennas: Vec<Vector3<f64>> = scene.antennas.iter().map(|a| a.position).collect();
        if shifts.iter().any(|s| s.len() != antennas.len()) {
            return Err(Error::Parameter { name: "shifts".into(), reason: "one entry per antenna".into() });
        }
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !ok(tolerance.sigma_multiple) || !ok(tolerance.evidence_reads) || !(tolerance.min_separation_m >= 0.0) {
            return Err(Error::Parameter { name: "tolerance".into(), reason: "sigma_multiple and evidence_reads must be positive".into() });
        }
        let wavenumbers: Vec<f64> = frequencies.iter().map(|f| 4.0 * std::f64::consts::PI * f / SPEED_OF_LIGHT).collect();
        let sum: f64 = wavenumbers.iter().sum();
        let sum_sq: f64 = wavenumbers.iter().map(|k| k * k).sum();
        Ok(Self {
            antennas,
            dimensions: scene.dimensions,
            plane_z: scene.plane_z,
            bounds,
            spacing: scene.phase_period * sum / sum_sq,
            wavenumbers,
            period: scene.phase_period,
            phase_noise_rad: scene.phase_noise_rad,
            evidence_reads: tolerance.evidence_reads,
            chi_square_max: tolerance.sigma_multiple * tolerance.sigma_multiple,
            min_separation_m: tolerance.min_separation_m,
            shifts,
            lines,
            mirror,
            explore: false,
        })
    }

    /// Adds starts at `p ± 15 cm` along each axis (thorough, 2–3× slower).
    pub fn exploring(mut self, explore: bool) -> Self {
        self.explore = explore;
        self
    }

    /// The same search restricted to `shifts` (e.g. the families a scene
    /// analysis found), which is what makes per-step calls cheap.
    pub fn with_shifts(mut self, shifts: Vec<Vec<i32>>) -> Self {
        self.shifts = shifts.into_iter().filter(|s| s.len() == self.antennas.len()).collect();
        self
    }

    /// Per-read RMS phase mismatch of `twin`, in σ: `√(χ² / (N A F))`.
    pub fn residual_sigma(&self, twin: &Twin) -> f64 {
        (twin.chi_square / (self.evidence_reads * (self.antennas.len() * self.wavenumbers.len()) as f64)).sqrt()
    }

    /// The χ² threshold `k²` (unitless).
    pub fn chi_square_max(&self) -> f64 {
        self.chi_square_max
    }

    pub fn shifts(&self) -> &[Vec<i32>] {
        &self.shifts
    }

    /// Least-squares common candidate spacing s̄ (m) of the channels.
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// Whether `p` (m) lies in the twin box (x, y only in 2D).
    pub fn in_bounds(&self, p: &Vector3<f64>) -> bool {
        (0..self.dimensions).all(|i| p[i] >= self.bounds.0[i] && p[i] <= self.bounds.1[i])
    }

    /// `χ² = N Σ_a Σ_f z²_{a,f}` of `candidate` as a twin of `p` (unitless).
    pub fn chi_square(&self, p: &Vector3<f64>, candidate: &Vector3<f64>) -> f64 {
        let mut total = 0.0;
        for a in &self.antennas {
            let delta = (candidate - a).norm() - (p - a).norm();
            for k in &self.wavenumbers {
                let z = wrap_signed(k * delta, self.period) / self.phase_noise_rad;
                total += z * z;
            }
        }
        self.evidence_reads * total
    }

    /// Every twin of `p` (m) in the box, nearest first, at most one per
    /// position (within the minimum separation).
    ///
    /// Cost, measured (release, shared 2-core VM, paper layout, 4 antennas,
    /// one channel, 12 starts per shift): about 75 µs with the four shift
    /// vectors a scene analysis finds there (±1, ±2 on antenna 4), 36 µs
    /// with ±1 only, 2.5 ms with the full 91-vector set.
    pub fn twins(&self, p: &Vector3<f64>) -> Vec<Twin> {
        let mut found: Vec<Twin> = Vec::new();
        let mut p = *p;
        if self.dimensions == 2 {
            p.z = self.plane_z;
        }
        let ranges: Vec<f64> = self.antennas.iter().map(|a| (p - a).norm()).collect();
        let mut targets = vec![0.0; self.antennas.len()];
        let range_slack = self.chi_square_max.sqrt() * self.phase_noise_rad / self.wavenumbers[0] + 1e-6;
        for shift in &self.shifts {
            for (t, (r, n)) in targets.iter_mut().zip(ranges.iter().zip(shift)) {
                *t = r + *n as f64 * self.spacing;
            }
            if !self.feasible(&targets, range_slack) {
                continue;
            }
            for start in self.starts(&p, shift) {
                let Some(x) = self.solve(&targets, start) else { continue };
                if !self.in_bounds(&x) || (x - p).norm() < self.min_separation_m {
                    continue;
                }
                if found.iter().any(|t| (t.position - x).norm() < self.min_separation_m) {
                    continue;
                }
                let chi_square = self.chi_square(&p, &x);
                if chi_square <= self.chi_square_max && self.separated(&p, &x) {
                    found.push(Twin { position: x, shift: shift.clone(), chi_square });
                }
            }
        }
        found.sort_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()));
        found
    }

    /// Whether `candidate` is a distinct minimum, not the far end of a flat
    /// valley around `p` (a poorly observed direction, which the tracker's
    /// covariance already shows): some point on the segment between them
    /// must be rejected by the χ² test.
    fn separated(&self, p: &Vector3<f64>, candidate: &Vector3<f64>) -> bool {
        [0.25, 0.5, 0.75].iter().any(|&t: &f64| self.chi_square(p, &(p + (candidate - p) * t)) > self.chi_square_max)
    }

    /// Triangle inequality on the targets: `|t_a − t_b| ≤ |a − b|` and
    /// `t_a ≥ 0`, else no point has these ranges (cheap early exit).
    fn feasible(&self, targets: &[f64], slack: f64) -> bool {
        if targets.iter().any(|&t| t < -slack) {
            return false;
        }
        for i in 0..targets.len() {
            for j in i + 1..targets.len() {
                if (targets[i] - targets[j]).abs() > (self.antennas[i] - self.antennas[j]).norm() + 2.0 * slack {
                    return false;
                }
            }
        }
        true
    }

    fn starts(&self, p: &Vector3<f64>, shift: &[i32]) -> Vec<Vector3<f64>> {
        let mut starts = Vec::with_capacity(12);
        let zero = shift.iter().all(|&n| n == 0);
        if !zero {
            starts.push(*p);
            let first = shift[0];
            if shift.iter().all(|&n| n == first) {
                let centroid = self.antennas.iter().sum::<Vector3<f64>>() / self.antennas.len() as f64;
                let mut radial = p - centroid;
                if self.dimensions == 2 {
                    radial.z = 0.0;
                }
                if radial.norm() > 1e-9 {
                    starts.push(p + radial.normalize() * (first as f64 * self.spacing));
                }
            }
        }
        if let Some((point, normal)) = self.mirror {
            starts.push(p - 2.0 * (p - point).dot(&normal) * normal);
        }
        if self.dimensions == 3 {
            for line in &self.lines {
                let v = p - line.point;
                let along = v.dot(&line.direction) * line.direction;
                let across = v - along;
                let side = line.direction.cross(&across);
                for angle_deg in [60.0f64, -60.0, 120.0, -120.0, 180.0] {
                    let (s, c) = angle_deg.to_radians().sin_cos();
                    starts.push(line.point + along + c * across + s * side);
                }
            }
        }
        if self.explore {
            for axis in 0..self.dimensions {
                for sign in [-1.0, 1.0] {
                    let mut q = *p;
                    q[axis] += sign * 0.15;
                    starts.push(q);
                }
            }
        }
        starts
    }

    /// Levenberg–Marquardt on `Σ_a (|x − a| − t_a)²` from `start` (m); z
    /// held at the plane in 2D. `None` when it cannot move (x on an antenna).
    fn solve(&self, targets: &[f64], start: Vector3<f64>) -> Option<Vector3<f64>> {
        let mut x = start;
        if self.dimensions == 2 {
            x.z = self.plane_z;
        }
        let cost = |x: &Vector3<f64>| -> f64 { self.antennas.iter().zip(targets).map(|(a, t)| ((x - a).norm() - t).powi(2)).sum() };
        let mut current = cost(&x);
        let mut damping = 1e-3;
        for _ in 0..40 {
            let mut jtj = Matrix3::<f64>::zeros();
            let mut jtr = Vector3::<f64>::zeros();
            for (a, t) in self.antennas.iter().zip(targets) {
                let d = x - a;
                let r = d.norm();
                if r < 1e-9 {
                    return None;
                }
                let mut u = d / r;
                if self.dimensions == 2 {
                    u.z = 0.0;
                }
                jtj += u * u.transpose();
                jtr += u * (r - t);
            }
            if self.dimensions == 2 {
                jtj[(2, 2)] = 1.0;
            }
            let mut accepted = false;
            while damping < 1e8 {
                let mut lhs = jtj;
                for i in 0..3 {
                    lhs[(i, i)] += damping * (jtj[(i, i)] + 1e-9);
                }
                let Some(chol) = lhs.cholesky() else { damping *= 10.0; continue };
                let step = -chol.solve(&jtr);
                let trial = x + step;
                let trial_cost = cost(&trial);
                if trial_cost <= current {
                    let small = step.norm() < 1e-10;
                    x = trial;
                    current = trial_cost;
                    damping = (damping / 3.0).max(1e-9);
                    accepted = true;
                    if small {
                        return Some(x);
                    }
                    break;
                }
                damping *= 4.0;
            }
            if !accepted || current < 1e-24 {
                break;
            }
        }
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}
