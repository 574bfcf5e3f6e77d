//! Angle of arrival by MUSIC on the virtual measurement matrix
//! (docs/marvel.md sections 4 and 7 step 5; paper sec. III-C "Angle
//! estimation", eqs. 5-6).
//!
//! **Steering vector, derived from the signal model** (docs/marvel.md
//! section 6). Receive antenna `m` sits at `rho_m = rho + e_m` (`e_m` its
//! offset from the array centre, m). The tag's phase there is
//! `psi_m = -2 pi f tau_m + ...` with `tau_m = (|p - rho_tx| + |p - rho_m|)
//! / c0`. Far from the array, `|p - rho - e_m| ~ |p - rho| - e_m . u` with
//! `u = (p - rho)/|p - rho|` the direction from the controller to the drone;
//! only the receive leg depends on `m`. So `tau_m = tau_0 - (e_m . u)/c0` and
//!
//! `psi_m - psi_0 = +2 pi (f/c0) (e_m . u)`, hence
//! `a_m(u) = exp(+i 2 pi (f/c0) e_m . u)`:
//!
//! the antenna nearer the drone (`e_m . u > 0`) sees the shorter path and
//! the *larger* phase. (The paper's eq. 5 writes `exp(-i eta sin phi)` for
//! its own angle convention; with this crate's phase sign, `psi = -2 pi f
//! tau`, the plus sign is the one that points at the drone, and the tests
//! check it against phases generated from the exact geometry.)
//!
//! MUSIC: the virtual measurement matrix `X_hat` (eq. 6) holds unit-modulus
//! `exp(i theta_mn)` (antenna m, snapshot n = a channel and/or tag), so the
//! link budget does not weight the snapshots; `R = X X^H / N`; the
//! eigenvectors of its `M - K` smallest eigenvalues span the noise subspace
//! `E_n` (`K` sources), and the pseudo-spectrum `1 / ||E_n^H a(u)||^2`
//! (with `|a| = 1`) peaks at the arrival directions. The search is a grid
//! over azimuth/elevation, then Nelder-Mead refinement.
//!
//! Snapshots at different carriers (902 and 928 MHz) see slightly different
//! steering vectors (2.9 % apart). The steering uses the snapshots' mean
//! frequency `f_ref`. A carrier `f_n` scales the steering phase as if `u`
//! were scaled by `f_n / f_ref` — along itself — so with `f_ref` the mean
//! the direction error cancels to first order (the tests measure 4e-6 rad
//! for carriers 27 MHz apart). `focus` (off by default) adds a second pass
//! that multiplies snapshot `n` by `exp(-i 2 pi (f_n - f_ref)/c0 e_m . u0)`
//! at the first estimate `u0` (coherent focusing) and refines again.
//!
//! A planar array cannot tell the two sides of its plane apart: the search
//! keeps the front half-space `u . front > 0` (`+y` for the default
//! triangle, docs/marvel.md section 4). A linear array measures only the
//! cone angle to its axis: the search is then one-dimensional over azimuth
//! `[0, pi]` at zero elevation (the paper's 2D case).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use num_complex::Complex64;

use super::geometry::{azimuth_elevation, cross, direction, dot, norm, normalize, Vec3};
use crate::error::{Error, Result};
use crate::SPEED_OF_LIGHT;

/// Receive-antenna offsets from the array centre, m (world frame axes).
#[derive(Debug, Clone, PartialEq)]
pub struct ArrayGeometry {
    elements: Vec<Vec3>,
}

/// The shape of an array, which decides what it can measure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArrayKind {
    /// Collinear elements along `axis` (unit): only the cone angle.
    Linear { axis: Vec3 },
    /// Coplanar elements with unit `normal`: azimuth and elevation up to the
    /// mirror image through the plane.
    Planar { normal: Vec3 },
    /// Elements spanning 3D: the whole sphere.
    Volume,
}

impl ArrayGeometry {
    /// At least two finite, distinct elements.
    pub fn new(elements: Vec<Vec3>) -> Result<Self> {
        if elements.len() < 2 {
            return Err(Error::TooShort { what: "array elements", needed: 2, got: elements.len() });
        }
        if elements.iter().flatten().any(|x| !x.is_finite()) {
            return Err(Error::NonFinite("array element offsets".into()));
        }
        let g = Self { elements };
        if g.extent() == 0.0 {
            return Err(Error::BadConfig("array elements coincide".into()));
        }
        Ok(g)
    }

    /// The default equilateral triangle of side `d` (m) in the vertical
    /// xz-plane, facing +y (docs/marvel.md section 4): offsets
    /// `(-d/2, 0, -d/(2 sqrt 3))`, `(d/2, 0, -d/(2 sqrt 3))`, `(0, 0, d/sqrt 3)`.
    pub fn triangle(side_m: f64) -> Self {
        let s3 = 3f64.sqrt();
        Self {
            elements: vec![
                [-side_m / 2.0, 0.0, -side_m / (2.0 * s3)],
                [side_m / 2.0, 0.0, -side_m / (2.0 * s3)],
                [0.0, 0.0, side_m / s3],
            ],
        }
    }

    /// `count` antennas on x, `spacing_m` apart, centred (docs/marvel.md
    /// section 4 option `linear`: 3 at 16 cm, the paper's pole).
    pub fn linear(spacing_m: f64, count: usize) -> Self {
        let c = (count as f64 - 1.0) / 2.0;
        Self { elements: (0..count).map(|i| [(i as f64 - c) * spacing_m, 0.0, 0.0]).collect() }
    }

    pub fn elements(&self) -> &[Vec3] {
        &self.elements
    }

    pub fn len(&self) -> usize {
        self.elements.len()
    }

    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    fn extent(&self) -> f64 {
        let e0 = self.elements[0];
        self.elements.iter().map(|e| norm(&[e[0] - e0[0], e[1] - e0[1], e[2] - e0[2]])).fold(0.0, f64::max)
    }

    /// Linear, planar or volumetric (relative tolerance 1e-9 of the extent).
    pub fn kind(&self) -> ArrayKind {
        let e0 = self.elements[0];
        let rel: Vec<Vec3> = self.elements.iter().map(|e| [e[0] - e0[0], e[1] - e0[1], e[2] - e0[2]]).collect();
        let scale = self.extent();
        let far = rel.iter().copied().fold([0.0; 3], |b, r| if norm(&r) > norm(&b) { r } else { b });
        let axis = normalize(&far).unwrap_or([1.0, 0.0, 0.0]);
        let best_normal =
            rel.iter().map(|r| cross(&axis, r)).fold([0.0; 3], |b, c| if norm(&c) > norm(&b) { c } else { b });
        if norm(&best_normal) <= 1e-9 * scale {
            return ArrayKind::Linear { axis };
        }
        let normal = normalize(&best_normal).expect("non-zero");
        if rel.iter().all(|r| dot(r, &normal).abs() <= 1e-9 * scale) {
            ArrayKind::Planar { normal }
        } else {
            ArrayKind::Volume
        }
    }

    /// `a_m(u) = exp(+i 2 pi (f/c0) e_m . u) / sqrt(M)` (see the module doc
    /// for the sign), unit norm; `frequency_hz` the carrier.
    pub fn steering_vector(&self, u: &Vec3, frequency_hz: f64) -> Vec<Complex64> {
        let k = TAU * frequency_hz / SPEED_OF_LIGHT;
        let a = 1.0 / (self.len() as f64).sqrt();
        self.elements.iter().map(|e| Complex64::from_polar(a, k * dot(e, u))).collect()
    }
}

/// Search domain and options of [`music`].
#[derive(Debug, Clone, PartialEq)]
pub struct MusicConfig {
    /// Number of sources `K` (the signal subspace dimension), `1 <= K < M`.
    pub sources: usize,
    /// Coarse grid step, rad (the 16 cm triangle's beam is ~1 rad wide, so
    /// a few degrees find the basin; the refinement does the rest).
    pub grid_step_rad: f64,
    /// Azimuth interval, rad.
    pub azimuth_range: (f64, f64),
    /// Elevation interval, rad (`(0, 0)`: azimuth-only search).
    pub elevation_range: (f64, f64),
    /// Directions with `u . front <= 0` are excluded (planar arrays).
    pub front: Option<Vec3>,
    /// Focus the snapshots of different carriers at the first estimate and
    /// refine again (see the module doc; off by default).
    pub focus: bool,
    /// Refinement tolerance, rad.
    pub tolerance_rad: f64,
}

impl MusicConfig {
    /// The natural domain of an array: a linear array searches azimuth in
    /// `[0, pi]` at zero elevation (its axis is assumed horizontal; the docs'
    /// option lies on x); a planar one the front half-space, `front` = its
    /// normal signed so that its largest component is positive (+y for the
    /// default triangle); a volumetric one the whole sphere.
    pub fn for_array(geometry: &ArrayGeometry) -> Self {
        let base = Self {
            sources: 1,
            grid_step_rad: 3f64.to_radians(),
            azimuth_range: (-PI, PI),
            elevation_range: (-FRAC_PI_2, FRAC_PI_2),
            front: None,
            focus: false,
            tolerance_rad: 1e-7,
        };
        match geometry.kind() {
            ArrayKind::Linear { .. } => Self { azimuth_range: (0.0, PI), elevation_range: (0.0, 0.0), ..base },
            ArrayKind::Planar { normal } => {
                let i = (0..3).max_by(|&a, &b| normal[a].abs().total_cmp(&normal[b].abs())).unwrap_or(1);
                let front = if normal[i] < 0.0 { [-normal[0], -normal[1], -normal[2]] } else { normal };
                Self { front: Some(front), ..base }
            }
            ArrayKind::Volume => base,
        }
    }
}

/// The direction found by [`music`].
#[derive(Debug, Clone, PartialEq)]
pub struct MusicEstimate {
    /// Azimuth and elevation of `u`, rad (docs/marvel.md section 1).
    pub azimuth: f64,
    pub elevation: f64,
    /// Unit direction from the array centre towards the source (world).
    pub direction: Vec3,
    /// Pseudo-spectrum at the peak, dB: `-10 log10 ||E_n^H a||^2` (high =
    /// a clean, well-fitting single source; 0 dB = no fit at all).
    pub spectrum_db: f64,
    /// Eigenvalues of the sample covariance, ascending.
    pub eigenvalues: Vec<f64>,
}

/// Eigen-decomposition of a small Hermitian matrix by cyclic complex Jacobi
/// rotations (row-major `n x n`; only the matrix's Hermitian part is used).
/// Returns the eigenvalues ascending and the eigenvectors as the columns of
/// a row-major `n x n` matrix (`v[i * n + k]` = component `i` of vector `k`).
///
/// Why Jacobi: the matrices here are 3x3 (antennas), Jacobi is
/// unconditionally stable and accurate to rounding, and it keeps the crate
/// free of a linear-algebra dependency.
///
/// Each rotation zeroes `a_pq = |a_pq| e^{i phi}`: `V = D P` with
/// `D = diag(1, e^{-i phi})` on (p, q), which makes the pair's block real,
/// and `P` the real Jacobi rotation (`t = sgn(theta)/(|theta| +
/// sqrt(theta^2 + 1))`, `theta = (a_qq - a_pp) / (2 |a_pq|)`).
pub fn hermitian_eigen(a: &[Complex64], n: usize) -> Result<(Vec<f64>, Vec<Complex64>)> {
    if a.len() != n * n || n == 0 {
        return Err(Error::Shape(format!("hermitian_eigen: {} values for {n} x {n}", a.len())));
    }
    if a.iter().any(|x| !(x.re.is_finite() && x.im.is_finite())) {
        return Err(Error::NonFinite("matrix".into()));
    }
    // Symmetrise: (A + A^H) / 2.
    let mut m: Vec<Complex64> = (0..n * n).map(|i| (a[i] + a[(i % n) * n + i / n].conj()) * 0.5).collect();
    let mut v = vec![Complex64::new(0.0, 0.0); n * n];
    for i in 0..n {
        v[i * n + i] = Complex64::new(1.0, 0.0);
    }
    let total: f64 = m.iter().map(|x| x.norm_sqr()).sum();
    for _sweep in 0..64 {
        let off: f64 = (0..n)
            .flat_map(|p| (0..n).filter(move |&q| q != p).map(move |q| (p, q)))
            .map(|(p, q)| m[p * n + q].norm_sqr())
            .sum();
        if off <= 1e-30 * total.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                let b = apq.norm();
                if b <= 1e-300 {
                    continue;
                }
                let phase = Complex64::from_polar(1.0, -apq.arg()); // e^{-i phi}
                let theta = (m[q * n + q].re - m[p * n + p].re) / (2.0 * b);
                let t = if theta == 0.0 { 1.0 } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                let (vpp, vpq, vqp, vqq) = (Complex64::new(c, 0.0), Complex64::new(s, 0.0), phase * -s, phase * c);
                // M <- M V (columns p, q), then M <- V^H M (rows p, q).
                for k in 0..n {
                    let (x, y) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = x * vpp + y * vqp;
                    m[k * n + q] = x * vpq + y * vqq;
                    let (x, y) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = x * vpp + y * vqp;
                    v[k * n + q] = x * vpq + y * vqq;
                }
                for k in 0..n {
                    let (x, y) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = vpp.conj() * x + vqp.conj() * y;
                    m[q * n + k] = vpq.conj() * x + vqq.conj() * y;
                }
                m[p * n + q] = Complex64::new(0.0, 0.0);
                m[q * n + p] = Complex64::new(0.0, 0.0);
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| m[i * n + i].re.total_cmp(&m[j * n + j].re));
    let values = order.iter().map(|&i| m[i * n + i].re).collect();
    let mut vectors = vec![Complex64::new(0.0, 0.0); n * n];
    for (k, &i) in order.iter().enumerate() {
        for r in 0..n {
            vectors[r * n + k] = v[r * n + i];
        }
    }
    Ok((values, vectors))
}

/// The virtual measurement matrix of eq. 6: `exp(i theta)` for each phase
/// (row-major, antennas x snapshots).
pub fn virtual_measurement_matrix(phases_rad: &[f64]) -> Vec<Complex64> {
    phases_rad.iter().map(|&t| Complex64::from_polar(1.0, t)).collect()
}

/// Sample covariance `R = X X^H / N` of a row-major `m x n` matrix.
pub fn sample_covariance(x: &[Complex64], m: usize, n: usize) -> Vec<Complex64> {
    let mut r = vec![Complex64::new(0.0, 0.0); m * m];
    for i in 0..m {
        for j in 0..m {
            r[i * m + j] = (0..n).map(|s| x[i * n + s] * x[j * n + s].conj()).sum::<Complex64>() / n as f64;
        }
    }
    r
}

/// MUSIC null `||E_n^H a(u)||^2` (0 at a source, 1 when `a` lies in the
/// noise subspace); `noise` holds the noise eigenvectors as row-major
/// columns of an `m x k` matrix.
pub fn music_null(geometry: &ArrayGeometry, noise: &[Complex64], k: usize, u: &Vec3, frequency_hz: f64) -> f64 {
    let a = geometry.steering_vector(u, frequency_hz);
    let m = a.len();
    (0..k).map(|c| (0..m).map(|r| noise[r * k + c].conj() * a[r]).sum::<Complex64>().norm_sqr()).sum()
}

/// One subspace estimate: the noise eigenvectors (`m x (m - K)`) and the
/// eigenvalues.
fn noise_subspace(x: &[Complex64], m: usize, n: usize, sources: usize) -> Result<(Vec<Complex64>, Vec<f64>)> {
    let r = sample_covariance(x, m, n);
    let (values, vectors) = hermitian_eigen(&r, m)?;
    let k = m - sources;
    let mut noise = vec![Complex64::new(0.0, 0.0); m * k];
    for row in 0..m {
        for c in 0..k {
            noise[row * k + c] = vectors[row * m + c];
        }
    }
    Ok((noise, values))
}

/// Direction of arrival from phases (eqs. 5-6).
///
/// `phases_rad` is row-major antennas x snapshots (`M x N`), each the
/// channel phase of one antenna for one snapshot (a channel/tag), rad;
/// `frequencies_hz` the snapshots' carriers (`N`), Hz.
///
/// Errors: [`Error::Shape`] for sizes that do not fit the array,
/// [`Error::BadConfig`] for `K` outside `1..M` or a bad domain,
/// [`Error::NonFinite`] for non-finite phases.
pub fn music(
    geometry: &ArrayGeometry,
    config: &MusicConfig,
    phases_rad: &[f64],
    frequencies_hz: &[f64],
) -> Result<MusicEstimate> {
    let m = geometry.len();
    let n = frequencies_hz.len();
    if n == 0 || phases_rad.len() != m * n {
        return Err(Error::Shape(format!("music: {} phases for {m} antennas x {n} snapshots", phases_rad.len())));
    }
    if !(1..m).contains(&config.sources) {
        return Err(Error::BadConfig(format!("music: {} sources for {m} antennas", config.sources)));
    }
    let (a0, a1) = config.azimuth_range;
    let (e0, e1) = config.elevation_range;
    if !(a1 > a0 && e1 >= e0 && config.grid_step_rad > 0.0 && config.tolerance_rad > 0.0) {
        return Err(Error::BadConfig("music: empty search domain or bad step".into()));
    }
    if phases_rad.iter().chain(frequencies_hz).any(|x| !x.is_finite()) {
        return Err(Error::NonFinite("music phases or frequencies".into()));
    }
    let f_ref = frequencies_hz.iter().sum::<f64>() / n as f64;
    let mut x = virtual_measurement_matrix(phases_rad);
    let k = m - config.sources;
    let (noise, mut eigenvalues) = noise_subspace(&x, m, n, config.sources)?;

    let in_front = |u: &Vec3| config.front.is_none_or(|f| dot(u, &f) > 0.0);
    let null_at = |noise: &[Complex64], az: f64, el: f64| -> f64 {
        let u = direction(az, el);
        if !in_front(&u) || az < a0 || az > a1 || el < e0 || el > e1 {
            return 2.0; // outside the domain: worse than any direction
        }
        music_null(geometry, noise, k, &u, f_ref)
    };

    // Coarse grid.
    let steps = |lo: f64, hi: f64| ((hi - lo) / config.grid_step_rad).ceil().max(1.0) as usize;
    let (na, ne) = (steps(a0, a1), if e1 > e0 { steps(e0, e1) } else { 0 });
    let mut best = (2.0, 0.5 * (a0 + a1), 0.5 * (e0 + e1));
    for i in 0..=na {
        let az = a0 + (a1 - a0) * i as f64 / na as f64;
        for j in 0..=ne {
            let el = if ne == 0 { e0 } else { e0 + (e1 - e0) * j as f64 / ne as f64 };
            let d = null_at(&noise, az, el);
            if d < best.0 {
                best = (d, az, el);
            }
        }
    }
    if best.0 > 1.5 {
        return Err(Error::BadConfig("music: no direction of the grid lies in the front half-space".into()));
    }
    let two_d = e1 > e0;
    let refine = |noise: &[Complex64], start: (f64, f64), size: f64| -> (f64, f64, f64) {
        if two_d {
            nelder_mead_2d(|p| null_at(noise, p.0, p.1), start, size, config.tolerance_rad)
        } else {
            let (az, d) = golden_min(
                |az| null_at(noise, az, e0),
                (start.0 - size).max(a0),
                (start.0 + size).min(a1),
                config.tolerance_rad,
            );
            (az, e0, d)
        }
    };
    let (mut az, mut el, mut d) = refine(&noise, (best.1, best.2), config.grid_step_rad);

    let spread = frequencies_hz.iter().any(|f| (f - f_ref).abs() > 1e-9 * f_ref);
    if config.focus && spread {
        // Coherent focusing at u0: remove each snapshot's frequency offset
        // from the steering phase, then refine from u0.
        let u0 = direction(az, el);
        for (row, e) in geometry.elements().iter().enumerate() {
            let p = dot(e, &u0);
            for (col, f) in frequencies_hz.iter().enumerate() {
                x[row * n + col] *= Complex64::from_polar(1.0, -TAU * (f - f_ref) / SPEED_OF_LIGHT * p);
            }
        }
        let (focused, values) = noise_subspace(&x, m, n, config.sources)?;
        let r = refine(&focused, (az, el), config.grid_step_rad / 2.0);
        (az, el, d) = r;
        eigenvalues = values;
    }
    let u = direction(az, el);
    let (az, el) = azimuth_elevation(&u);
    Ok(MusicEstimate {
        azimuth: az,
        elevation: el,
        direction: u,
        spectrum_db: -10.0 * d.max(1e-300).log10(),
        eigenvalues,
    })
}

/// Golden-section minimum of `f` on `[a, b]`: `(x, f(x))`.
fn golden_min(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64, tolerance: f64) -> (f64, f64) {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - ratio * (b - a);
    let mut d = a + ratio * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..200 {
        if (b - a).abs() <= tolerance {
            break;
        }
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - ratio * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + ratio * (b - a);
            fd = f(d);
        }
    }
    let x = 0.5 * (a + b);
    (x, f(x))
}

/// Nelder-Mead minimum of `f(az, el)` from `start` with an initial simplex of
/// `size` rad: `(az, el, f)`.
fn nelder_mead_2d(f: impl Fn((f64, f64)) -> f64, start: (f64, f64), size: f64, tolerance: f64) -> (f64, f64, f64) {
    let mut s = [(start.0, start.1), (start.0 + size, start.1), (start.0, start.1 + size)];
    let mut v = [f(s[0]), f(s[1]), f(s[2])];
    for _ in 0..400 {
        // Order best..worst.
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        s = [s[idx[0]], s[idx[1]], s[idx[2]]];
        v = [v[idx[0]], v[idx[1]], v[idx[2]]];
        let extent =
            ((s[1].0 - s[0].0).abs() + (s[1].1 - s[0].1).abs()).max((s[2].0 - s[0].0).abs() + (s[2].1 - s[0].1).abs());
        if extent < tolerance {
            break;
        }
        let c = ((s[0].0 + s[1].0) / 2.0, (s[0].1 + s[1].1) / 2.0);
        let at = |t: f64| (c.0 + t * (s[2].0 - c.0), c.1 + t * (s[2].1 - c.1));
        let r = at(-1.0);
        let fr = f(r);
        if fr < v[0] {
            let e = at(-2.0);
            let fe = f(e);
            if fe < fr {
                s[2] = e;
                v[2] = fe;
            } else {
                s[2] = r;
                v[2] = fr;
            }
        } else if fr < v[1] {
            s[2] = r;
            v[2] = fr;
        } else {
            let (k, fk) = if fr < v[2] {
                let k = at(-0.5);
                (k, f(k))
            } else {
                let k = at(0.5);
                (k, f(k))
            };
            if fk < v[2].min(fr) {
                s[2] = k;
                v[2] = fk;
            } else {
                for i in 1..3 {
                    s[i] = ((s[0].0 + s[i].0) / 2.0, (s[0].1 + s[i].1) / 2.0);
                    v[i] = f(s[i]);
                }
            }
        }
    }
    let i = (0..3).min_by(|&i, &j| v[i].total_cmp(&v[j])).unwrap_or(0);
    (s[i].0, s[i].1, v[i])
}

/// How the four tags' angles are combined into one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AngleCombine {
    /// The paper's choice (sec. III-C, "the harmonic mean of the four
    /// angles"), applied to the azimuth in `[0, 2 pi)` and to the polar
    /// angle from +z, `pi/2 - el` in `[0, pi]` (the paper's 3D
    /// parametrisation, where both are non-negative).
    #[default]
    HarmonicMean,
    /// The normalised mean of the unit directions: the circular mean on the
    /// sphere.
    MeanDirection,
}

/// Combines per-tag `(azimuth, elevation)` pairs (rad) into one.
///
/// Why the circular mean may be better: the harmonic mean `n / sum 1/x`
/// is pulled towards the smallest angle (it equals the arithmetic mean only
/// when all agree, and an azimuth near 0 drags it far down), and it is not
/// invariant to where the angle's zero lies, so it breaks across the wrap
/// (0 vs 2 pi) and is undefined for mixed signs. The mean of unit vectors
/// has none of these problems and is the ML combination for equal
/// von Mises-Fisher errors. The paper's harmonic mean stays the default to
/// reproduce it; the tags' spread is ~D/r rad, so the two differ little
/// when the estimates agree.
///
/// Errors: [`Error::TooShort`] for no angles, [`Error::NonFinite`].
pub fn combine_angles(angles: &[(f64, f64)], method: AngleCombine) -> Result<(f64, f64)> {
    if angles.is_empty() {
        return Err(Error::TooShort { what: "angles to combine", needed: 1, got: 0 });
    }
    if angles.iter().any(|a| !(a.0.is_finite() && a.1.is_finite())) {
        return Err(Error::NonFinite("angles".into()));
    }
    match method {
        AngleCombine::HarmonicMean => {
            let harmonic = |xs: &mut dyn Iterator<Item = f64>| -> f64 {
                let v: Vec<f64> = xs.collect();
                if v.iter().any(|&x| x <= 0.0) {
                    0.0
                } else {
                    v.len() as f64 / v.iter().map(|x| 1.0 / x).sum::<f64>()
                }
            };
            let az = harmonic(&mut angles.iter().map(|a| a.0.rem_euclid(TAU)));
            let polar = harmonic(&mut angles.iter().map(|a| (FRAC_PI_2 - a.1).clamp(0.0, PI)));
            Ok((super::wrap_angle(az), FRAC_PI_2 - polar))
        }
        AngleCombine::MeanDirection => {
            let sum = angles.iter().fold([0.0; 3], |s, a| {
                let u = direction(a.0, a.1);
                [s[0] + u[0], s[1] + u[1], s[2] + u[2]]
            });
            let u = normalize(&sum).ok_or_else(|| Error::BadConfig("angles cancel: no mean direction".into()))?;
            Ok(azimuth_elevation(&u))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, Normal};

    #[test]
    fn jacobi_diagonalises_hermitian_matrices() {
        let mut rng = StdRng::seed_from_u64(7);
        for n in [1usize, 2, 3, 5] {
            for _ in 0..20 {
                let b: Vec<Complex64> = (0..n * n)
                    .map(|_| Complex64::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)))
                    .collect();
                let a: Vec<Complex64> = (0..n * n).map(|i| b[i] + b[(i % n) * n + i / n].conj()).collect();
                let (values, vectors) = hermitian_eigen(&a, n).unwrap();
                assert!(values.windows(2).all(|w| w[0] <= w[1]));
                for k in 0..n {
                    for i in 0..n {
                        let av: Complex64 = (0..n).map(|j| a[i * n + j] * vectors[j * n + k]).sum();
                        assert!((av - vectors[i * n + k] * values[k]).norm() < 1e-10, "n {n}");
                    }
                    for l in 0..n {
                        let ip: Complex64 = (0..n).map(|i| vectors[i * n + k].conj() * vectors[i * n + l]).sum();
                        let expected = if k == l { 1.0 } else { 0.0 };
                        assert!((ip - expected).norm() < 1e-10);
                    }
                }
            }
        }
        assert!(hermitian_eigen(&[Complex64::new(1.0, 0.0); 3], 2).is_err());
    }

    #[test]
    fn array_kinds_and_domains() {
        assert!(matches!(ArrayGeometry::linear(0.16, 3).kind(), ArrayKind::Linear { .. }));
        match ArrayGeometry::triangle(0.16).kind() {
            ArrayKind::Planar { normal } => assert!(normal[1].abs() > 0.999999),
            k => panic!("{k:?}"),
        }
        let c = MusicConfig::for_array(&ArrayGeometry::triangle(0.16));
        assert!(c.front.unwrap()[1] > 0.999);
        let volume = ArrayGeometry::new(vec![[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]]).unwrap();
        assert_eq!(volume.kind(), ArrayKind::Volume);
        assert!(ArrayGeometry::new(vec![[0.0; 3], [0.0; 3]]).is_err());
    }

    /// Exact phases at the array from the geometry (spherical wave,
    /// docs/marvel.md section 6, rx leg only varies), plus noise.
    fn array_phases(geometry: &ArrayGeometry, source: &Vec3, freqs: &[f64], sigma: f64, rng: &mut StdRng) -> Vec<f64> {
        let normal = Normal::new(0.0, sigma.max(1e-300)).unwrap();
        let mut out = vec![0.0; geometry.len() * freqs.len()];
        let mut offsets = Vec::new();
        for _ in freqs {
            offsets.push(rng.random_range(-PI..PI)); // unknown per-snapshot phase
        }
        for (m, e) in geometry.elements().iter().enumerate() {
            let d = norm(&[source[0] - e[0], source[1] - e[1], source[2] - e[2]]);
            for (i, f) in freqs.iter().enumerate() {
                let noise = if sigma > 0.0 { normal.sample(rng) } else { 0.0 };
                out[m * freqs.len() + i] = -TAU * f * d / SPEED_OF_LIGHT + offsets[i] + noise;
            }
        }
        out
    }

    #[test]
    fn triangle_recovers_azimuth_and_elevation_with_the_derived_sign() {
        let geometry = ArrayGeometry::triangle(0.16);
        let config = MusicConfig::for_array(&geometry);
        let freqs = [902.6e6, 928.5e6];
        let mut rng = StdRng::seed_from_u64(8);
        let mut worst: f64 = 0.0;
        for &(az, el, r) in &[(1.2, 0.2, 30.0), (0.6, -0.3, 12.0), (2.3, 0.5, 50.0), (1.6, 0.0, 20.0), (0.3, 0.1, 25.0)]
        {
            let source = direction(az, el).map(|x| x * r);
            let ph = array_phases(&geometry, &source, &freqs, 0.0, &mut rng);
            let e = music(&geometry, &config, &ph, &freqs).unwrap();
            let err = dot(&e.direction, &direction(az, el)).clamp(-1.0, 1.0).acos();
            worst = worst.max(err);
            // The spherical wave at 12 m bends the far-field fit by ~2e-3 rad.
            assert!(err < 4e-3, "az {az} el {el}: {e:?}");
            // With the opposite sign the same phases would point at -u, i.e.
            // (front half-space) at the mirror (pi - az, -el): negated phases
            // must land there, not at the truth.
            let mirrored: Vec<f64> = ph.iter().map(|p| -p).collect();
            let m = music(&geometry, &config, &mirrored, &freqs).unwrap();
            assert!(dot(&m.direction, &direction(PI - az, -el)) > 0.9999, "{m:?}");
        }
        println!("music triangle noise-free worst error {:.2e} rad", worst);
    }

    #[test]
    fn triangle_and_linear_at_moderate_noise() {
        // 0.1 rad phase noise per antenna and snapshot (about the phase CRLB
        // at -13 dB per-sample SNR, SF 12); 2 channels per tag.
        let geometry = ArrayGeometry::triangle(0.16);
        let config = MusicConfig::for_array(&geometry);
        let freqs = [902.6e6, 928.5e6];
        let mut rng = StdRng::seed_from_u64(9);
        let (mut e_az, mut e_el) = (Vec::new(), Vec::new());
        for _ in 0..200 {
            let az = rng.random_range(0.5..2.6);
            let el = rng.random_range(-0.4..0.6);
            let source = direction(az, el).map(|x| x * 40.0);
            let ph = array_phases(&geometry, &source, &freqs, 0.1, &mut rng);
            let e = music(&geometry, &config, &ph, &freqs).unwrap();
            e_az.push(super::super::wrap_angle(e.azimuth - az));
            e_el.push(e.elevation - el);
        }
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        println!(
            "music triangle @0.1 rad: az rms {:.2} deg, el rms {:.2} deg",
            rms(&e_az).to_degrees(),
            rms(&e_el).to_degrees()
        );
        assert!(rms(&e_az) < 6f64.to_radians() && rms(&e_el) < 6f64.to_radians());

        let linear = ArrayGeometry::linear(0.16, 3);
        let config = MusicConfig::for_array(&linear);
        let mut errors = Vec::new();
        for _ in 0..100 {
            let az = rng.random_range(0.4..2.7);
            let ph = array_phases(&linear, &direction(az, 0.0).map(|x| x * 30.0), &freqs, 0.1, &mut rng);
            let e = music(&linear, &config, &ph, &freqs).unwrap();
            errors.push(e.azimuth - az);
        }
        println!("music linear @0.1 rad: az rms {:.2} deg", rms(&errors).to_degrees());
        assert!(rms(&errors) < 5f64.to_radians());
    }

    #[test]
    fn carrier_mismatch_is_negligible_with_the_mean_frequency() {
        let geometry = ArrayGeometry::triangle(0.16);
        let freqs = [902.6e6, 903.1e6, 928.5e6, 930.0e6];
        let mut rng = StdRng::seed_from_u64(10);
        let source = direction(0.5, 0.4).map(|x| x * 1e4);
        let ph = array_phases(&geometry, &source, &freqs, 0.0, &mut rng);
        let plain = music(&geometry, &MusicConfig::for_array(&geometry), &ph, &freqs).unwrap();
        let focused =
            music(&geometry, &MusicConfig { focus: true, ..MusicConfig::for_array(&geometry) }, &ph, &freqs).unwrap();
        let err = |e: &MusicEstimate| dot(&e.direction, &direction(0.5, 0.4)).clamp(-1.0, 1.0).acos();
        println!(
            "music carrier mismatch: error {:.2e} rad without focusing, {:.2e} rad with",
            err(&plain),
            err(&focused)
        );
        assert!(err(&plain) < 1e-4 && err(&focused) < 1e-4);
    }

    #[test]
    fn harmonic_and_circular_means() {
        let same = [(1.0, 0.2); 4];
        for method in [AngleCombine::HarmonicMean, AngleCombine::MeanDirection] {
            let (a, e) = combine_angles(&same, method).unwrap();
            assert!((a - 1.0).abs() < 1e-12 && (e - 0.2).abs() < 1e-12);
        }
        let spread = [(0.9, 0.1), (1.1, 0.3), (1.0, 0.2), (1.0, 0.2)];
        let (ah, eh) = combine_angles(&spread, AngleCombine::HarmonicMean).unwrap();
        assert!(ah < 1.0 && ah > 0.98, "{ah}"); // pulled towards the smaller
        let polar_h = 4.0 / [1.4707963, 1.2707963, 1.3707963, 1.3707963].iter().map(|x: &f64| 1.0 / x).sum::<f64>();
        assert!((eh - (FRAC_PI_2 - polar_h)).abs() < 1e-6);
        let (ac, _) = combine_angles(&[(3.1, 0.0), (-3.1, 0.0)], AngleCombine::MeanDirection).unwrap();
        assert!((super::super::wrap_angle(ac - PI)).abs() < 1e-9);
        assert!(combine_angles(&[], AngleCombine::HarmonicMean).is_err());
    }
}
