//! Yaw from the rotational Doppler of the two opposing tag pairs
//! (docs/marvel.md section 7 step 6; paper eqs. 7-8, generalised to 3D).
//!
//! **Model.** Tag k at body position `r_k` moves at `v + R (omega_B x r_k)`
//! (`R = world_R_body`, `omega_B` the gyroscope's body rate). Its dechirped
//! peak is `cfo_k + f_D,k - (BW/T) tau_k` with `f_D,k = -(f/c0) d(path_k)/dt
//! = -(2 f/c0) u . (v + R (omega_B x r_k))` (round trip, docs/marvel.md
//! section 6; `u` the unit vector from the controller to the drone) and
//! `tau_k = tau + (2/c0) u . R r_k` to first order. The difference of an
//! opposing pair `(a, b)`, after removing the known `cfo_a - cfo_b`, is
//! (paper eq. 7, `= 2 x` the rotational shift)
//!
//! `d = -(2/c0) u . R w`, `w = f (omega_B x dr) + (BW/T) dr`, `dr = r_a - r_b`:
//!
//! the translation cancels; the second term is the chirp-timing difference
//! of the two tags (their ranges differ by up to `D`), `(BW/T) 2D/c0` =
//! 0.27 Hz at most, which is 7 % of the rotational signal at 1 rad/s and so
//! kept (`chirp_rate_hz_per_s`; `None` drops it).
//!
//! **Parallax.** The translation cancels only to first order: the two tags
//! are seen along slightly different directions, `u_k ~ u + (I - u u^T) R
//! r_k / r` at range `r`, so `u_a . v - u_b . v = ((I - u u^T) v) . R dr /
//! r`. At 3 m/s and 10 m that is 0.2 m/s of "rotation", 1.2 Hz — 17 deg of
//! yaw at 1 rad/s — so when the velocity and the range are known the term
//! `-(2 f/c0) ((I - u u^T) v / r) . R dr` is modelled too.
//!
//! **Yaw.** With `R = Rz(yaw) R_rp` (`R_rp` the roll/pitch part, known from
//! the IMU's gravity direction) and `q = R_rp w`,
//! `u . Rz(yaw) q = cos(yaw) (u_x q_x + u_y q_y) + sin(yaw) (u_y q_x - u_x
//! q_y) + u_z q_z`, i.e. `d = A cos(yaw) + B sin(yaw) + C`, linear in
//! `(cos yaw, sin yaw)` (the parallax term `g . R b` likewise, with `g` in
//! place of `u`). Pair x (`dr` along body x) and pair y (along body
//! y) give two such equations with roughly orthogonal `(A, B)`: the paper's
//! eq. 8 is pair x's `sin(phi - yaw)` for level flight and a vertical
//! `omega`, and pair y's cosine resolves its pi ambiguity. Weighted least
//! squares for `(cos, sin)` gives `yaw = atan2(sin, cos)`; Gauss-Newton on
//! the yaw itself (the constrained ML fit, `cos^2 + sin^2 = 1`) then
//! refines it. The rotational signal scales with `|omega|`: below
//! `min_omega_rad_s` there is no yaw (`None`).

use super::geometry::{cross, dot, mat_vec, norm, rotation_z, sub, Mat3, Vec3};
use crate::SPEED_OF_LIGHT;

/// One measured pair difference (one channel and antenna, or an average).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairObservation {
    /// Body positions of tags a and b, m.
    pub tag_a: Vec3,
    pub tag_b: Vec3,
    /// The pair's mean received carrier `f_j + (s_a + s_b)/4`, Hz.
    pub carrier_hz: f64,
    /// `f_peak,a - f_peak,b - (cfo_a - cfo_b)`, Hz (eq. 7).
    pub difference_hz: f64,
    /// Standard deviation of `difference_hz`, Hz (> 0).
    pub sigma_hz: f64,
}

/// Options of [`solve_yaw`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingConfig {
    /// No yaw below this body rate, rad/s.
    pub min_omega_rad_s: f64,
    /// `BW/T` for the tags' chirp-timing difference (Hz/s); `None` ignores
    /// it.
    pub chirp_rate_hz_per_s: Option<f64>,
}

impl Default for HeadingConfig {
    fn default() -> Self {
        Self { min_omega_rad_s: 0.05, chirp_rate_hz_per_s: Some(500e3 / 8.192e-3) }
    }
}

/// The yaw of [`solve_yaw`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingEstimate {
    /// Yaw, rad in (-pi, pi] (docs/marvel.md section 1).
    pub yaw: f64,
    /// Its standard deviation from the observations' sigmas, rad:
    /// `1 / sqrt(sum (dd/dyaw)^2 / sigma^2)`.
    pub sigma_rad: f64,
    /// Condition number of the `(cos, sin)` least-squares problem (singular
    /// value ratio of the weighted `[A B]` design): ~1 with two orthogonal
    /// pairs, large when `u` is nearly parallel to the rotation axis (e.g.
    /// the drone right above the controller while yawing) and the yaw is
    /// poorly defined.
    pub condition: f64,
    /// RMS of the fit residuals, Hz.
    pub residual_rms_hz: f64,
}

/// What the pair differences are modelled with, besides the yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawGeometry {
    /// `R_rp`, the attitude without its yaw (`R = Rz(yaw) R_rp`).
    pub roll_pitch: Mat3,
    /// Gyroscope body rate, rad/s.
    pub omega_body: Vec3,
    /// Unit direction from the controller to the drone (world).
    pub direction: Vec3,
    /// Velocity of the tags' centroid, m/s (world), and the range, m: both
    /// given, the parallax term is modelled.
    pub velocity: Option<Vec3>,
    pub range_m: Option<f64>,
}

impl YawGeometry {
    /// The `(world vector, body vector)` terms whose `a . Rz(yaw) R_rp b`
    /// add up to the pair difference, Hz.
    fn terms(&self, observation: &PairObservation, chirp_rate: Option<f64>) -> [(Vec3, Vec3); 2] {
        let dr = sub(&observation.tag_a, &observation.tag_b);
        let rot = cross(&self.omega_body, &dr);
        let kappa = chirp_rate.unwrap_or(0.0);
        let k = -2.0 / SPEED_OF_LIGHT;
        let f = observation.carrier_hz;
        let doppler_timing =
            [k * (f * rot[0] + kappa * dr[0]), k * (f * rot[1] + kappa * dr[1]), k * (f * rot[2] + kappa * dr[2])];
        let u = self.direction;
        let parallax = match (self.velocity, self.range_m) {
            (Some(v), Some(r)) if r > 0.0 => {
                let along = dot(&u, &v);
                [(v[0] - along * u[0]) / r, (v[1] - along * u[1]) / r, (v[2] - along * u[2]) / r]
            }
            _ => [0.0; 3],
        };
        [(u, doppler_timing), (parallax, [k * f * dr[0], k * f * dr[1], k * f * dr[2]])]
    }
}

/// `(A, B, C)` of `d = A cos(yaw) + B sin(yaw) + C` for one observation (Hz):
/// with `q = R_rp b`, `a . Rz(yaw) q = cos(yaw) (a_x q_x + a_y q_y) +
/// sin(yaw) (a_y q_x - a_x q_y) + a_z q_z`, summed over the terms.
pub fn pair_coefficients(
    observation: &PairObservation,
    geometry: &YawGeometry,
    chirp_rate_hz_per_s: Option<f64>,
) -> (f64, f64, f64) {
    geometry.terms(observation, chirp_rate_hz_per_s).iter().fold((0.0, 0.0, 0.0), |(sa, sb, sc), (a, b)| {
        let q = mat_vec(&geometry.roll_pitch, b);
        (sa + a[0] * q[0] + a[1] * q[1], sb + a[1] * q[0] - a[0] * q[1], sc + a[2] * q[2])
    })
}

/// The modelled pair difference at `yaw` (Hz), computed directly as
/// `sum a . Rz(yaw) R_rp b` (the reference for [`pair_coefficients`]).
pub fn predicted_difference_hz(
    observation: &PairObservation,
    yaw: f64,
    geometry: &YawGeometry,
    chirp_rate_hz_per_s: Option<f64>,
) -> f64 {
    let r = rotation_z(yaw);
    geometry
        .terms(observation, chirp_rate_hz_per_s)
        .iter()
        .map(|(a, b)| dot(a, &mat_vec(&r, &mat_vec(&geometry.roll_pitch, b))))
        .sum()
}

/// Yaw from pair differences (see the module doc). `None` when
/// `|omega_body| < min_omega_rad_s`, without observations, with a
/// non-finite input or when the observations carry no yaw information.
pub fn solve_yaw(
    observations: &[PairObservation],
    geometry: &YawGeometry,
    config: &HeadingConfig,
) -> Option<HeadingEstimate> {
    let rate = norm(&geometry.omega_body);
    if rate.is_nan() || rate < config.min_omega_rad_s || observations.is_empty() {
        return None;
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let g = geometry;
    if !(finite(&g.omega_body)
        && finite(&g.direction)
        && g.roll_pitch.iter().all(|r| finite(r))
        && g.velocity.is_none_or(|v| finite(&v))
        && g.range_m.is_none_or(f64::is_finite))
    {
        return None;
    }
    let mut rows = Vec::with_capacity(observations.len());
    for o in observations {
        if !(o.difference_hz.is_finite() && o.sigma_hz > 0.0 && o.sigma_hz.is_finite()) {
            return None;
        }
        let (a, b, c) = pair_coefficients(o, geometry, config.chirp_rate_hz_per_s);
        rows.push((a, b, c, o.difference_hz, 1.0 / (o.sigma_hz * o.sigma_hz)));
    }
    // Weighted normal equations for (cos, sin).
    let (mut n11, mut n12, mut n22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(a, b, c, d, w) in &rows {
        n11 += w * a * a;
        n12 += w * a * b;
        n22 += w * b * b;
        b1 += w * a * (d - c);
        b2 += w * b * (d - c);
    }
    let trace = n11 + n22;
    let det = n11 * n22 - n12 * n12;
    let disc = ((n11 - n22).powi(2) + 4.0 * n12 * n12).sqrt();
    let (l_max, l_min) = (0.5 * (trace + disc), 0.5 * (trace - disc));
    if l_max.is_nan() || l_max <= 0.0 {
        return None;
    }
    let condition = if l_min > 0.0 { (l_max / l_min).sqrt() } else { f64::INFINITY };
    let cost = |yaw: f64| -> f64 {
        let (s, c) = yaw.sin_cos();
        rows.iter().map(|&(a, b, cc, d, w)| w * (a * c + b * s + cc - d).powi(2)).sum()
    };
    // Starts: the unconstrained solution and a coarse scan (the constrained
    // cost on the circle can have two minima when the design is
    // ill-conditioned).
    let mut start = if det > 1e-12 * l_max * l_max {
        let (c, s) = ((n22 * b1 - n12 * b2) / det, (n11 * b2 - n12 * b1) / det);
        s.atan2(c)
    } else {
        0.0
    };
    let mut best = cost(start);
    for i in 0..72 {
        let yaw = -std::f64::consts::PI + std::f64::consts::TAU * i as f64 / 72.0;
        let v = cost(yaw);
        if v < best {
            best = v;
            start = yaw;
        }
    }
    // Gauss-Newton on the yaw with step halving.
    let mut yaw = start;
    for _ in 0..50 {
        let (s, c) = yaw.sin_cos();
        let (mut g, mut h) = (0.0, 0.0);
        for &(a, b, cc, d, w) in &rows {
            let r = a * c + b * s + cc - d;
            let j = -a * s + b * c;
            g += w * j * r;
            h += w * j * j;
        }
        if h.is_nan() || h <= 0.0 {
            break;
        }
        let mut step = -g / h;
        let mut improved = false;
        for _ in 0..30 {
            let v = cost(yaw + step);
            if v <= best {
                best = v;
                yaw += step;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved || step.abs() < 1e-12 {
            break;
        }
    }
    let (s, c) = yaw.sin_cos();
    let mut information = 0.0;
    let mut rss = 0.0;
    for &(a, b, cc, d, w) in &rows {
        information += w * (-a * s + b * c).powi(2);
        rss += (a * c + b * s + cc - d).powi(2);
    }
    if information.is_nan() || information <= 0.0 {
        return None;
    }
    Some(HeadingEstimate {
        yaw: super::wrap_angle(yaw),
        sigma_rad: 1.0 / information.sqrt(),
        condition,
        residual_rms_hz: (rss / rows.len() as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::geometry::{add, mat_mul, roll_pitch_matrix};
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const D: f64 = 0.66;
    const H: f64 = -0.30;
    fn tags() -> [Vec3; 4] {
        [[D / 2.0, 0.0, H], [-D / 2.0, 0.0, H], [0.0, D / 2.0, H], [0.0, -D / 2.0, H]]
    }

    #[test]
    fn coefficients_match_the_direct_model_and_the_derivative_matches_finite_differences() {
        let u = super::super::geometry::normalize(&[0.3, 0.8, 0.52]).unwrap();
        let g = YawGeometry {
            roll_pitch: roll_pitch_matrix(0.2, -0.15),
            omega_body: [0.3, -0.2, 1.1],
            direction: u,
            velocity: Some([1.0, -2.0, 0.5]),
            range_m: Some(12.0),
        };
        let t = tags();
        let o = PairObservation { tag_a: t[0], tag_b: t[1], carrier_hz: 903e6, difference_hz: 0.0, sigma_hz: 1.0 };
        let kappa = Some(500e3 / 8.192e-3);
        let (a, b, c) = pair_coefficients(&o, &g, kappa);
        for i in 0..16 {
            let yaw = -3.0 + 0.4 * i as f64;
            let direct = predicted_difference_hz(&o, yaw, &g, kappa);
            assert!((a * yaw.cos() + b * yaw.sin() + c - direct).abs() < 1e-9);
            // Jacobian of the residual used by Gauss-Newton: -A sin + B cos.
            let h = 1e-6;
            let fd = (predicted_difference_hz(&o, yaw + h, &g, kappa)
                - predicted_difference_hz(&o, yaw - h, &g, kappa))
                / (2.0 * h);
            assert!((fd - (-a * yaw.sin() + b * yaw.cos())).abs() < 1e-6, "{fd}");
        }
    }

    /// Pair differences from the exact geometry: path rates by central
    /// differences of `|p_k - rho| + |p_k - rho_rx|` over a short time, the
    /// exact delay difference, noise of `sigma` Hz.
    #[allow(clippy::too_many_arguments)]
    fn exact_differences(
        rho: &Vec3,
        p: &Vec3,
        v: &Vec3,
        r: &Mat3,
        omega_body: &Vec3,
        carrier: f64,
        sigma: f64,
        rng: &mut StdRng,
    ) -> Vec<PairObservation> {
        let kappa = 500e3 / 8.192e-3;
        let rx = add(rho, &[0.08, 0.0, -0.046]);
        let t = tags();
        // R(t) = R exp([omega_B] t): body-rate rotation, to first order.
        let at = |dt: f64, tag: &Vec3| -> f64 {
            let w = [omega_body[0] * dt, omega_body[1] * dt, omega_body[2] * dt];
            let rb = add(tag, &cross(&w, tag));
            let pk = add(&add(p, &v.map(|x| x * dt)), &mat_vec(r, &rb));
            norm(&sub(&pk, rho)) + norm(&sub(&pk, &rx))
        };
        let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
        [(0usize, 1usize), (2, 3)]
            .iter()
            .map(|&(a, b)| {
                let h = 1e-4;
                let rate = |k: usize| (at(h, &t[k]) - at(-h, &t[k])) / (2.0 * h);
                let fd = -carrier / SPEED_OF_LIGHT * (rate(a) - rate(b));
                let timing = -kappa * (at(0.0, &t[a]) - at(0.0, &t[b])) / SPEED_OF_LIGHT;
                let n = if sigma > 0.0 { noise.sample(rng) } else { 0.0 };
                PairObservation {
                    tag_a: t[a],
                    tag_b: t[b],
                    carrier_hz: carrier,
                    difference_hz: fd + timing + n,
                    sigma_hz: sigma.max(0.01),
                }
            })
            .collect()
    }

    #[test]
    fn recovers_yaw_over_a_full_turn_for_several_rates_and_attitudes() {
        let mut rng = StdRng::seed_from_u64(11);
        let rho = [0.0, -25.0, 1.0];
        let config = HeadingConfig::default();
        let mut worst_clean: f64 = 0.0;
        let mut noisy = Vec::new();
        for &(roll, pitch) in &[(0.0, 0.0), (0.15, -0.1), (-0.25, 0.2)] {
            for &omega in &[[0.0, 0.0, 0.3], [0.0, 0.0, -1.0], [0.2, -0.1, 1.5], [0.0, 0.0, 3.0]] {
                for i in 0..36 {
                    let yaw = -std::f64::consts::PI + std::f64::consts::TAU * (i as f64 + 0.5) / 36.0;
                    let rp = roll_pitch_matrix(roll, pitch);
                    let r = mat_mul(&rotation_z(yaw), &rp);
                    let p = [4.0, 3.0, 6.0];
                    let u = super::super::geometry::normalize(&sub(&p, &rho)).unwrap();
                    let v = [0.5, -1.0, 0.2];
                    let clean = exact_differences(&rho, &p, &v, &r, &omega, 903e6, 0.0, &mut rng);
                    let g = YawGeometry {
                        roll_pitch: rp,
                        omega_body: omega,
                        direction: u,
                        velocity: Some(v),
                        range_m: Some(norm(&sub(&p, &rho))),
                    };
                    let e = solve_yaw(&clean, &g, &config).unwrap();
                    let err = super::super::wrap_angle(e.yaw - yaw).abs();
                    worst_clean = worst_clean.max(err);
                    assert!(err < 0.01, "roll {roll} pitch {pitch} omega {omega:?} yaw {yaw}: {e:?}");
                    // 0.3 Hz noise per pair difference.
                    let obs = exact_differences(&rho, &p, &v, &r, &omega, 903e6, 0.3, &mut rng);
                    if let Some(e) = solve_yaw(&obs, &g, &config) {
                        noisy.push((norm(&omega), super::super::wrap_angle(e.yaw - yaw), e.sigma_rad));
                    }
                }
            }
        }
        println!("heading: worst noise-free error {:.5} rad (first-order model at 31 m, 1.1 m/s)", worst_clean);
        for &w in &[0.3, 1.0, 1.52, 3.0] {
            let errs: Vec<&(f64, f64, f64)> = noisy.iter().filter(|x| (x.0 - w).abs() < 0.05).collect();
            let rms = (errs.iter().map(|x| x.1 * x.1).sum::<f64>() / errs.len() as f64).sqrt();
            let sig = errs.iter().map(|x| x.2).sum::<f64>() / errs.len() as f64;
            println!(
                "heading @0.3 Hz noise, |omega| {w:.2} rad/s: yaw rms {:.2} deg (predicted sigma {:.2} deg)",
                rms.to_degrees(),
                sig.to_degrees()
            );
            if w >= 1.0 {
                assert!(rms < 3.0 * sig + 0.03, "{w}: {rms} vs {sig}");
            }
        }
        // No yaw at rest.
        let rp = roll_pitch_matrix(0.0, 0.0);
        let obs = exact_differences(&rho, &[0.0, 0.0, 5.0], &[0.0; 3], &rp, &[0.0, 0.0, 0.01], 903e6, 0.0, &mut rng);
        let g = YawGeometry {
            roll_pitch: rp,
            omega_body: [0.0, 0.0, 0.01],
            direction: [0.0, 1.0, 0.0],
            velocity: None,
            range_m: None,
        };
        assert!(solve_yaw(&obs, &g, &config).is_none());
    }
}
