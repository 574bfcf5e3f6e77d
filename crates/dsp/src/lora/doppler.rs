//! Doppler and clock offsets of the dechirped peaks (docs/marvel.md section 7,
//! step 2; paper eqs. 1, 2, 7).
//!
//! Sign convention (docs/marvel.md section 6): the Doppler of tag k is
//! `f_D,k = -(f/c0) d(path_k)/dt`, the round-trip path
//! `path_k = |p_k - rho_tx| + |p_k - rho_m|`. With the tx and rx antennas a
//! few centimetres apart at tens of metres, both legs change at
//! `u . dp_k/dt` (`u` the unit vector from the controller to the drone), so
//! `f_D,k = -(2 f/c0) u . dp_k/dt`, and a drone flying away (`u . v > 0`)
//! lowers the tone. The paper's eq. 1 writes `+(f/c) u_p . v` with `u_p`
//! from the drone to the controller (`u_p = -u`) and one leg; the round trip
//! doubles it. With `dp_k/dt = v + R (omega_B x r_k)` (the tag's body
//! position `r_k`, the body angular velocity `omega_B`):
//!
//! - translational shift `f_t = -(2 f/c0) u . v`, common to all tags;
//! - rotational shift `-(2 f/c0) u . R (omega_B x r_k)`, equal and opposite
//!   for two opposing tags (`r_b = -r_a` in the gear plane), eq. 2.
//!
//! The dechirped peak of tag k is `cfo_k + f_D,k - (BW/T) tau_k`, so the
//! mean of an opposing pair is `cfo_mean + f_t - (BW/T) tau` (rotation
//! removed, eq. 2) and the half difference is the rotational shift plus
//! `(cfo_a - cfo_b)/2` and a small chirp-timing term (eq. 7; see
//! [`super::heading`]).

use super::chirp::ChirpConfig;
use super::geometry::{cross, dot, mat_vec, Mat3, Vec3};
use crate::error::{Error, Result};
use crate::SPEED_OF_LIGHT;

/// Mean of an opposing pair's peaks, Hz (eq. 2): the rotational shifts
/// `+f_r` and `-f_r` cancel, leaving timing + translation + mean CFO.
pub fn pair_mean(peak_a_hz: f64, peak_b_hz: f64) -> f64 {
    0.5 * (peak_a_hz + peak_b_hz)
}

/// Half difference of an opposing pair's peaks, Hz (eq. 7 divided by two):
/// the rotational shift of tag a (plus half the pair's CFO difference,
/// removed by the caller when the CFO is known).
pub fn pair_half_difference(peak_a_hz: f64, peak_b_hz: f64) -> f64 {
    0.5 * (peak_a_hz - peak_b_hz)
}

/// A tag's carrier frequency offset, `cfo_k = eps s_k` (Hz; docs/marvel.md
/// section 2: one FPGA clock of fractional error `eps` shifts every tag's
/// `s_k`).
pub fn cfo_hz(clock_error: f64, shift_hz: f64) -> f64 {
    clock_error * shift_hz
}

/// Translational Doppler (round trip), `f_t = -(2 f/c0) u . v`, Hz:
/// `carrier_hz` the received carrier, `u` the unit direction from the
/// controller to the drone (world), `velocity` m/s (world).
pub fn translational_doppler_hz(carrier_hz: f64, u: &Vec3, velocity: &Vec3) -> f64 {
    -2.0 * carrier_hz / SPEED_OF_LIGHT * dot(u, velocity)
}

/// Rotational Doppler of a tag at body position `tag_body` (m),
/// `-(2 f/c0) u . R (omega_B x r_k)`, Hz: `world_r_body` the attitude,
/// `omega_body` the body angular velocity (rad/s, the gyroscope's frame).
pub fn rotational_doppler_hz(
    carrier_hz: f64,
    u: &Vec3,
    world_r_body: &Mat3,
    omega_body: &Vec3,
    tag_body: &Vec3,
) -> f64 {
    let v_body = cross(omega_body, tag_body);
    -2.0 * carrier_hz / SPEED_OF_LIGHT * dot(u, &mat_vec(world_r_body, &v_body))
}

/// Whole Doppler of a tag, `-(2 f/c0) u . (v + R (omega_B x r_k))`, Hz.
pub fn tag_doppler_hz(
    carrier_hz: f64,
    u: &Vec3,
    velocity: &Vec3,
    world_r_body: &Mat3,
    omega_body: &Vec3,
    tag_body: &Vec3,
) -> f64 {
    translational_doppler_hz(carrier_hz, u, velocity)
        + rotational_doppler_hz(carrier_hz, u, world_r_body, omega_body, tag_body)
}

/// The dechirped tone of a delay, `-(BW/T) tau`, Hz (docs/marvel.md
/// section 6): the chirp's timing offset seen as a frequency.
pub fn delay_frequency_hz(chirp: &ChirpConfig, tau_s: f64) -> f64 {
    -chirp.chirp_rate_hz_per_s() * tau_s
}

/// The inverse of [`delay_frequency_hz`]: `tau = -f T / BW`, s.
pub fn delay_from_frequency_s(chirp: &ChirpConfig, frequency_hz: f64) -> f64 {
    -frequency_hz / chirp.chirp_rate_hz_per_s()
}

/// The clock error fitted at rest by [`estimate_clock_error`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockEstimate {
    /// Fractional clock error `eps` (dimensionless; 1e-6 = 1 ppm).
    pub clock_error: f64,
    /// Its standard error from the scatter of the observations (`None` with
    /// one observation).
    pub sigma: Option<f64>,
    /// Mean over the observations of the common timing term
    /// `-(BW/T) tau` (Hz): the pair means minus their CFO.
    pub timing_hz: f64,
    /// Observations (4-tag peak sets) used.
    pub observations: usize,
}

/// Fits the tags' common clock error `eps` (`cfo_k = eps s_k`) from peaks
/// measured at rest (docs/marvel.md section 7 step 2; paper sec. III-B: "the
/// difference of CFOs upon averaging the two pairs").
///
/// `shifts_hz` are the four `s_k`, `pairs` the two opposing pairs (tag
/// indices), `peaks_hz` one row of four peak frequencies (Hz) per
/// observation (a channel and antenna of an epoch at rest).
///
/// Model per observation `o`: `f_k = eps s_k + d_o + g_{p(k),o} sign_k`,
/// the least-squares fit over the 4 tags with a timing term `d_o` common to
/// the tags (the unknown range at rest) and an antisymmetric term per pair
/// `g` (the tags' slightly different ranges and any rotation cancel in a
/// pair mean, eq. 2). A plain fit of `eps s_k + d` would let the tags'
/// range differences (up to `(BW/T) 2D/c0` = 0.27 Hz, comparable to a
/// 1 ppm CFO on 1 MHz) leak into `eps`. The normal equations reduce to
/// `eps_o = (m_y - m_x) / (sbar_y - sbar_x)` with `m` the pair means and
/// `sbar` their mean shifts; `eps` is their mean.
///
/// Errors: [`Error::BadConfig`] for pairs that are not a partition of the 4
/// tags or pairs with equal mean shift, [`Error::TooShort`] without
/// observations, [`Error::NonFinite`] for non-finite peaks.
pub fn estimate_clock_error(
    shifts_hz: &[f64; 4],
    pairs: &[(usize, usize); 2],
    peaks_hz: &[[f64; 4]],
) -> Result<ClockEstimate> {
    let mut seen = [false; 4];
    for &(a, b) in pairs {
        for t in [a, b] {
            if t >= 4 || seen[t] {
                return Err(Error::BadConfig(format!("pairs {pairs:?} must partition tags 0..4")));
            }
            seen[t] = true;
        }
    }
    let sbar = |p: (usize, usize)| 0.5 * (shifts_hz[p.0] + shifts_hz[p.1]);
    let ds = sbar(pairs[1]) - sbar(pairs[0]);
    if ds == 0.0 || !ds.is_finite() {
        return Err(Error::BadConfig("the two pairs' mean shifts must differ to separate the CFO".into()));
    }
    if peaks_hz.is_empty() {
        return Err(Error::TooShort { what: "clock error fit", needed: 1, got: 0 });
    }
    if peaks_hz.iter().flatten().any(|x| !x.is_finite()) {
        return Err(Error::NonFinite("peak frequencies".into()));
    }
    let estimates: Vec<(f64, f64)> = peaks_hz
        .iter()
        .map(|f| {
            let mx = pair_mean(f[pairs[0].0], f[pairs[0].1]);
            let my = pair_mean(f[pairs[1].0], f[pairs[1].1]);
            let eps = (my - mx) / ds;
            // Timing term: the pair means with their CFO removed, averaged.
            let d = 0.5 * ((mx - eps * sbar(pairs[0])) + (my - eps * sbar(pairs[1])));
            (eps, d)
        })
        .collect();
    let n = estimates.len() as f64;
    let clock_error = estimates.iter().map(|e| e.0).sum::<f64>() / n;
    let timing_hz = estimates.iter().map(|e| e.1).sum::<f64>() / n;
    let sigma = (estimates.len() > 1).then(|| {
        let var = estimates.iter().map(|e| (e.0 - clock_error).powi(2)).sum::<f64>() / (n - 1.0);
        (var / n).sqrt()
    });
    Ok(ClockEstimate { clock_error, sigma, timing_hz, observations: estimates.len() })
}

#[cfg(test)]
mod tests {
    use super::super::geometry::{direction, mat_mul, roll_pitch_matrix, rotation_z, transpose};
    use super::*;

    #[test]
    fn pair_average_cancels_equal_and_opposite_shifts() {
        for &(common, rot) in &[(3.0, 1.5), (-12.25, 40.0), (0.0, -7.0)] {
            assert!((pair_mean(common + rot, common - rot) - common).abs() < 1e-12);
            assert!((pair_half_difference(common + rot, common - rot) - rot).abs() < 1e-12);
        }
        // ... and so does the exact rotational Doppler of two opposing tags.
        let r = mat_mul(&rotation_z(0.7), &roll_pitch_matrix(0.1, -0.2));
        let u = direction(1.0, 0.3);
        let omega = [0.2, -0.1, 1.3];
        let (ra, rb) = ([0.33, 0.0, -0.3], [-0.33, 0.0, -0.3]);
        let fa = tag_doppler_hz(915e6, &u, &[1.0, 2.0, 0.5], &r, &omega, &ra);
        let fb = tag_doppler_hz(915e6, &u, &[1.0, 2.0, 0.5], &r, &omega, &rb);
        let ft = translational_doppler_hz(915e6, &u, &[1.0, 2.0, 0.5]);
        let rot_h = rotational_doppler_hz(915e6, &u, &r, &omega, &[0.0, 0.0, -0.3]);
        assert!((pair_mean(fa, fb) - ft - rot_h).abs() < 1e-9);
    }

    #[test]
    fn doppler_signs_follow_the_path_rate() {
        // Flying away along u at 3 m/s: the path grows at 6 m/s, so the tone
        // drops by 2 f v / c0 (18.3 Hz at 915 MHz).
        let u = [0.0, 1.0, 0.0];
        let f = translational_doppler_hz(915e6, &u, &[0.0, 3.0, 0.0]);
        assert!((f + 2.0 * 915e6 * 3.0 / SPEED_OF_LIGHT).abs() < 1e-9 && f < -18.0);
        // Finite-difference check of the whole Doppler against the path rate.
        let rho = [0.3, -20.0, 1.0];
        let r0 = roll_pitch_matrix(0.05, 0.1);
        let omega = [0.0, 0.0, 1.2];
        let v = [0.4, 1.1, -0.2];
        let tag = [0.33, 0.0, -0.3];
        let path = |t: f64| {
            let r = mat_mul(&rotation_z(omega[2] * t), &r0);
            let p = [
                v[0] * t + r[0][0] * tag[0] + r[0][2] * tag[2],
                v[1] * t + r[1][0] * tag[0] + r[1][2] * tag[2],
                v[2] * t + r[2][0] * tag[0] + r[2][2] * tag[2],
            ];
            2.0 * ((p[0] - rho[0]).powi(2) + (p[1] - rho[1]).powi(2) + (p[2] - rho[2]).powi(2)).sqrt()
        };
        let h = 1e-5;
        let fd = -915e6 / SPEED_OF_LIGHT * (path(h) - path(-h)) / (2.0 * h);
        let p0 = mat_vec(&r0, &tag);
        let to = [p0[0] - rho[0], p0[1] - rho[1], p0[2] - rho[2]];
        let n = (to[0] * to[0] + to[1] * to[1] + to[2] * to[2]).sqrt();
        let u = [to[0] / n, to[1] / n, to[2] / n];
        // omega about world z equals body omega R^T w for this R(t); use the
        // body vector so that R (omega_B x r) = w x (R r).
        let wb = mat_vec(&transpose(&r0), &omega);
        let model = tag_doppler_hz(915e6, &u, &v, &r0, &wb, &tag);
        assert!((fd - model).abs() < 1e-6, "{fd} vs {model}");
    }

    #[test]
    fn clock_error_from_rest_ignores_range_and_geometry() {
        let chirp = ChirpConfig::marvel();
        let shifts = [1e6, 2e6, 3e6, 4e6];
        let eps = 1.7e-6;
        let pairs = [(0, 1), (2, 3)];
        // Rest: common timing -(BW/T) tau plus antisymmetric per-pair terms.
        let rows: Vec<[f64; 4]> = (0..6)
            .map(|o| {
                let d = delay_frequency_hz(&chirp, (100.0 + o as f64) * 1e-9);
                let (gx, gy) = (0.2 - 0.05 * o as f64, -0.13);
                [eps * 1e6 + d + gx, eps * 2e6 + d - gx, eps * 3e6 + d + gy, eps * 4e6 + d - gy]
            })
            .collect();
        let e = estimate_clock_error(&shifts, &pairs, &rows).unwrap();
        assert!((e.clock_error - eps).abs() < 1e-15, "{}", e.clock_error);
        assert!(e.sigma.unwrap() < 1e-15);
        assert!((e.timing_hz - delay_frequency_hz(&chirp, 102.5e-9)).abs() < 1e-9);
        assert!(estimate_clock_error(&shifts, &[(0, 1), (1, 3)], &rows).is_err());
        assert!(estimate_clock_error(&shifts, &pairs, &[]).is_err());
        assert!((delay_from_frequency_s(&chirp, delay_frequency_hz(&chirp, 3e-7)) - 3e-7).abs() < 1e-20);
    }
}
